r"""Synthetic slab captures rendered by Mitsuba 3 volumetric path tracing (``volpath``).

Why the obvious set-up fails: a delta light (point, directional) behind a ``dielectric``
boundary cannot be reached by next-event estimation (the shadow ray stops at the
boundary), and a pencil beam is a source of measure zero that no camera path can hit.
The set-up here converges, for any eta:

* **Slab**: a box (Mitsuba ``cube``), top face at z = 0, lateral half-size far beyond
  the field of view, thickness ``thickness_mm`` or, for "semi-infinite", many transport
  lengths (:func:`semi_infinite_depth`). Its surface is a smooth ``dielectric`` of
  ``int_ior = eta`` (``null`` when eta = 1: index-matched); inside, a ``homogeneous``
  medium with :math:`\sigma_t = \sigma_a + \sigma'_s`, albedo :math:`\sigma'_s/\sigma_t`
  and an isotropic phase function per RGB channel (the similarity relation: the dipole's
  reduced coefficients). Scene units are mm.
* **Beam** (``SlabBeam``, a Python ``mi.Emitter`` registered as :data:`BEAM_PLUGIN`): a
  collimated Gaussian beam that *starts just inside the medium*, on the plane
  :data:`BEAM_DEPTH_MM` below the top face, travelling straight down. It is delta in
  direction (like ``directional``) but has a finite origin plane: for a point p below
  the plane it returns the direction straight up, the sample point p projected onto the
  plane (so the shadow ray stops before the dielectric and sees only the medium's
  transmittance) and the weight :math:`E(\rho) = P_{in}\,\frac{2}{\pi
  w^2}\,e^{-2\rho^2/w^2}` with :math:`P_{in} = 1`: unit power *entering* the slab. The
  external beam's Fresnel loss at normal incidence is taken out exactly (a
  normal-incidence collimated beam is not refracted). Points above the plane get
  nothing. Volpath's next-event estimation at each scattering vertex then adds
  :math:`E(\rho)\,e^{-\sigma_t d}\,p(\omega)`: the single-scattering source of the
  collimated beam, every order of scattering following from there. In a finite slab the
  unscattered beam reflected at the bottom face (and again at the top) is a second delta
  direction of the same emitter (:func:`collimated_powers`). A finite beam radius ``w``
  is required: camera paths cannot find a pencil.
* **Sensor** (``SlabExitanceSensor``, a Python ``mi.Sensor``, :data:`SENSOR_PLUGIN`): a
  film lying on the slab face the camera sees (the top for ``reflection``, the bottom
  for ``transmission``), ``pixel_size_mm`` per pixel, box filter. In the default
  ``"exitance"`` mode each sample starts at a uniform point of its pixel and looks into
  the slab along a cosine-distributed direction with weight :math:`\pi`, so a pixel
  holds :math:`\int L\cos\theta\,d\omega` averaged over its area: the radiant exitance
  ``E`` of the capture format (mm^-2 per unit entering power), exactly what the fitter's
  forward model and the photon random walk describe, with no angular assumption. In
  ``"normal radiance"`` mode it looks straight along the normal (what an orthographic
  camera on the axis sees) and converts the radiance ``L`` with
  :func:`exitance_per_normal_radiance`, which is exact only where the radiance inside is
  isotropic (see that function for how far from it real profiles are). Camera paths
  cannot see a collimated beam, so the unscattered light leaving the imaged face is
  added in closed form over the beam's footprint (:func:`beam_pixel_image`).
* **Integrator**: ``volpath`` with unlimited depth (high-albedo media need thousands of
  bounces) and Russian roulette only once the throughput has fallen to
  :data:`ROULETTE_THROUGHPUT` (:func:`roulette_depth`): volpath's default (from the
  fifth bounce, survival capped at 0.95) makes the far field of a high-albedo medium an
  estimate that is unbiased in theory and almost always far too low in practice.
* **Channels**: one render per distinct channel, of a grey medium with that channel's
  coefficients (:data:`CHANNEL_MODES`): volpath's RGB mode fills a chromatic medium's
  far field with fireflies.

The image is rendered in passes of at most ``pass_spp`` samples per pixel (independent
seeds), so that 10^4 spp fit in memory on a GPU; the mean is the capture and the spread
of the passes gives each pixel's standard error. The Python plugins run in any JIT
variant (``llvm_ad_rgb`` here, ``cuda_ad_rgb`` on a GPU; ``TRANSLUCENT_VARIANT``
chooses). The exitance then passes through the same camera defects as the other
generators (:func:`~translucent.fitting.synthetic.apply_camera`).
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, check_count
from ..materials import Dipole
from ..materials.dipole import reduced_albedo, reduced_extinction
from ..materials.profiles import diffuse_entry_transmittance
from .synthetic import Camera, apply_camera, capture_spec

__all__ = ["BEAM_DEPTH_MM", "CHANNEL_MODES", "DEFAULT_BEAM_FRACTION", "VolpathRender",
           "beam_pixel_image", "collimated_powers", "exitance_per_normal_radiance",
           "register_plugins", "render_exitance", "roulette_depth", "semi_infinite_depth",
           "slab_scene_dict", "volpath_capture"]

#: Depth of the beam's origin plane below the top face, mm: far below any mean free path
#: of the catalogue (the shortest is Spectralon's 0.05 mm), so the light scattered in the
#: layer above it is negligible, yet many float32 steps away from the face at z = 0.
BEAM_DEPTH_MM = 1e-4
#: Height of the sensor plane off the slab face, mm (rays start there, outside the medium).
SENSOR_OFFSET_MM = 1e-3
#: Default 1/e^2 beam radius as a fraction of the field's width: 4.8 pixels on a 96-pixel
#: image, wide enough for camera paths to find the beam, narrow next to the ~12 diffusion
#: lengths the default field spans.
DEFAULT_BEAM_FRACTION = 0.05
#: A semi-infinite slab is this many diffusion lengths 1 / sigma_tr deep (the light left
#: at that depth is e^-20 of the entering power) and at least :data:`DEPTH_MIN_MFP`
#: reduced mean free paths; but at most :data:`DEPTH_MAX_MFP` of them (a medium with
#: little absorption has an enormous diffusion length; a non-absorbing slab of optical
#: thickness tau' transmits about 4 / (3 tau'), 0.7 % at 200).
DEPTH_DIFFUSION_LENGTHS = 20.0
DEPTH_MIN_MFP = 30.0
DEPTH_MAX_MFP = 200.0
#: Lateral half-size of the slab beyond the field's half-diagonal, in units of the slab
#: depth: paths that leave through the side faces are lost, so the sides stay as far away
#: as the bottom.
LATERAL_MARGIN_DEPTHS = 1.0
#: Most samples per pixel in one pass (one Mitsuba render call): 96 x 96 x 1024 lanes is
#: about 10^7 paths in flight, well within a GPU's memory and a CPU's.
DEFAULT_PASS_SPP = 1024
#: Unlimited path depth (Mitsuba's -1): Russian roulette ends the paths.
MAX_DEPTH = -1
#: Russian roulette starts once the throughput of every channel has fallen below this
#: (albedo^n): volpath survives a roulette with probability min(throughput eta^2, 0.95)
#: and divides by it, so roulette on a throughput near 1 (a high-albedo medium) multiplies
#: a survivor by 1.05 a bounce: a camera path that needs 2500 bounces to reach a beam
#: 50 mean free paths away then carries 1e53 with probability 1e-56, an unbiased but
#: never-converging estimate (measured: 0.80 +- 0.02 of the light found on a
#: non-absorbing slab where the walk finds 0.97, at 4096 spp with volpath's default
#: rr_depth of 5).
ROULETTE_THROUGHPUT = 1e-4
#: Most bounces before roulette (a non-absorbing medium never reaches the throughput;
#: its paths end by leaving the slab).
MAX_ROULETTE_DEPTH = 10**7

SENSOR_MODES = ("exitance", "normal radiance")
#: How the three channels are rendered. Volpath's RGB mode samples free paths with one
#: channel's extinction and weights the others by the ratio of the densities, which grows
#: as exp((sigma_t,sampled - sigma_t,other) t) along a path: in a chromatic medium the far
#: field fills with fireflies (measured on Skin1, 48 x 48, 512 spp: annulus means 1.3 and
#: 2.1 times the random walk's in the red channel, and the dipole fitted to it returned
#: sigma_s' 1.7-3 times the truth where the walk's capture gives 0.5-1.1). "separate"
#: renders one grey medium per distinct channel instead: no chromatic weights, and each
#: channel's roulette depth follows its own albedo.
CHANNEL_MODES = ("separate", "rgb")
BEAM_PLUGIN = "translucent_slab_beam"
SENSOR_PLUGIN = "translucent_slab_exitance"


def exitance_per_normal_radiance(eta: float) -> float:
    r"""Factor from radiance seen along the normal outside to exitance, isotropic inside.

    Where the radiance :math:`L_i` inside the slab is isotropic, the exitance is
    :math:`E = \pi L_i (1 - F^{int}_{dr})` and the radiance leaving along the normal is
    :math:`L = L_i (1 - R(0)) / \eta^2`, so

    .. math:: E = \pi L \frac{1 - F^{ext}_{dr}(\eta)}{1 - R(0)},\qquad
        R(0) = \left(\frac{\eta - 1}{\eta + 1}\right)^2,

    using :math:`1 - F^{int}_{dr} = (1 - F^{ext}_{dr})/\eta^2`.
    :math:`F^{ext}_{dr} = \int_0^1 2\mu F_r(\eta, \mu)\,d\mu` is the diffuse Fresnel
    reflectance of light from outside, integrated from the exact Fresnel term by
    :func:`~translucent.materials.profiles.diffuse_entry_transmittance`. (The
    polynomial of Jensen et al. 2001,
    :func:`~translucent.materials.fresnel.diffuse_fresnel_reflectance`, is the *internal*
    one: 0.445 at eta = 1.3, against 0.061 from outside.)

    The radiance at the boundary is never isotropic, even deep in the diffusion regime
    (at eta = 1 the Milne problem's exit distribution gives :math:`E/L \approx 2.5`,
    not :math:`\pi`), so this factor is an approximation whose error the fitter absorbs
    into the exposure only where it is the same at every radius; it is not (see
    docs/capture-format.md for the measured ratio).

    Parameters
    ----------
    eta : float
        Relative index of refraction, >= 1.

    Returns
    -------
    float
        :math:`E / L`, sr (pi at eta = 1).
    """
    r_normal = ((eta - 1.0) / (eta + 1.0)) ** 2
    return math.pi * float(diffuse_entry_transmittance(eta)) / (1.0 - r_normal)


def semi_infinite_depth(material: Dipole) -> float:
    """Depth (mm) of the box that stands for a semi-infinite slab (see the constants)."""
    sigma_t_prime = material.sigma_a + material.sigma_s_prime
    mfp = 1.0 / np.maximum(sigma_t_prime, 1e-12)
    with np.errstate(divide="ignore"):
        diffusion = np.where(material.sigma_tr > 0,
                             DEPTH_DIFFUSION_LENGTHS / np.maximum(material.sigma_tr, 1e-300),
                             np.inf)
    depth = np.minimum(np.maximum(diffusion, DEPTH_MIN_MFP * mfp), DEPTH_MAX_MFP * mfp)
    return float(np.max(depth))


def roulette_depth(material: Dipole) -> int:
    r"""Bounces before volpath's Russian roulette (see :data:`ROULETTE_THROUGHPUT`).

    The throughput after ``n`` scatterings is ``albedo^n`` (reduced albedo
    :math:`\sigma'_s / (\sigma_a + \sigma'_s)`, the highest channel).
    """
    albedo = float(np.max(reduced_albedo(material.sigma_a, material.sigma_s_prime)))
    if albedo >= 1.0:
        return MAX_ROULETTE_DEPTH
    if albedo <= ROULETTE_THROUGHPUT:
        return 1
    return int(min(math.ceil(math.log(ROULETTE_THROUGHPUT) / math.log(albedo)),
                   MAX_ROULETTE_DEPTH))


def collimated_powers(material: Dipole, depth_mm: float) -> dict[str, np.ndarray]:
    r"""Powers of the unscattered (collimated) beam in a slab, per channel.

    The beam enters with unit power and crosses the slab with transmittance
    :math:`e^{-\tau}`, :math:`\tau = \sigma'_t d`; at each face a fraction
    :math:`R(0) = ((\eta - 1)/(\eta + 1))^2` is reflected back. Summing the bounces:

    .. math::
        D = \frac{1}{1 - R(0)^2 e^{-2\tau}},\quad U = R(0)\,e^{-\tau} D,\quad
        T_b = (1 - R(0))\,e^{-\tau} D,\quad R_b = (1 - R(0))\,e^{-\tau} U.

    Parameters
    ----------
    material : Dipole
    depth_mm : float
        Slab thickness, mm.

    Returns
    -------
    dict
        ``down`` (D: downward power at the top, all bounces), ``up`` (U: upward power at
        the bottom), ``transmitted`` (T_b) and ``reflected`` (R_b): the unscattered
        power leaving through the bottom and the top; arrays of shape (3,).
    """
    r_normal = ((material.eta - 1.0) / (material.eta + 1.0)) ** 2
    crossing = np.exp(-(material.sigma_a + material.sigma_s_prime) * depth_mm)
    down = 1.0 / (1.0 - r_normal ** 2 * crossing ** 2)
    up = r_normal * crossing * down
    return {"down": down, "up": up, "transmitted": (1.0 - r_normal) * crossing * down,
            "reflected": (1.0 - r_normal) * crossing * up}


def beam_pixel_image(shape, pixel_size_mm, incident_px, beam_radius_mm) -> np.ndarray:
    """Gaussian beam irradiance of unit power averaged over each pixel, mm^-2, (H, W).

    The 1/e^2 radius ``w`` is twice the standard deviation; the pixel average is a product
    of error-function differences, exact.
    """
    from scipy.special import ndtr

    height, width = shape
    sigma_px = 0.5 * beam_radius_mm / pixel_size_mm
    x_edges = ndtr((np.arange(width + 1) - incident_px[0]) / sigma_px)
    y_edges = ndtr((np.arange(height + 1) - incident_px[1]) / sigma_px)
    return np.outer(np.diff(y_edges), np.diff(x_edges)) / pixel_size_mm ** 2


@functools.lru_cache(maxsize=None)
def _plugin_classes(variant: str):
    """Define the beam and sensor plugins for the active variant (once per variant)."""
    from ..backend import mitsuba

    mi = mitsuba()
    import drjit as dr

    # what the two plugins share: no bounding box, no differentiable parameters (nanobind
    # classes take one base, so no mixin)
    def no_bbox(self):
        return mi.ScalarBoundingBox3f()

    def no_parameters(self, *args):
        pass

    class SlabBeam(mi.Emitter):
        """Collimated Gaussian beam starting on a plane inside the medium, going down (-z).

        In a slab of finite thickness with a dielectric boundary the unscattered beam is
        partly reflected at the bottom face (and again at the top): those collimated
        beams light the medium too. They are a second delta direction, straight down to
        the ``return_plane_z`` plane just above the bottom face, chosen with probability
        proportional to its power.

        ================ ===== ======= ===========================================
        parameter        type  default meaning
        ================ ===== ======= ===========================================
        plane_z          float -1e-4   z of the origin plane, mm
        beam_radius      float         1/e^2 radius w of the irradiance, mm, > 0
        centre_x/y       float 0       beam axis, mm
        power_0/1/2      float 1       downward power per channel (all the bounces)
        return_plane_z   float -inf    z of the upward beam's origin plane, mm
        return_power_0.. float 0       upward power per channel at that plane
        ================ ===== ======= ===========================================
        """

        bbox, traverse, parameters_changed = no_bbox, no_parameters, no_parameters

        def __init__(self, props):
            super().__init__(props)
            self.plane_z = props.get("plane_z", -BEAM_DEPTH_MM)
            self.beam_radius = props.get("beam_radius")
            self.centre_x = props.get("centre_x", 0.0)
            self.centre_y = props.get("centre_y", 0.0)
            self.power = [props.get(f"power_{c}", 1.0) for c in range(3)]
            self.return_plane_z = props.get("return_plane_z", -math.inf)
            self.return_power = [props.get(f"return_power_{c}", 0.0) for c in range(3)]
            down, up = sum(self.power), sum(self.return_power)
            self.down_probability = down / (down + up) if up > 0 else 1.0
            self.m_flags = mi.EmitterFlags.DeltaDirection

        def irradiance(self, x, y):
            """Irradiance of unit power on an origin plane, per mm^2."""
            w2 = self.beam_radius * self.beam_radius
            rho2 = dr.square(x - self.centre_x) + dr.square(y - self.centre_y)
            return 2.0 / (dr.pi * w2) * dr.exp(-2.0 * rho2 / w2)

        def sample_direction(self, it, sample, active=True):
            # the downward beam is seen looking up, the returning one looking down
            look_up = sample.x < self.down_probability
            plane = dr.select(look_up, self.plane_z, self.return_plane_z)
            distance = dr.select(look_up, self.plane_z - it.p.z, it.p.z - self.return_plane_z)
            lit = active & (distance > 0.0)
            choice = dr.select(look_up, self.down_probability, 1.0 - self.down_probability)
            up_sign = dr.select(look_up, 1.0, -1.0)
            ds = dr.zeros(mi.DirectionSample3f)
            ds.p = mi.Point3f(it.p.x, it.p.y, plane)
            ds.n = mi.Normal3f(0.0, 0.0, -up_sign)
            ds.d = mi.Vector3f(0.0, 0.0, up_sign)
            ds.dist = dr.select(lit, distance, 0.0)
            ds.pdf = dr.select(lit, choice, 0.0)
            ds.delta = mi.Bool(True)
            ds.time = it.time
            power = mi.Spectrum(*[dr.select(look_up, down, up) for down, up
                                  in zip(self.power, self.return_power, strict=True)])
            weight = dr.select(lit, self.irradiance(it.p.x, it.p.y) / choice, 0.0)
            return ds, power * weight

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)  # delta in direction: never hit by a sampled direction

        def eval_direction(self, it, ds, active=True):
            return mi.Spectrum(0.0)

        def eval(self, si, active=True):
            return mi.Spectrum(0.0)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            raise NotImplementedError("the slab beam is only sampled from the camera side")

        def sample_position(self, time, sample, active=True):
            raise NotImplementedError("the slab beam is only sampled from the camera side")

        def to_string(self):
            return f"SlabBeam[w = {self.beam_radius} mm, plane z = {self.plane_z} mm]"

    class SlabExitanceSensor(mi.Sensor):
        """A film lying on a slab face: exitance (cosine-weighted) or normal radiance.

        ============ ====== ========== ==========================================
        parameter    type   default    meaning
        ============ ====== ========== ==========================================
        width_mm     float             film width on the slab, mm
        height_mm    float             film height, mm
        plane_z      float             z of the film plane (outside the slab), mm
        facing_up    bool   false      look up (+z) into the slab (transmission)
        exitance     bool   true       cosine-weighted directions, weight pi
        ============ ====== ========== ==========================================

        Film x maps to +x and film rows to +y, both centred on the origin.
        """

        bbox, traverse, parameters_changed = no_bbox, no_parameters, no_parameters

        def __init__(self, props):
            super().__init__(props)
            self.width_mm = props.get("width_mm")
            self.height_mm = props.get("height_mm")
            self.plane_z = props.get("plane_z")
            self.direction_sign = 1.0 if props.get("facing_up", False) else -1.0
            self.exitance = props.get("exitance", True)
            self.m_needs_sample_3 = self.exitance

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            origin = mi.Point3f((sample2.x - 0.5) * self.width_mm,
                                (sample2.y - 0.5) * self.height_mm, self.plane_z)
            if self.exitance:
                local = mi.warp.square_to_cosine_hemisphere(sample3)
                direction = mi.Vector3f(local.x, local.y, self.direction_sign * local.z)
                weight = dr.pi  # E = integral of L cos over the hemisphere = pi E_cos[L]
            else:
                direction = mi.Vector3f(0.0, 0.0, self.direction_sign)
                weight = 1.0
            ray = mi.Ray3f(origin, direction, time, dr.zeros(mi.Color0f))
            return ray, mi.Spectrum(weight)

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            return mi.RayDifferential3f(ray), weight

        def to_string(self):
            return f"SlabExitanceSensor[{self.width_mm} x {self.height_mm} mm]"

    mi.register_emitter(BEAM_PLUGIN, lambda props: SlabBeam(props))
    mi.register_sensor(SENSOR_PLUGIN, lambda props: SlabExitanceSensor(props))
    return SlabBeam, SlabExitanceSensor


def register_plugins():
    """Register the beam and sensor plugins with Mitsuba; return their classes."""
    from ..backend import mitsuba

    return _plugin_classes(mitsuba().variant())


def _rgb_texture(values) -> tuple[dict, float]:
    """Return an RGB texture of values that may exceed 1, and the scale that goes with it."""
    values = np.asarray(values, dtype=np.float64)
    scale = float(values.max())
    normalised = values / scale if scale > 0 else values
    return {"type": "rgb", "value": [float(v) for v in normalised]}, scale


def slab_scene_dict(material: Dipole, *, shape, pixel_size_mm, incident_px, side,
                    thickness_mm, beam_radius_mm, pass_spp, sensor="exitance") -> dict:
    """Return the Mitsuba ``load_dict`` description of the capture (see the module docstring).

    Parameters
    ----------
    material : Dipole
        sigma_a and sigma_s' (mm^-1) per channel and eta; rendered with the reduced
        coefficients and an isotropic phase function.
    shape : (int, int)
        ``(H, W)``, pixels.
    pixel_size_mm : float
    incident_px : (float, float)
        Beam axis ``(x, y)``, pixels (top-left corner of the image at 0, 0).
    side : {"reflection", "transmission"}
    thickness_mm : float or None
        None: :func:`semi_infinite_depth`.
    beam_radius_mm : float
        1/e^2 radius, mm, > 0.
    pass_spp : int
        Samples per pixel of one render call.
    sensor : {"exitance", "normal radiance"}

    Returns
    -------
    dict
    """
    from ..backend import mitsuba

    mi = mitsuba()
    register_plugins()
    height, width = shape
    depth = semi_infinite_depth(material) if thickness_mm is None else float(thickness_mm)
    width_mm, height_mm = width * pixel_size_mm, height * pixel_size_mm
    lateral = 0.5 * math.hypot(width_mm, height_mm) + LATERAL_MARGIN_DEPTHS * depth
    transform = mi.ScalarTransform4f
    sigma_t_prime = reduced_extinction(material.sigma_a, material.sigma_s_prime)
    albedo = reduced_albedo(material.sigma_a, material.sigma_s_prime)
    sigma_t_texture, sigma_t_scale = _rgb_texture(sigma_t_prime)
    boundary = {"type": "null"} if material.eta == 1.0 else \
        {"type": "dielectric", "int_ior": float(material.eta), "ext_ior": 1.0}
    collimated = collimated_powers(material, depth)
    plane_z = SENSOR_OFFSET_MM if side == "reflection" else -depth - SENSOR_OFFSET_MM
    return {
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": MAX_DEPTH,
                       "rr_depth": roulette_depth(material)},
        "sensor": {"type": SENSOR_PLUGIN, "width_mm": width_mm, "height_mm": height_mm,
                   "plane_z": plane_z, "facing_up": side == "transmission",
                   "exitance": sensor == "exitance",
                   "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                            "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                   "sampler": {"type": "independent", "sample_count": int(pass_spp)}},
        "slab": {"type": "cube",
                 "to_world": transform().translate([0.0, 0.0, -0.5 * depth])
                 @ transform().scale([lateral, lateral, 0.5 * depth]),
                 "bsdf": boundary,
                 "interior": {"type": "homogeneous", "sigma_t": sigma_t_texture,
                              "scale": sigma_t_scale,
                              "albedo": {"type": "rgb", "value": [float(a) for a in albedo]},
                              "phase": {"type": "isotropic"}}},
        "beam": {"type": BEAM_PLUGIN, "beam_radius": float(beam_radius_mm),
                 "plane_z": -BEAM_DEPTH_MM, "return_plane_z": -depth + BEAM_DEPTH_MM,
                 "centre_x": (incident_px[0] - 0.5 * width) * pixel_size_mm,
                 "centre_y": (incident_px[1] - 0.5 * height) * pixel_size_mm,
                 **{f"power_{c}": float(collimated["down"][c]) for c in range(3)},
                 **{f"return_power_{c}": float(collimated["up"][c]) for c in range(3)}},
    }


@dataclass
class VolpathRender:
    """A volpath exitance image and what it took.

    Attributes
    ----------
    exitance : ndarray, shape (H, W, 3)
        Mean over the passes, mm^-2 per unit entering power.
    standard_error : ndarray, shape (H, W, 3)
        Per pixel, from the spread of the passes.
    spp : int
        Samples per pixel in all (passes x pass_spp).
    passes : int
    pass_spp : int
    depth_mm : float
        Slab thickness rendered.
    unscattered : ndarray, shape (3,)
        Power of the unscattered beam leaving through the imaged face, per unit entering
        power (:func:`collimated_powers`), added to ``exitance`` over the beam's footprint.
    pixel_size_mm : float
    sensor : str
    variant : str
    seconds : float
    """

    exitance: np.ndarray
    standard_error: np.ndarray
    spp: int
    passes: int
    pass_spp: int
    depth_mm: float
    unscattered: np.ndarray
    pixel_size_mm: float
    sensor: str
    variant: str
    seconds: float

    @property
    def total(self) -> np.ndarray:
        """Power leaving through the film per unit entering power, per channel."""
        return self.exitance.sum(axis=(0, 1)) * self.pixel_area

    @property
    def pixel_area(self) -> float:
        """Pixel area, mm^2."""
        return self.pixel_size_mm ** 2

    def relative_standard_error(self) -> np.ndarray:
        """Relative standard error of the film's total exitance, per channel."""
        total_se = np.sqrt((self.standard_error ** 2).sum(axis=(0, 1))) * self.pixel_area
        total = self.total
        return np.where(total > 0, total_se / np.where(total > 0, total, 1.0), np.inf)

    def median_pixel_relative_error(self) -> np.ndarray:
        """Median over pixels of the per-pixel relative standard error, per channel."""
        with np.errstate(divide="ignore", invalid="ignore"):
            relative = self.standard_error / self.exitance
        relative = np.where(self.exitance > 0, relative, np.inf)
        return np.median(relative.reshape(-1, 3), axis=0)


