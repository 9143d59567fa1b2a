r"""Synthetic slab captures with known truth, and the camera defects real captures have.

Two generators share one camera (:class:`Camera`):

* :func:`dipole_capture` renders the exact model the fitter assumes (dipole, or multipole
  for a slab), integrated over each pixel by supersampling and convolved with the beam by
  polar quadrature. Its implementation is independent of the fitter's forward operator
  (which uses exact pixel-ring overlaps and a Bessel kernel), so agreement between the two
  tests both.
* :func:`walk_capture` (in :mod:`translucent.fitting.random_walk`) scores photons of a
  random walk onto the film.

The camera turns the exitance image ``E`` (mm^-2 per unit entering power) into stored
values: ``exposure * E`` (code units) -> Poisson shot noise in electrons (``gain`` electrons
per code) -> Gaussian read noise (``read_noise`` codes) -> black level -> clipping at the
saturation level and at 0 -> rounding (PNG/TIFF) or float (OpenEXR).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError
from ..materials import Dipole
from ..materials.dipole import dipole_reflectance_profile
from ..materials.multipole import multipole_profiles
from .beam import beam_irradiance
from .capture import CaptureSpec, decode_pixels, encode_srgb

__all__ = ["Camera", "apply_camera", "default_pixel_size", "dipole_capture", "exitance_image",
           "material_profile_function"]

#: Sub-samples per pixel side for the exitance image, and for the pixels within
#: :data:`CENTRAL_PIXELS` of the incident point (where the dipole peaks on the scale of
#: its source depth, often well below a pixel). The midpoint rule underestimates a convex
#: profile by ~ h^2 f'' / 24: at 6 sub-samples that was 0.6-1.5e-4 of an annulus mean beyond
#: :data:`NEAR_PIXELS` (measured against 24), a third of the standard error of a bright
#: annulus of a capture that saturates; at 16, 1e-5 to 2e-5.
SUPERSAMPLE = 16
#: Shot noise above this mean (electrons) is drawn from the Gaussian limit of the Poisson
#: law (relative skewness 1e-6 there); numpy's Poisson sampler refuses means near 1e19.
POISSON_MEAN_LIMIT = 1e12
CENTRAL_SUPERSAMPLE = 64
CENTRAL_PIXELS = 2.5
#: Pixels within this many pixels of the incident point (and beyond the central ones) use
#: :data:`NEAR_SUPERSAMPLE`: where the profile falls like 1/r^3, midpoint sampling errs by
#: ~ (h / r)^2 / 2 relative, 1e-4 at 3 px with h = 1/24 px, below the noise of an annulus.
NEAR_PIXELS = 12.0
NEAR_SUPERSAMPLE = 24
#: Polar quadrature of the beam convolution: Gauss-Legendre points in radius (over 0..3 w,
#: beyond which the Gaussian beam holds 1.5e-8 of its power) and equally spaced angles.
BEAM_RADIAL_POINTS = 96
BEAM_ANGULAR_POINTS = 192


@dataclass(frozen=True)
class Camera:
    """A linear camera with the defects of a real one.

    Parameters
    ----------
    peak_signal : float
        Stored value above black that the brightest pixel would reach without clipping;
        sets the exposure. Above ``saturation_level - black_level`` the centre saturates.
    gain : float
        Electrons per stored unit (shot noise: Poisson in electrons). 0 disables it.
    read_noise : float
        Gaussian read noise, stored units (standard deviation).
    black_level : float
        Stored value of zero light.
    saturation_level : float
        Stored value at which pixels clip (65535 for 16 bits).
    encoding : str
        ``"linear"`` or ``"srgb"`` (PNG/TIFF only).
    exposure_known : bool
        Write the exposure into the sidecar (False: ``null``, a nuisance parameter).
    file_format : str
        ``"exr"``, ``"png"`` or ``"tiff"``.
    clip_at_black : bool
        Clip the stored values at the black level, as many cameras and HDR merges do (the
        noise below black is lost: those pixels are censored observations).
    saturated_fraction : float, optional
        Set the exposure instead of ``peak_signal``: this fraction of the image's pixels,
        in (0, 1), has a channel whose signal (before noise) reaches the saturation level.
    """

    peak_signal: float = 20000.0
    gain: float = 1.0
    read_noise: float = 4.0
    black_level: float = 256.0
    saturation_level: float = 65535.0
    encoding: str = "linear"
    exposure_known: bool = False
    file_format: str = "exr"
    clip_at_black: bool = False
    saturated_fraction: float | None = None

    def __post_init__(self):
        for name in ("peak_signal", "saturation_level"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise InputError("must be finite and > 0", field=name,
                                 value=getattr(self, name))
        for name in ("gain", "read_noise", "black_level"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise InputError("must be finite and >= 0", field=name,
                                 value=getattr(self, name))
        if self.file_format not in ("exr", "png", "tiff"):
            raise InputError("must be 'exr', 'png' or 'tiff'", field="file_format",
                             value=self.file_format)
        if self.encoding not in ("linear", "srgb"):
            raise InputError("must be 'linear' or 'srgb'", field="encoding", value=self.encoding)
        if self.encoding == "srgb" and self.file_format == "exr":
            raise InputError("OpenEXR is linear", field="encoding", value=self.encoding)
        if self.file_format != "exr" and self.saturation_level > 65535:
            raise InputError("16-bit files clip at 65535", field="saturation_level",
                             value=self.saturation_level)
        if self.saturated_fraction is not None and not 0 < self.saturated_fraction < 1:
            raise InputError("must be in (0, 1): the fraction of pixels that saturate",
                             field="saturated_fraction", value=self.saturated_fraction)
        if self.saturated_fraction is not None and \
                not self.saturation_level > self.black_level:
            raise InputError("must lie above black_level for pixels to saturate",
                             field="saturation_level", value=self.saturation_level)


def apply_camera(exitance, camera: Camera, rng, *, exposure: float | None = None):
    """Turn an exitance image into stored values: shot and read noise, black level, clipping.

    Parameters
    ----------
    exitance : ndarray, shape (H, W, 3)
        ``E`` in mm^-2 per unit entering power (pixel averages).
    camera : Camera
    rng : numpy.random.Generator
    exposure : float, optional
        Stored units per unit ``E``; default: ``camera.peak_signal / max(E)``, or with
        ``camera.saturated_fraction`` the exposure at which that fraction of the pixels has
        a channel at the saturation level before noise.

    Returns
    -------
    (ndarray, float)
        Stored values (H, W, 3), float64, and the exposure used.
    """
    exitance = np.asarray(exitance, dtype=np.float64)
    if exposure is None and camera.saturated_fraction is not None:
        brightest = np.quantile(exitance.max(axis=-1), 1.0 - camera.saturated_fraction)
        if not brightest > 0:
            raise InputError("the exitance image is black where pixels should saturate",
                             field="exitance", value=float(brightest))
        exposure = _ceiling_signal(camera) / float(brightest)
    if exposure is None:
        peak = float(np.max(exitance))
        if not peak > 0:
            raise InputError("the exitance image is black", field="exitance", value=peak)
        exposure = camera.peak_signal / peak
    signal = exposure * exitance
    if camera.gain > 0:
        electrons = np.clip(signal, 0, None) * camera.gain
        huge = electrons > POISSON_MEAN_LIMIT
        counts = rng.poisson(np.where(huge, 0.0, electrons)).astype(np.float64)
        if huge.any():  # numpy refuses such means; the Gaussian limit is exact enough there
            counts[huge] = rng.normal(electrons[huge], np.sqrt(electrons[huge]))
        signal = counts / camera.gain
    if camera.read_noise > 0:
        signal = signal + rng.normal(0.0, camera.read_noise, size=signal.shape)
    if camera.encoding == "srgb":
        spec = CaptureSpec(image="x.png", pixel_size_mm=1.0, incident_px=(0, 0),
                           black_level=camera.black_level)
        stored = encode_srgb(signal, spec)
    else:
        stored = signal + camera.black_level
    stored = np.minimum(stored, camera.saturation_level)
    if camera.clip_at_black:
        stored = np.maximum(stored, camera.black_level)
    if camera.file_format != "exr":
        stored = np.clip(np.rint(stored), 0.0, 65535.0)
    return stored, float(exposure)


def _ceiling_signal(camera: Camera) -> float:
    """Return the signal above black (linear, stored units) at which ``camera`` saturates."""
    if camera.encoding == "linear":
        return camera.saturation_level - camera.black_level
    spec = CaptureSpec(image="x.png", pixel_size_mm=1.0, incident_px=(0, 0),
                       black_level=camera.black_level, encoding="srgb")
    return float(decode_pixels(np.array([camera.saturation_level]), spec)[0])


def material_profile_function(material: Dipole, *, side="reflection", thickness_mm=None):
    """``f(r) -> (..., 3)`` exitance per unit entering power, mm^-2, for the dipole model.

    Semi-infinite reflection: Eq. 2 of Wang et al. 2008 (Jensen et al. 2001); slabs:
    the multipole of Donner & Jensen 2005 (:mod:`translucent.materials.multipole`).
    """
    sigma_a, sigma_s_prime, eta = material.sigma_a, material.sigma_s_prime, material.eta
    if side == "transmission":
        if thickness_mm is None:
            raise InputError("transmission needs a finite thickness", field="thickness_mm",
                             value=None)
        return lambda r: multipole_profiles(np.asarray(r)[..., None], sigma_a, sigma_s_prime,
                                            eta, thickness_mm)[1]
    if thickness_mm is None:
        return lambda r: dipole_reflectance_profile(np.asarray(r)[..., None], sigma_a,
                                                    sigma_s_prime, eta)
    return lambda r: multipole_profiles(np.asarray(r)[..., None], sigma_a, sigma_s_prime,
                                        eta, thickness_mm, transmission=False)[0]


def _beam_convolved_table(profile_fn, beam_radius_mm, r_max_mm, beam_profile="gaussian"):
    """Tabulate the beam-convolved profile on a fine radial table, by polar quadrature."""
    w = beam_radius_mm
    table_r = np.concatenate([[0.0], np.geomspace(1e-4, r_max_mm, 1200)])
    radial, radial_w = np.polynomial.legendre.leggauss(BEAM_RADIAL_POINTS)
    # Gauss-Legendre over the beam: [0, 3 w] for a Gaussian, the disk for a top hat
    half = 1.5 * w if beam_profile == "gaussian" else 0.5 * w
    b = half * (radial + 1.0)
    b_weight = half * radial_w * b * beam_irradiance(b, w, beam_profile)
    phi = np.linspace(0.0, 2.0 * np.pi, BEAM_ANGULAR_POINTS, endpoint=False)
    phi_weight = 2.0 * np.pi / BEAM_ANGULAR_POINTS
    out = np.zeros((table_r.size, 3))
    for start in range(0, table_r.size, 64):
        rho = table_r[start:start + 64, None, None]
        distance = np.sqrt(rho ** 2 + b[None, :, None] ** 2
                           - 2.0 * rho * b[None, :, None] * np.cos(phi)[None, None, :])
        values = profile_fn(distance)
        out[start:start + 64] = np.einsum("rbpc,b->rc", values, b_weight) * phi_weight
    total = b_weight.sum() * 2.0 * np.pi
    return table_r, out / total


def exitance_image(profile_fn, shape, pixel_size_mm, centre_px, beam_radius_mm=0.0,
                   beam_profile="gaussian"):
    """Pixel-averaged exitance image of a radial profile, optionally convolved with the beam.

    Parameters
    ----------
    profile_fn : callable
        ``r (mm, any shape) -> (..., 3)`` exitance per unit entering power, mm^-2.
    shape : (int, int)
        ``(H, W)``.
    pixel_size_mm : float
    centre_px : (float, float)
        Incident point ``(x, y)``, pixels (top-left corner of the image at 0, 0).
    beam_radius_mm : float
        1/e^2 radius of the Gaussian beam, or a top hat's radius, mm (0: pencil).
    beam_profile : {"gaussian", "top_hat"}

    Returns
    -------
    ndarray, shape (H, W, 3)
        mm^-2.
    """
    height, width = shape
    cx, cy = centre_px
    r_max = np.hypot(max(cx, width - cx), max(cy, height - cy)) * pixel_size_mm * 1.01 + 1e-9
    if beam_radius_mm > 0:
        table_r, table = _beam_convolved_table(profile_fn, beam_radius_mm, r_max,
                                               beam_profile)

        def evaluate(r):
            return np.stack([np.interp(r, table_r, table[:, c]) for c in range(3)], axis=-1)
    else:
        evaluate = profile_fn
    image = np.zeros((height, width, 3))
    offsets = (np.arange(SUPERSAMPLE) + 0.5) / SUPERSAMPLE
    for row in range(height):
        ys = row + offsets
        xs = np.arange(width)[:, None] + offsets[None, :]
        dx = (xs - cx)[:, None, :]
        dy = (ys - cy)[None, :, None]
        r = np.hypot(dx, dy) * pixel_size_mm
        image[row] = evaluate(r).mean(axis=(1, 2))
    for reach, count in ((NEAR_PIXELS, NEAR_SUPERSAMPLE), (CENTRAL_PIXELS, CENTRAL_SUPERSAMPLE)):
        fine = (np.arange(count) + 0.5) / count
        rows = range(max(0, int(cy - reach)), min(height, int(cy + reach) + 1))
        cols = range(max(0, int(cx - reach)), min(width, int(cx + reach) + 1))
        for row in rows:
            for col in cols:
                r = np.hypot(col + fine[None, :] - cx, row + fine[:, None] - cy) * pixel_size_mm
                image[row, col] = evaluate(r).mean(axis=(0, 1))
    return image


def dipole_capture(material: Dipole, *, size: int | tuple[int, int] = 96,
                   pixel_size_mm: float = 0.1, incident_px=None, side: str = "reflection",
                   thickness_mm: float | None = None, beam_radius_mm: float = 0.0,
                   camera: Camera | None = None, seed: int | None = None,
                   image_name: str = "capture.exr", eta_known: bool = True,
                   beam_profile: str = "gaussian"):
    """Make a synthetic capture of the exact dipole/multipole model, with camera defects.

    Parameters
    ----------
    material : Dipole
        The truth.
    size : int or (int, int)
        Image size, pixels (``(H, W)``).
    pixel_size_mm : float
    incident_px : (float, float), optional
        Incident point (default: the image centre).
    side : str
    thickness_mm : float or None
    beam_radius_mm : float
    camera : Camera, optional
        Default: ``Camera()``.
    seed : int, optional
    image_name : str
        The sidecar's ``image`` (its suffix should match ``camera.file_format``).
    eta_known : bool
        Write eta into the sidecar (False: null, eta is fitted).
    beam_profile : {"gaussian", "top_hat"}
        The beam's shape, written into the sidecar.

    Returns
    -------
    (ndarray, CaptureSpec)
        Stored values (H, W, 3) and the sidecar; ``spec.synthetic`` holds the truth.
    """
    camera = Camera() if camera is None else camera
    height, width = (size, size) if np.isscalar(size) else size
    if incident_px is None:
        incident_px = (width / 2.0, height / 2.0)
    incident_px = check_incident(incident_px, width, height)
    check_geometry(pixel_size_mm, thickness_mm, beam_radius_mm)
    profile_fn = material_profile_function(material, side=side, thickness_mm=thickness_mm)
    exitance = exitance_image(profile_fn, (height, width), pixel_size_mm, incident_px,
                              beam_radius_mm, beam_profile)
    rng = np.random.default_rng(seed)
    stored, exposure = apply_camera(exitance, camera, rng)
    spec = capture_spec(material, camera, image_name=image_name, pixel_size_mm=pixel_size_mm,
                         incident_px=incident_px, side=side, thickness_mm=thickness_mm,
                         beam_radius_mm=beam_radius_mm, exposure=exposure, eta_known=eta_known,
                         generator="dipole")
    return stored, replace(spec, beam_profile=beam_profile)


def check_geometry(pixel_size_mm, thickness_mm, beam_radius_mm):
    """:class:`InputError` naming the first length that is not finite or out of range (mm)."""
    if not (np.isfinite(pixel_size_mm) and pixel_size_mm > 0):
        raise InputError("must be finite and > 0, mm", field="pixel_size_mm",
                         value=pixel_size_mm)
    if thickness_mm is not None and not (np.isfinite(thickness_mm) and thickness_mm > 0):
        raise InputError("must be finite and > 0, mm (None: a semi-infinite slab)",
                         field="thickness_mm", value=thickness_mm)
    if not (np.isfinite(beam_radius_mm) and beam_radius_mm >= 0):
        raise InputError("must be finite and >= 0, mm (0: a pencil beam)",
                         field="beam_radius_mm", value=beam_radius_mm)


def check_incident(incident_px, width, height):
    """Return ``incident_px`` as floats; :class:`InputError` unless it lies inside the image.

    The capture format takes an incident point inside the image only (the fitter refuses
    any other), so a generator must not write one.
    """
    x, y = (float(v) for v in incident_px)
    if not (0.0 <= x <= width and 0.0 <= y <= height):
        raise InputError(f"must lie inside the {width} x {height} image (x in [0, {width}], "
                         f"y in [0, {height}])", field="incident_px", value=(x, y))
    return x, y


def capture_spec(material, camera, *, image_name, pixel_size_mm, incident_px, side,
                  thickness_mm, beam_radius_mm, exposure, eta_known, generator, extra=None):
    """Return the sidecar of a synthetic capture, with its truth under ``synthetic``."""
    truth = {"generator": generator, "sigma_a": material.sigma_a.tolist(),
             "sigma_s_prime": material.sigma_s_prime.tolist(), "eta": material.eta,
             "g": material.g, "exposure": exposure, "incident_px": list(incident_px),
             "camera": {"peak_signal": camera.peak_signal, "gain": camera.gain,
                        "read_noise": camera.read_noise}}
    if camera.saturated_fraction is not None:
        truth["camera"]["saturated_fraction"] = camera.saturated_fraction
    if material.name:
        truth["material"] = material.name
    truth.update(extra or {})
    return CaptureSpec(image=image_name, pixel_size_mm=float(pixel_size_mm),
                       incident_px=(float(incident_px[0]), float(incident_px[1])), side=side,
                       thickness_mm=thickness_mm, eta=material.eta if eta_known else None,
                       beam_radius_mm=float(beam_radius_mm), black_level=camera.black_level,
                       saturation_level=camera.saturation_level,
                       exposure=exposure if camera.exposure_known else None,
                       encoding=camera.encoding, synthetic=truth)


def default_pixel_size(material: Dipole, size: int) -> float:
    """Pixel size (mm) for a ``size``-pixel image spanning ~12 diffusion lengths.

    The half-width is 6 / sigma_tr of the most absorbing channel (the light has fallen by
    e^-6 and more there), at most 30 transport lengths of the most scattering-poor
    channel (a non-absorbing medium has no diffusion length).
    """
    sigma_tr = float(np.max(material.sigma_tr))
    transport = float(np.max(material.mean_free_path))
    half_width = 6.0 / sigma_tr if sigma_tr > 0 else 30.0 * transport
    return min(half_width, 30.0 * transport) * 2.0 / size


def with_camera(camera: Camera, **changes) -> Camera:
    """Return a copy of ``camera`` with ``changes``."""
    return replace(camera, **changes)
