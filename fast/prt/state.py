"""The interactive PRT state: relighting and material editing (Wang et al. 2008, Eq. 7-10)."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field

import numba
import numpy as np

from ...errors import InputError
from ...image import Image
from ...materials import Dipole
from ...materials.dipole import dipole_reflectance_profile, total_diffuse_reflectance
from ...materials.dipole_pca import (
    DipolePCABasis,
    truncated_diffuse_reflectance,
)
from ...materials.fresnel import fresnel_transmittance
from ...scenes.scene import (
    ConstantEnvironment,
    ImageEnvironment,
)
from ..base import StageLog
from ..indirect_light import IndirectLight, reflectance_of
from ..knobs import DEFAULT_PROFILE
from ..wavelets import (
    SpatialWavelet,
)
from .knobs import (
    ENERGY_BLEND_END,
    ENERGY_BLEND_START,
    LOCAL_BLEND_END,
    LOCAL_BLEND_START,
    PRT_VERSION,
    RESOLUTION_BLEND_OCTAVES,
    SAMPLING_BLEND_END,
    SAMPLING_BLEND_START,
    UNKEYED_KNOBS,
    pca_basis_for,
)
from .lighting import EnvironmentTransfer, precompute_environment, sample_irradiance
from .profile_basis import ProfileFamily, project_profile_with_energy
from .transfer import ObjectTransfer

# ----------------------------------------------------------------- the state


def brute_force_radiance(transfer: ObjectTransfer, vertices, irradiance, material: Dipole,
                         *, mm_per_unit: float = 1.0, vertex_indices=None,
                         profile=None) -> np.ndarray:
    r"""Eq. 1-2 evaluated directly on the same samples: :math:`\sum_i R_d(r_{vi}) A_i E_i`.

    No basis, no wavelets, no quantisation: the exact dipole :math:`R_d` (all distances,
    also beyond 65 mm), or the exact ``profile``. Omits :math:`F_t(\omega_o)/\pi`, like the
    vertex values of :meth:`PRTState.vertex_radiance`.

    Parameters
    ----------
    transfer : ObjectTransfer
        For its samples.
    vertices : ndarray, (V, 3)
        The object's vertices, scene units.
    irradiance : ndarray, (N, 3)
        E at the samples (:func:`sample_irradiance`).
    material : Dipole
    mm_per_unit : float
    vertex_indices : array_like of int, optional
        Evaluate only these vertices (cost V x N).
    profile : RadialProfile, optional
        The material's profile of another family (the knob ``profile``) instead of the
        dipole's :math:`R_d`.

    Returns
    -------
    ndarray, (V, 3) or (len(vertex_indices), 3), float64
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    if vertex_indices is not None:
        vertices = vertices[np.asarray(vertex_indices)]
    samples = transfer.samples
    out = np.zeros((len(vertices), 3))
    block = max(1, (1 << 22) // len(samples))
    for start in range(0, len(vertices), block):
        chunk = vertices[start:start + block]
        distance = np.linalg.norm(chunk[:, None, :] - samples.positions[None, :, :],
                                  axis=-1) * mm_per_unit
        values = dipole_reflectance_profile(distance[..., None], material.sigma_a,
                                            material.sigma_s_prime, material.eta) \
            if profile is None else profile.reflection(distance)
        out[start:start + block] = np.einsum("vnc,nc->vc", values, irradiance) * samples.area
    return out


def _material(material) -> Dipole:
    if not isinstance(material, Dipole):
        raise InputError("the prt method renders homogeneous translucent materials: give a "
                         "Dipole", field="material", value=type(material).__name__)
    return material


@dataclass
class _PixelMap:
    """Where an object's vertices land in the image: barycentric gathers, exit cosines."""

    pixels: np.ndarray
    corners: np.ndarray
    barycentrics: np.ndarray
    cosine: np.ndarray


#: Materials whose profiles (the knob ``profile``) a state keeps, the oldest dropped first.
KEPT_PROFILES = 32

#: E^w counts as one colour when its second singular value is below this fraction of the
#: first (float32 round-off of the Haar transform is ~1e-7).
SINGLE_COLOUR_TOLERANCE = 1e-6


def single_colour(values) -> np.ndarray | None:
    """Return the unit RGB ``c`` with ``values ~ (values @ c) c^T``, or None if E has colours."""
    gram = values.astype(np.float64).T @ values.astype(np.float64)
    eigenvalues, eigenvectors = np.linalg.eigh(gram)
    if eigenvalues[-1] <= 0 or eigenvalues[-2] > SINGLE_COLOUR_TOLERANCE**2 * eigenvalues[-1]:
        return None
    colour = eigenvectors[:, -1]
    return (colour if colour.sum() >= 0 else -colour).astype(np.float32)


@numba.njit(cache=True, nogil=True, fastmath=True)
def _combine(vectors, coefficients, out):  # pragma: no cover
    """``out[c, r] = sum_k coefficients[c, k] vectors[c, k, r]`` (Eq. 7): the editing step."""
    for c in range(vectors.shape[0]):
        for r in range(vectors.shape[2]):
            out[c, r] = 0.0
        for k in range(vectors.shape[1]):
            weight = coefficients[c, k]
            for r in range(vectors.shape[2]):
                out[c, r] += weight * vectors[c, k, r]


def _same_lights(first, second) -> bool:
    """Return whether two sequences hold the same objects (lights, materials), in order."""
    return len(first) == len(second) and all(a is b for a, b in zip(first, second, strict=True))


def _ramp(value, start, end):
    return np.clip((value - start) / (end - start), 0.0, 1.0)


def projection_blend(basis: DipolePCABasis, sigma_a, sigma_s_prime, eta,
                     sample_spacing: float | None = None, profile=None):
    r"""Coefficients :math:`s_k(\sigma)` and the weight :math:`\beta` of the local vector.

    Sect. 3.3 (step 3) of Wang et al. 2008 projects the profile onto the basis of Eq. 4;
    :math:`\beta` in [0, 1] is the weight of the local (opaque-limit) vector instead,
    0 where the projection is trusted. It is the largest of three weights, each a linear
    ramp from 0 to 1:

    * residual :math:`\rho` of the projection (:meth:`DipolePCABasis.project_with_residual`),
      from :data:`LOCAL_BLEND_START` to :data:`LOCAL_BLEND_END`;
    * relative energy error :math:`|E_K - E|/E` of the K-term profile against the exact one,
      both :math:`2\pi\int_0^{65} R(r)\,r\,dr` (:meth:`DipolePCABasis.project_with_energy`),
      from :data:`ENERGY_BLEND_START` to :data:`ENERGY_BLEND_END`;
    * sampling: :math:`\log_2(\Delta / \ell)`, with :math:`\ell = 1/\sigma'_t` the reduced
      mean free path and :math:`\Delta` the spacing of the basis's first two distances (0.1 mm
      for the paper's basis), from 0 to :data:`RESOLUTION_BLEND_OCTAVES`;
    * with ``sample_spacing`` h (mm), the fraction of the profile's energy within h,
      :math:`R_d(h) / R_d(65)` (closed form:
      :func:`~translucent.materials.dipole_pca.truncated_diffuse_reflectance`), from
      :data:`SAMPLING_BLEND_START` to :data:`SAMPLING_BLEND_END`: the illumination samples
      cannot integrate a profile that lives between them.

    A projection is trusted (:math:`\beta = 0`) only when all the weights are 0; the
    measured media inside a basis's grid always are (the paper's method unchanged), with
    the sampling weight at the default 16384 samples on a 10 mm sphere or denser (0.28 mm).
    About 0.3 ms for three channels.

    Parameters
    ----------
    basis : DipolePCABasis
    sigma_a, sigma_s_prime : array_like
        mm^-1, >= 0, broadcast together (RGB: shape (3,)).
    eta : array_like
        Relative index of refraction in [1, 3].
    sample_spacing : float, optional
        Spacing of the illumination samples, mm; None leaves the last weight out (the
        projection alone).
    profile : RadialProfile, optional
        The medium's profile of another family than the dipole's (the knob ``profile``),
        sampled for the projection, its residual and energies
        (:func:`~translucent.fast.prt.profile_basis.project_profile_with_energy`) and
        its energy within h (its :meth:`total` to h); None: the dipole in closed form.

    Returns
    -------
    coefficients : ndarray, shape ``broadcast shape + (K,)``
    blend : ndarray, broadcast shape
        :math:`\beta`, dimensionless.
    """
    if profile is None:
        coefficients, residual, energy, exact_energy = basis.project_with_energy(
            sigma_a, sigma_s_prime, eta)
    else:
        coefficients, residual, energy, exact_energy = project_profile_with_energy(basis,
                                                                                  profile)
    energy_error = np.abs(energy - exact_energy) / np.where(exact_energy > 0, exact_energy, 1.0)
    spacing = float(basis.radii[1] - basis.radii[0])
    sigma_t_prime = np.asarray(sigma_a, np.float64) + np.asarray(sigma_s_prime, np.float64)
    with np.errstate(divide="ignore"):
        octaves = np.log2(spacing * sigma_t_prime)
    weights = [_ramp(residual, LOCAL_BLEND_START, LOCAL_BLEND_END),
               _ramp(energy_error, ENERGY_BLEND_START, ENERGY_BLEND_END),
               _ramp(octaves, 0.0, RESOLUTION_BLEND_OCTAVES)]
    if sample_spacing is not None:
        within = truncated_diffuse_reflectance(sigma_a, sigma_s_prime, eta, sample_spacing) \
            if profile is None else profile.total(max_radius=sample_spacing)
        fraction = within / np.where(exact_energy > 0, exact_energy, 1.0)
        weights.append(_ramp(fraction, SAMPLING_BLEND_START, SAMPLING_BLEND_END))
    blend = np.maximum.reduce(weights)
    return coefficients, np.broadcast_to(blend, residual.shape)


@dataclass
class PRTState:
    """What :func:`precompute` returns; ``render(lights=None, material=None) -> Image``.

    Holds the precomputed transfers, the G-buffer of the scene's camera (computed on first
    render) and, per object, the per-basis vectors :math:`v_k` of the last lighting: a new
    material only re-weights them (editing), new lights recompute them (relighting).
    """

    scene: object
    knobs: dict
    transfers: list
    log: StageLog = field(default_factory=StageLog)
    #: the light the scene's diffuse surfaces bounce onto the objects (None: lights alone)
    indirect: IndirectLight | None = None
    #: each object's geometry correction (fast.object_geometry) with its samples' and
    #: vertices' cluster weights; an object without one keeps the half-space profile
    geometry: dict = field(default_factory=dict)

    def __post_init__(self):
        self.basis = pca_basis_for(self.knobs)
        # another profile than the dipole's: a material is projected by sampling its profile
        self.family = None if self.knobs["profile"] == DEFAULT_PROFILE else \
            ProfileFamily(self.knobs["profile"])
        self._profiles: dict = {}
        self._lighting: dict = {}
        self._entry_power: dict = {}
        self._vertex_vectors: dict = {}
        self._product_buffers: dict = {}
        self._frames_lit: dict = {}
        self._pixels: dict | None = None
        self._exit_factors: dict = {}
        self._environment: dict = {}
        self._wavelets = {t.name: SpatialWavelet(t.spatial_shape) for t in self.transfers
                          if t.spatial_shape is not None}
        # the materials whose exitance the last relighting bounced back (an edit keeps it)
        self._bounce_materials = {t.name: self.scene.object(t.name).material
                                  for t in self.transfers}
        self._bounced = None  # (lights, materials, radiosity) of the last bounce solve
        self._lock = threading.Lock()

    def _environment_transfer(self, transfer: ObjectTransfer, lights):
        if not any(isinstance(light, (ConstantEnvironment, ImageEnvironment)) for light in lights):
            self.log.notes["environment"] = ("no environment light: no environment visibility "
                                             "precomputed")
            return None
        from ...cache import Cache, content_hash

        # the scene and knobs are fixed for the state: one visibility per object, and the
        # geometry is hashed only when it is first needed, not on every relighting frame
        if transfer.name not in self._environment:
            resolution = self.knobs["environment_resolution"]
            terms = self.knobs["environment_terms"]
            key = content_hash("prt-environment", PRT_VERSION, self.scene.geometry_key(),
                               transfer.name, resolution, terms,
                               {k: v for k, v in self.knobs.items() if k not in UNKEYED_KNOBS})
            cache = Cache("prt")
            environment = cache.load_object(key)
            if not isinstance(environment, EnvironmentTransfer):
                start = time.perf_counter()
                environment = precompute_environment(self.scene, transfer.samples, resolution,
                                                     terms)
                cache.store_object(key, environment)
                self.log.seconds["environment visibility"] = time.perf_counter() - start
            self._environment[transfer.name] = environment
        return self._environment[transfer.name]

    def irradiance(self, transfer: ObjectTransfer, lights, eta: float) -> np.ndarray:
        """Return E at the samples of one object, (N, 3).

        The lights' (:func:`sample_irradiance`) plus, with indirect light, what the scene's
        diffuse surfaces bounce (:class:`~translucent.fast.indirect_light.IndirectLight`).
        """
        direct = sample_irradiance(self.scene, transfer.samples, lights, eta,
                                   area_light_samples=self.knobs["area_light_samples"],
                                   environment=self._environment_transfer(transfer, lights),
                                   seed=self.knobs["seed"])
        if self.indirect is None:
            return direct
        return direct + self.indirect.irradiance(transfer.name, self._radiosity(lights), eta)

    def _radiosity(self, lights) -> np.ndarray:
        """Return the surfaces' radiosity under ``lights``, solved once for every object."""
        materials = tuple(self._bounce_materials.values())
        held = self._bounced
        if held is not None and _same_lights(held[1], materials) \
                and _same_lights(held[0], lights):
            return held[2]
        names = [item.name for item in self.scene.objects]
        reflectance = {names.index(name): found for name, material in
                       self._bounce_materials.items()
                       if (found := reflectance_of(material)) is not None}
        radiosity, facts = self.indirect.radiosity(
            self.scene, lights, bounces=self.knobs["indirect_bounces"],
            light_samples=self.knobs["area_light_samples"], seed=self.knobs["seed"],
            reflectance=reflectance)
        self.log.notes["indirect bounces"] = facts
        self._bounced = (tuple(lights), materials, radiosity)
        return radiosity

    def basis_vectors(self, transfer: ObjectTransfer, irradiance) -> np.ndarray:
        """:math:`v_k = {}^wT_k^w E^w` (Eq. 8-9) for all k, shape (3, K + 1, R), float32.

        Lights of one colour make E one spectrum times one scalar field: then a single
        channel is multiplied (the matrix is read once either way, for a third of the
        arithmetic) and the colour applied afterwards. The products are written into
        buffers kept per object (no allocation per frame); the returned array is a copy
        only the caller holds.
        """
        irradiance_w = transfer.samples.to_wavelets(irradiance)
        shape = (transfer.basis_terms + 1, transfer.row_count)
        colour = single_colour(irradiance_w)
        channels = () if colour is not None else (3,)
        key = (transfer.name, channels)
        if key not in self._product_buffers:
            self._product_buffers[key] = np.empty((transfer.transfer.rows,) + channels,
                                                  dtype=np.float32)
        products = self._product_buffers[key]
        if colour is not None:
            transfer.transfer.product(irradiance_w @ colour, out=products)
            return colour[:, None, None] * products.reshape(shape)[None]
        transfer.transfer.product(irradiance_w, out=products)
        return np.ascontiguousarray(products.T.reshape((3,) + shape))

    def relight(self, transfer: ObjectTransfer, lights, eta: float) -> None:
        """Recompute E and the per-basis vectors of one object for ``lights`` and ``eta``."""
        lights = tuple(lights)
        start = time.perf_counter()
        irradiance = self.irradiance(transfer, lights, eta)
        middle = time.perf_counter()
        vectors = self.basis_vectors(transfer, irradiance)
        self.log.seconds["irradiance"] = middle - start
        self.log.seconds["transfer product"] = time.perf_counter() - middle
        self._lighting[transfer.name] = (lights, float(eta), vectors)
        # E A at the samples, for the geometry correction's entry clusters
        self._entry_power[transfer.name] = irradiance * transfer.samples.area
        self._vertex_vectors.pop(transfer.name, None)
        self._frames_lit[transfer.name] = 0

    def _spatial_vertex_vectors(self, transfer: ObjectTransfer) -> np.ndarray | None:
        r"""Per-basis vectors in vertex space, or None while only one frame used this light.

        The inverse CDF 9/7 is linear, so :math:`W^{-1} \sum_k s_k v_k = \sum_k s_k
        W^{-1} v_k`: once a second frame (an edit) uses the same lighting, every basis
        vector is transformed back once and each further edit is a plain weighted sum (no
        transfer product and no inverse transform redone; Sect. 3.3 of Wang et al. 2008).
        The first frame after a relighting transforms the 3 combined channels instead (13x
        cheaper), so relighting frames do not pay for it.
        """
        cached = self._vertex_vectors.get(transfer.name)
        if cached is None and self._frames_lit.get(transfer.name, 0) >= 1:
            _, _, vectors = self._lighting[transfer.name]
            channels, blocks, rows = vectors.shape
            coefficients = np.moveaxis(vectors, 2, 0).reshape(rows, channels * blocks)
            values = self._wavelets[transfer.name].inverse(coefficients)
            cached = np.ascontiguousarray(np.moveaxis(values.reshape(rows, channels, blocks),
                                                      0, 2))
            self._vertex_vectors[transfer.name] = cached
        self._frames_lit[transfer.name] = self._frames_lit.get(transfer.name, 0) + 1
        return cached

    def vertex_radiance(self, transfer: ObjectTransfer, material: Dipole) -> np.ndarray:
        r"""Per-vertex :math:`\sum_k s_k(\sigma) v_k` (Eq. 7/10), before :math:`F_t/\pi`, (V, 3).

        Uses the per-basis vectors of the object's last :meth:`relight`.
        """
        _, _, vectors = self._lighting[transfer.name]
        spatial = transfer.spatial_shape is not None
        in_vertex_space = self._spatial_vertex_vectors(transfer) if spatial else vectors
        source = vectors if in_vertex_space is None else in_vertex_space
        combined = np.empty((3, source.shape[2]), dtype=np.float32)
        spacing = float(np.sqrt(transfer.samples.area)) if self.knobs["sampling_blend"] \
            else None
        _combine(source, self.coefficients(material, spacing), combined)
        combined = combined.T
        if in_vertex_space is None:
            combined = self._wavelets[transfer.name].inverse(combined)
        return combined

    def exit_radiance(self, transfer: ObjectTransfer, material: Dipole) -> np.ndarray:
        r"""Per-vertex exitance before :math:`F_t/\pi`, (V, 3): the profile's and the geometry's.

        :meth:`vertex_radiance` plus, where the object has one, the geometry correction
        of the last lighting (:mod:`translucent.fast.object_geometry`).
        """
        radiance = self.vertex_radiance(transfer, material)
        if transfer.name not in self.geometry:
            return radiance
        geometry, entry, exit_weights = self.geometry[transfer.name]
        profile = self.profile_of(material)
        # an exitance: the walks' noise can take the sum below zero where both are dark
        return np.maximum(radiance + geometry.exitance(
            entry, self._entry_power[transfer.name], exit_weights, material,
            profile).astype(np.float32), 0.0)

    def coefficients(self, material: Dipole, sample_spacing: float | None = None) -> np.ndarray:
        r"""Weights of the K basis vectors and of the local vector, per channel, (3, K + 1).

        :math:`s_k(\sigma)` (Sect. 3.3, step 3) for profiles the basis represents. A profile
        it cannot represent (mean free path far below the sampled distances: the paper's
        "uninteresting cases where multiple scattering is insignificant ... more appropriate
        to handle using the diffuse BRDF model", Sect. 4) is blended, by the projection's
        weight :math:`\beta` of :func:`projection_blend` (residual, energy and sampling of
        the projection; with ``sample_spacing`` in mm, also how well the illumination
        samples resolve the profile), into exactly that: the local vector (irradiance averaged
        around each vertex) times the total diffuse reflectance :math:`R_d` (closed form), so
        that in the opaque limit the object is a Lambertian surface of albedo :math:`R_d`,
        the limit of the dipole. For the measured media inside the basis's grid
        :math:`\beta = 0`: the paper's method unchanged. With another profile than the
        dipole's (the knob ``profile``) the projection samples the material's profile of
        that family and the local vector carries its total.
        """
        profile = self.profile_of(material)
        coefficients, blend = projection_blend(self.basis, material.sigma_a,
                                               material.sigma_s_prime, material.eta,
                                               sample_spacing, profile)
        total = total_diffuse_reflectance(material.sigma_a, material.sigma_s_prime,
                                          material.eta) if profile is None else profile.total()
        local = blend * total
        kept = (1.0 - blend)[:, None] * coefficients
        return np.concatenate([kept, local[:, None]], axis=1).astype(np.float32)

    def profile_of(self, material: Dipole):
        """Return the material's profile of the knob ``profile`` (None: the dipole's).

        Kept per material: editing back and forth makes each profile once.
        """
        if self.family is None:
            return None
        key = (material.sigma_a.tobytes(), material.sigma_s_prime.tobytes(), material.eta)
        if key not in self._profiles:
            if len(self._profiles) >= KEPT_PROFILES:
                self._profiles.pop(next(iter(self._profiles)))
            self._profiles[key] = self.family.profile(material)
        return self._profiles[key]

    def _pixel_maps(self) -> dict:
        if self._pixels is None:
            from ...scenes.gbuffer import gbuffer

            view = gbuffer(self.scene)
            maps = {}
            for transfer in self.transfers:
                where = view.mask(transfer.name)
                mesh = self.scene.object(transfer.name).mesh
                cosine = np.einsum("...d,...d->...", view.normal, view.view_direction)[where]
                maps[transfer.name] = _PixelMap(
                    np.flatnonzero(where.ravel()), mesh.faces[view.triangle_id[where]],
                    view.barycentrics[where].astype(np.float32), np.clip(cosine, 0.0, 1.0))
            self._pixels = {"shape": view.shape, "maps": maps}
        return self._pixels

    def _exit_factor(self, name: str, pixel_map: _PixelMap, eta: float) -> np.ndarray:
        r""":math:`F_t(\eta, \omega_o)/\pi` at the object's pixels, kept while eta is unchanged.

        Edits that keep eta (most of them) reuse it instead of evaluating Fresnel per pixel.
        """
        held = self._exit_factors.get(name)
        if held is None or held[0] != eta:
            held = (eta, (fresnel_transmittance(eta, pixel_map.cosine) / np.pi)
                    .astype(np.float32))
            self._exit_factors[name] = held
        return held[1]

    def render(self, lights=None, material=None) -> Image:
        """Render a frame: relight if the lights (or eta) changed, re-weight for the material.

        Parameters
        ----------
        lights : sequence of lights, optional
            Replace the scene's lights (relighting: E and the products are recomputed);
            None keeps the lights of the last frame (the scene's at first).
        material : Dipole, optional
            Replace the material of every homogeneous translucent object (editing: only the
            projection onto the basis and the weighted sum are redone, unless eta changes,
            which changes :math:`F_t` in E and relights).

        Returns
        -------
        Image
            Linear radiance; objects that are not homogeneous translucent are black.
        """
        material = None if material is None else _material(material)
        with self._lock:
            start = time.perf_counter()
            maps = self._pixel_maps()
            height, width = maps["shape"]
            image = np.zeros((height * width, 3), dtype=np.float32)
            for transfer in self.transfers:
                chosen = material or self.scene.object(transfer.name).material
                cached = self._lighting.get(transfer.name)
                wanted = tuple(lights) if lights is not None else \
                    (cached[0] if cached else tuple(self.scene.lights))
                if cached is None or cached[1] != chosen.eta or not _same_lights(cached[0],
                                                                                 wanted):
                    self._bounce_materials = {
                        t.name: material or self.scene.object(t.name).material
                        for t in self.transfers}
                    self.relight(transfer, wanted, chosen.eta)
                radiance = self.exit_radiance(transfer, chosen)
                pixel_map = maps["maps"][transfer.name]
                exit_factor = self._exit_factor(transfer.name, pixel_map, chosen.eta)
                gathered = np.einsum("pk,pkc->pc", pixel_map.barycentrics,
                                     radiance[pixel_map.corners])
                image[pixel_map.pixels] = gathered * exit_factor[:, None]
            seconds = time.perf_counter() - start
            return Image(image.reshape(height, width, 3), metadata={
                "producer": "prt", "knobs": self.knobs, "seconds": seconds,
                "stage_seconds": dict(self.log.seconds), "notes": self.log.notes,
                "skipped": list(self.log.skipped)})