def _grey_medium(material: Dipole, channel: int) -> Dipole:
    """Return ``material`` with channel ``channel``'s coefficients in all three channels."""
    return replace(material, sigma_a=np.full(3, material.sigma_a[channel]),
                   sigma_s_prime=np.full(3, material.sigma_s_prime[channel]))


def _channel_groups(material: Dipole, channels: str) -> list[tuple[int | None, list[int]]]:
    """Return the renders to make: (channel rendered as a grey medium, or None; targets).

    Channels with the same coefficients share one render.
    """
    if channels == "rgb":
        return [(None, [0, 1, 2])]
    groups: list[tuple[int | None, list[int]]] = []
    for c in range(3):
        for source, targets in groups:
            if (material.sigma_a[c] == material.sigma_a[source]
                    and material.sigma_s_prime[c] == material.sigma_s_prime[source]):
                targets.append(c)
                break
        else:
            groups.append((c, [c]))
    return groups


def _check_inputs(material, *, shape, pixel_size_mm, incident_px, side, thickness_mm,
                  beam_radius_mm, spp, pass_spp, sensor, channels):
    """Validate the arguments shared by :func:`render_exitance` and :func:`volpath_capture`."""
    if not isinstance(material, Dipole):
        raise InputError("must be a Dipole (sigma_a, sigma_s', eta)", field="material",
                         value=type(material).__name__)
    height, width = shape
    if int(height) < 1 or int(width) < 1:
        raise InputError("must be at least 1 x 1 pixels", field="size", value=shape)
    if not (np.isfinite(pixel_size_mm) and pixel_size_mm > 0):
        raise InputError("must be > 0 and finite, mm", field="pixel_size_mm",
                         value=pixel_size_mm)
    if not (0.0 <= incident_px[0] <= width and 0.0 <= incident_px[1] <= height):
        raise InputError(f"must lie inside the {width} x {height} image", field="incident_px",
                         value=tuple(incident_px))
    if side not in ("reflection", "transmission"):
        raise InputError("must be 'reflection' or 'transmission'", field="side", value=side)
    if thickness_mm is not None and not (np.isfinite(thickness_mm) and thickness_mm > 0):
        raise InputError("must be > 0 or None (semi-infinite), and finite", field="thickness_mm",
                         value=thickness_mm)
    if side == "transmission" and thickness_mm is None:
        raise InputError("transmission needs a finite thickness", field="thickness_mm",
                         value=None)
    if not (np.isfinite(beam_radius_mm) and beam_radius_mm > 0):
        raise InputError("must be > 0 and finite for volpath captures: camera paths cannot "
                         "find a pencil beam (use the walk or dipole generator for one)",
                         field="beam_radius_mm", value=beam_radius_mm)
    check_count(spp, "spp", 2, why=" (two passes at least, for the standard error)")
    check_count(pass_spp, "pass_spp")
    if sensor not in SENSOR_MODES:
        raise InputError(f"must be one of {', '.join(SENSOR_MODES)}", field="sensor",
                         value=sensor)
    if channels not in CHANNEL_MODES:
        raise InputError(f"must be one of {', '.join(CHANNEL_MODES)}", field="channels",
                         value=channels)


def render_exitance(material: Dipole, *, shape=(96, 96), pixel_size_mm: float = 0.1,
                    incident_px=None, side: str = "reflection",
                    thickness_mm: float | None = None, beam_radius_mm: float | None = None,
                    spp: int = 256, pass_spp: int = DEFAULT_PASS_SPP, sensor: str = "exitance",
                    channels: str = "separate", seed: int | None = None,
                    progress: bool = False) -> VolpathRender:
    """Render the exitance image of a beam-lit slab with Mitsuba ``volpath``, in passes.

    Parameters
    ----------
    material : Dipole
    shape : (int, int)
        ``(H, W)``.
    pixel_size_mm : float
    incident_px : (float, float), optional
        Beam axis, pixels (default: the image centre).
    side : {"reflection", "transmission"}
    thickness_mm : float or None
    beam_radius_mm : float, optional
        1/e^2 radius, mm, > 0 (default: :data:`DEFAULT_BEAM_FRACTION` of the field width).
    spp : int
        Samples per pixel in all, >= 2; split into ``ceil(spp / pass_spp)`` passes (at
        least 2) of equal size, so slightly more may be rendered.
    pass_spp : int
        Most samples per pixel in one pass.
    sensor : {"exitance", "normal radiance"}
        ``"normal radiance"`` converts with :func:`exitance_per_normal_radiance`.
    channels : {"separate", "rgb"}
        ``"separate"``: one render per distinct channel, of a grey medium with that
        channel's coefficients (see :data:`CHANNEL_MODES`); ``"rgb"``: one render of the
        chromatic medium.
    seed : int, optional
    progress : bool
        A progress bar over the passes (stderr).

    Returns
    -------
    VolpathRender
    """
    from ..backend import mitsuba

    height, width = shape
    if incident_px is None:
        incident_px = (width / 2.0, height / 2.0)
    if beam_radius_mm is None:
        beam_radius_mm = DEFAULT_BEAM_FRACTION * width * pixel_size_mm
    _check_inputs(material, shape=shape, pixel_size_mm=pixel_size_mm, incident_px=incident_px,
                  side=side, thickness_mm=thickness_mm, beam_radius_mm=beam_radius_mm,
                  spp=spp, pass_spp=pass_spp, sensor=sensor, channels=channels)
    began = time.perf_counter()
    passes = max(2, math.ceil(int(spp) / int(pass_spp)))
    per_pass = math.ceil(int(spp) / passes)
    mi = mitsuba()
    groups = _channel_groups(material, channels)
    rng = np.random.default_rng(seed)
    scale = 1.0 if sensor == "exitance" else exitance_per_normal_radiance(material.eta)
    images = np.zeros((passes, height, width, 3))
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=passes * len(groups), desc=f"volpath {per_pass} spp/pass",
                   unit="pass", leave=False)
    try:
        for source, targets in groups:
            medium = material if source is None else _grey_medium(material, source)
            scene = mi.load_dict(slab_scene_dict(
                medium, shape=(height, width), pixel_size_mm=pixel_size_mm,
                incident_px=incident_px, side=side, thickness_mm=thickness_mm,
                beam_radius_mm=beam_radius_mm, pass_spp=per_pass, sensor=sensor))
            for index, pass_seed in enumerate(rng.integers(0, 2**31, size=passes)):
                image = np.asarray(mi.render(scene, spp=per_pass, seed=int(pass_seed)),
                                   dtype=np.float64)[..., :3]
                rendered = image[..., targets] if source is None else image[..., :1]
                images[index][..., targets] = scale * rendered
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    depth = semi_infinite_depth(material) if thickness_mm is None else float(thickness_mm)
    # camera paths cannot see a collimated beam: its unscattered light leaving the face
    # is added in closed form
    unscattered = collimated_powers(material, depth)[
        "reflected" if side == "reflection" else "transmitted"]
    footprint = beam_pixel_image((height, width), pixel_size_mm, incident_px, beam_radius_mm)
    return VolpathRender(
        exitance=images.mean(axis=0) + footprint[..., None] * unscattered,
        standard_error=images.std(axis=0, ddof=1) / math.sqrt(passes),
        spp=passes * per_pass, passes=passes, pass_spp=per_pass,
        depth_mm=depth, unscattered=unscattered, pixel_size_mm=float(pixel_size_mm),
        sensor=sensor, variant=mi.variant(), seconds=time.perf_counter() - began)


def volpath_capture(material: Dipole, *, size: int | tuple[int, int] = 96,
                    pixel_size_mm: float = 0.1, incident_px=None, side: str = "reflection",
                    thickness_mm: float | None = None, beam_radius_mm: float | None = None,
                    spp: int = 256, pass_spp: int = DEFAULT_PASS_SPP, sensor: str = "exitance",
                    channels: str = "separate", camera: Camera | None = None,
                    seed: int | None = None, image_name: str = "capture.exr",
                    eta_known: bool = True, progress: bool = False):
    """Make a synthetic capture rendered by Mitsuba ``volpath``, with camera defects.

    Parameters are those of :func:`~translucent.fitting.synthetic.dipole_capture`, plus
    ``spp``, ``pass_spp``, ``sensor``, ``channels`` and ``progress`` (see
    :func:`render_exitance`);
    ``beam_radius_mm`` must be > 0 (default: :data:`DEFAULT_BEAM_FRACTION` of the field).

    Returns
    -------
    (ndarray, CaptureSpec, VolpathRender)
        Stored values, the sidecar (truth under ``synthetic``, with generator
        ``"mitsuba volpath"``, spp and variant) and the render.
    """
    camera = Camera() if camera is None else camera
    height, width = (size, size) if np.isscalar(size) else size
    if incident_px is None:
        incident_px = (width / 2.0, height / 2.0)
    if beam_radius_mm is None:
        beam_radius_mm = DEFAULT_BEAM_FRACTION * width * pixel_size_mm
    rng = np.random.default_rng(seed)
    render = render_exitance(material, shape=(height, width), pixel_size_mm=pixel_size_mm,
                             incident_px=incident_px, side=side, thickness_mm=thickness_mm,
                             beam_radius_mm=beam_radius_mm, spp=spp, pass_spp=pass_spp,
                             sensor=sensor, channels=channels, seed=int(rng.integers(2**31)),
                             progress=progress)
    stored, exposure = apply_camera(render.exitance, camera, rng)
    spec = capture_spec(material, camera, image_name=image_name, pixel_size_mm=pixel_size_mm,
                         incident_px=incident_px, side=side, thickness_mm=thickness_mm,
                         beam_radius_mm=beam_radius_mm, exposure=exposure, eta_known=eta_known,
                         generator="mitsuba volpath",
                         extra={"spp": int(render.spp), "passes": int(render.passes),
                                "variant": render.variant, "sensor": render.sensor,
                                "channels": channels,
                                "depth_mm": render.depth_mm,
                                "relative_standard_error":
                                    render.relative_standard_error().tolist(),
                                "seconds": render.seconds})
    return stored, spec, render
