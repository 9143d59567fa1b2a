r"""The light a scene's diffuse surfaces bounce onto its translucent objects.

PRT (Wang et al. 2008, Eq. 6) and splatting (Chen et al. 2012, Eq. 5-6) light a
translucent object with the scene's lights alone. In a room the walls and the floor light
it too: on the Cornell box that light is most of what the object receives from below and
from the side. This module adds it, once for every method that takes irradiance at
surface points:

1. **The bouncing surfaces.** Every Lambertian object of the scene is cut into the
   radiosity patches of :func:`~translucent.fast.radiosity.form_factors.build_patches`
   (one a triangle) and their form factors are ray cast
   (:func:`~translucent.fast.radiosity.form_factors.form_factors`). A frame lights the
   patches' centroids with the scene's lights (shadow rays), then solves the diffuse
   inter-reflection :math:`B = \rho\,(E + F B)` by iteration (Sheng et al. 2014, Eq. 14
   with S the albedo): B is the radiosity of each patch, W per scene unit squared.
2. **The gather.** From every receiver (a PRT illumination sample, a splatting triangle)
   ``indirect_rays`` cosine-distributed, stratified rays find the first patch they hit.
   The transmitted irradiance is then, with :math:`L = B / \pi` of a Lambertian patch,

   .. math:: E_t(x) = \int L(\omega)\,F_t(\eta, n\cdot\omega)\,(n\cdot\omega)\,d\omega
             \approx \frac{1}{K} \sum_k F_t(\eta, n\cdot\omega_k)\,B_{p(k)},

   a sparse matrix (receivers x patches) per index of refraction times B.

The gather and the form factors depend on the geometry only (cached); a frame costs one
shadow ray per patch and light sample, a few sparse products and the gather's product.
Translucent objects and non-Lambertian surfaces do not re-emit here: their patches absorb
(the light the object itself sends back to the walls, a second-order term, is left out).

Examples
--------
>>> import translucent
>>> from translucent.fast.indirect_light import bouncing_objects
>>> bouncing_objects(translucent.load_scene("sphere"))
[]
>>> scene = translucent.load_scene("dielectric_on_floor")
>>> [scene.objects[i].name for i in bouncing_objects(scene)]
['floor']
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..materials.fresnel import fresnel_transmittance, transmitted_cosine
from ..materials.homogeneous import Lambertian
from ..scenes.lighting import stratified_cosine_directions
from .knobs import Knob

__all__ = ["INDIRECT_LIGHT", "IndirectLight", "bouncing_objects", "indirect_light_knobs",
           "precompute_indirect_light", "reflectance_of"]

#: Values of the knob ``indirect_light``: ``"diffuse"`` adds the diffuse inter-reflection
#: of the scene's Lambertian surfaces and of the translucent objects' own exitance,
#: ``"lambertian"`` that of the Lambertian surfaces alone (the translucent objects absorb
#: what reaches them), ``"off"`` lights with the lights alone (the papers).
INDIRECT_LIGHT = ("diffuse", "lambertian", "off")

#: Relative change of B below which the bounce iteration stops early.
BOUNCE_TOLERANCE = 1e-4

#: Samples per area light of the bouncing patches' direct light, for a method without a
#: knob of its own for it.
PATCH_LIGHT_SAMPLES = 16

#: Rays per ray query of the gather.
GATHER_BATCH = 1 << 20

#: Receivers' ray origins are moved this fraction of the scene's bounding-box diagonal
#: along their normals (ten times the shadow rays' offset: a receiver lies on a curved
#: surface between its triangles' planes).
RECEIVER_OFFSET = 1e-4


def indirect_light_knobs(*, rays: int = 64, patch_rays: int = 256) -> list[Knob]:
    """Return the knobs every method with indirect light declares (one spec, one meaning).

    Not part of the method's own cache key (``keyed=False``): the indirect light has its
    own cache entry, keyed by them.
    """
    return [
        Knob("indirect_light", "diffuse", "light bounced onto translucent objects: diffuse "
             "(by the scene's Lambertian surfaces and the objects' own exitance), lambertian "
             "(by the Lambertian surfaces alone) or off (the lights alone, as the paper)",
             kind="choice", choices=INDIRECT_LIGHT, keyed=False),
        Knob("indirect_rays", rays, "gather rays per receiver of the indirect light",
             kind="int", low=1, high=1 << 16, keyed=False, ladder=(4, 16)),
        Knob("indirect_patch_rays", patch_rays, "form-factor rays per bouncing patch",
             kind="int", low=1, high=1 << 16, keyed=False),
        Knob("indirect_bounces", 16, "most diffuse bounces between the surfaces (stops "
             "earlier once a bounce adds under 1e-4)", kind="int", low=1, high=1000,
             keyed=False),
    ]


def reflectance_of(material):
    r"""Return ``(R_d, eta)`` of a translucent material for the bounce, or None.

    :math:`R_d` is the total diffuse reflectance per channel, (3,): a Dipole's closed form
    (Jensen et al. 2001, Eq. 6), a SubEdit texture's mean over its texels
    (:math:`2\pi\int P\,r\,dr`). Other materials give None (they absorb).
    """
    from ..materials.dipole import total_diffuse_reflectance
    from ..materials.homogeneous import Dipole
    from ..materials.subedit import SubEditProfiles

    if isinstance(material, Dipole):
        return (np.asarray(total_diffuse_reflectance(material.sigma_a, material.sigma_s_prime,
                                                     material.eta), dtype=np.float64),
                float(material.eta))
    if isinstance(material, SubEditProfiles):
        total = material.total_diffuse_reflectance().reshape(-1, 3).mean(axis=0)
        return np.clip(total, 0.0, 1.0), float(material.eta)
    return None


def bouncing_objects(scene) -> list[int]:
    """Return the objects that bounce light diffusely (Lambertian, albedo above 0), by index."""
    return [index for index, item in enumerate(scene.objects)
            if isinstance(item.material, Lambertian) and float(np.max(item.material.albedo)) > 0]


@dataclass(frozen=True, eq=False)
class IndirectLight:
    r"""The geometry-only part of the indirect light: patches, form factors, gathers.

    Attributes
    ----------
    patches : Patches
        Every object's triangles.
    bouncing : ndarray of int
        The rows of the Lambertian patches.
    form_factors : scipy.sparse.csr_matrix
        :math:`F_{ij}` for the bouncing rows and those of :attr:`reflecting` (others
        empty), float32.
    gathers : dict
        Receiver set name -> ``(patch, cosine)``, each (N, K): the first patch each gather
        ray hits (-1 none) and :math:`n \cdot \omega_k`.
    facts : dict
        Rays cast and seconds, for the method's log.
    """

    patches: object
    bouncing: np.ndarray
    form_factors: sparse.csr_matrix
    gathers: dict
    facts: dict
    #: Indices of the translucent objects that send their exitance back into the scene
    #: (empty: they absorb what reaches them)
    reflecting: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "_matrices", {})

    @property
    def nbytes(self) -> int:
        """Bytes held (cache entry limit)."""
        F = self.form_factors
        return int(F.data.nbytes + F.indices.nbytes + F.indptr.nbytes
                   + sum(p.nbytes + c.nbytes for p, c in self.gathers.values()))

    def albedo(self, scene) -> np.ndarray:
        """Albedo per patch, (P, 3): the Lambertian objects' own, 0 elsewhere."""
        albedo = np.zeros((len(self.patches), 3))
        for index, item in enumerate(scene.objects):
            if isinstance(item.material, Lambertian):
                albedo[self.patches.object_of == index] = item.material.albedo
        return albedo

    def radiosity(self, scene, lights=None, *, bounces: int = 16,
                  light_samples: int = PATCH_LIGHT_SAMPLES, seed: int = 0,
                  reflectance: dict | None = None) -> tuple[np.ndarray, dict]:
        r"""Radiosity B of every patch under ``lights`` (default the scene's), (P, 3).

        :math:`B = \rho\,(E + F B)` by Jacobi iteration from :math:`B_0 = \rho E`, each
        step one more bounce, at most ``bounces`` (the albedos are below 1, so it
        converges); E from the lights with shadows at the patch centroids
        (:func:`translucent.fast.radiosity.lighting.direct_irradiance`, ``light_samples``
        per area light).

        A translucent object of :attr:`reflecting` given in ``reflectance`` (object index
        -> its total diffuse reflectance :math:`R_d`, (3,), and its eta) takes part as a
        diffuse reflector: its patches leave :math:`B = R_d\,E_t`, with the lights' light
        entering at each sample's angle (:math:`F_t(\eta, \mu)`) and the surfaces'
        with :math:`T_{in}(\eta)`. The exitance is the object's as a whole: light leaves
        near where it entered, which for a profile shorter than the object is the local
        estimate of what the methods compute exactly.

        Returns
        -------
        B : ndarray, (P, 3)
            W per scene unit squared (the lights' units).
        facts : dict
            ``bounces`` made and the ``last_change`` (relative, max over channels).
        """
        from ..materials.profiles.base import diffuse_entry_transmittance
        from .radiosity.lighting import direct_irradiance

        patches = self.patches
        rows = self.bouncing
        albedo = self.albedo(scene)[rows]
        points = patches.centroid[rows] + 1e-6 * patches.radius[rows, None] * patches.normal[rows]
        direct = direct_irradiance(scene, points, patches.normal[rows], lights=lights,
                                   samples=light_samples, seed=seed)
        gain = albedo  # what a patch sends on of the irradiance from the other patches
        reflectance = {index: value for index, value in (reflectance or {}).items()
                       if index in self.reflecting}
        for index, (total, eta) in reflectance.items():
            own = patches.of_object(index)
            own = own[~patches.is_back[own]]
            where = patches.centroid[own] + 1e-6 * patches.radius[own, None] \
                * patches.normal[own]
            entered = direct_irradiance(scene, where, patches.normal[own], lights=lights,
                                        samples=light_samples, seed=seed,
                                        response=functools.partial(transmitted_cosine, eta))
            total = np.asarray(total, dtype=np.float64).reshape(1, 3)
            rows = np.concatenate([rows, own])
            direct = np.concatenate([direct, entered])
            albedo = np.concatenate([albedo, np.broadcast_to(total, (len(own), 3))])
            gain = np.concatenate([gain, np.broadcast_to(
                total * float(diffuse_entry_transmittance(eta)), (len(own), 3))])
        F = self._form_factors_among(rows, tuple(reflectance))
        emitted = albedo * direct
        B = emitted.copy()
        change, made = 0.0, 1
        while made < bounces:
            updated = emitted + gain * (F @ B)
            change = float(np.max(np.abs(updated - B)) / max(float(np.max(np.abs(updated))),
                                                             1e-300))
            B, made = updated, made + 1
            if change < BOUNCE_TOLERANCE:
                break
        full = np.zeros((len(patches), 3))
        full[rows] = B
        return full, {"bounces": made, "last_change": change}

    def _form_factors_among(self, rows, reflecting: tuple) -> sparse.csr_matrix:
        """F between ``rows`` (the bouncing patches, then those of ``reflecting``), kept."""
        key = ("among", reflecting)
        if key not in self._matrices:
            self._matrices[key] = self.form_factors[rows][:, rows].tocsr()
        return self._matrices[key]

    def gather_matrix(self, name: str, eta: float) -> sparse.csr_matrix:
        r"""Receivers x patches: :math:`F_t(\eta, n\cdot\omega_k) / K` summed per patch."""
        key = (name, float(eta))
        matrices = self._matrices
        if key not in matrices:
            patch, cosine = self.gathers[name]
            hit = patch >= 0
            rows = np.broadcast_to(np.arange(len(patch))[:, None], patch.shape)[hit]
            weight = fresnel_transmittance(float(eta), np.clip(cosine[hit], 0.0, 1.0)) \
                / patch.shape[1]
            matrix = sparse.coo_matrix((weight, (rows, patch[hit])),
                                       shape=(len(patch), len(self.patches))).tocsr()
            matrix.sum_duplicates()
            if len(matrices) >= 8:
                matrices.pop(next(iter(matrices)))
            matrices[key] = matrix
        return matrices[key]

    def irradiance(self, name: str, radiosity: np.ndarray, eta: float) -> np.ndarray:
        """Return the transmitted irradiance at receivers ``name``, (N, 3), from ``radiosity``."""
        return np.asarray(self.gather_matrix(name, eta) @ radiosity)


def _array_digest(*arrays) -> str:
    """SHA-256 of the float64 bytes of ``arrays`` (receivers in a cache key)."""
    import hashlib

    digest = hashlib.sha256()
    for array in arrays:
        digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    return digest.hexdigest()


def _gather(scene, patches, positions, normals, rays: int, rng) -> tuple:
    """First patch hit and cosine of ``rays`` cosine-distributed rays per receiver."""
    from ..scenes.raycast import ray_engine, trace
    from .radiosity.form_factors import first_hit_patches

    positions = np.asarray(positions, np.float64)
    normals = np.asarray(normals, np.float64)
    offset = RECEIVER_OFFSET * ray_engine(scene).diagonal
    count = len(positions)
    patch = np.full((count, rays), -1, dtype=np.int32)
    cosine = np.zeros((count, rays), dtype=np.float32)
    per_batch = max(1, GATHER_BATCH // rays)
    for start in range(0, count, per_batch):
        stop = min(count, start + per_batch)
        directions = stratified_cosine_directions(normals[start:stop], rays, rng)
        origins = np.repeat(positions[start:stop] + offset * normals[start:stop], rays, axis=0)
        patch[start:stop] = first_hit_patches(scene, patches, origins,
                                              directions.reshape(-1, 3),
                                              trace).reshape(-1, rays)
        cosine[start:stop] = np.einsum("nkd,nd->nk", directions, normals[start:stop])
    return patch, cosine


def precompute_indirect_light(scene, receivers: dict, knobs: dict, log=None
                              ) -> IndirectLight | None:
    """Patches, form factors and gathers for ``receivers``; cached on disk.

    Parameters
    ----------
    scene : Scene
    receivers : dict
        Name -> ``(positions, normals)``, each (N, 3): the points of a translucent object
        where the method takes irradiance (scene units, unit outward normals).
    knobs : dict
        The method's resolved knobs (those of :func:`indirect_light_knobs` and ``seed``).
    log : StageLog, optional
        Where the note goes: what was skipped, or the patches and rays.

    Returns
    -------
    IndirectLight or None
        None where the knob is ``"off"`` or no surface bounces light (said in ``log``).
    """
    from ..cache import content_hash
    from .base import load_or_precompute
    from .radiosity.form_factors import build_patches, form_factors

    if knobs["indirect_light"] == "off":
        if log is not None and bouncing_objects(scene):
            log.skip("indirect light off: the light the scene's surfaces bounce onto the "
                     "translucent objects is left out (the paper's setting)")
        return None
    bouncing = bouncing_objects(scene)
    if not bouncing:
        if log is not None:
            log.notes["indirect light"] = "no Lambertian surface: nothing bounces light"
        return None
    seed = knobs.get("seed", 0)
    names = [item.name for item in scene.objects]
    reflecting = tuple(names.index(name) for name in receivers if name in names) \
        if knobs["indirect_light"] == "diffuse" else ()
    settings = {"rays": knobs["indirect_rays"], "patch_rays": knobs["indirect_patch_rays"],
                "seed": seed, "reflecting": list(reflecting)}
    key = content_hash("indirect-light", 1, scene.geometry_key(),
                       [scene.objects[i].name for i in bouncing], settings,
                       {name: _array_digest(*pair) for name, pair in receivers.items()})

    def make():
        started = time.perf_counter()
        rng = np.random.default_rng(seed)
        patches = build_patches(scene)
        rows = np.flatnonzero(np.isin(patches.object_of, bouncing))
        cast = np.flatnonzero(np.isin(patches.object_of, bouncing + list(reflecting)))
        F, facts = form_factors(scene, patches, rays_per_patch=knobs["indirect_patch_rays"],
                                seed=seed, rows=cast)
        gathers = {name: _gather(scene, patches, positions, normals, knobs["indirect_rays"],
                                 rng)
                   for name, (positions, normals) in receivers.items()}
        return IndirectLight(patches, rows, F, gathers, {
            "bouncing patches": len(rows), "reflecting patches": len(cast) - len(rows),
            "form factor rays": facts["rays"],
            "gather rays": sum(p.size for p, _ in gathers.values()),
            "seconds": time.perf_counter() - started}, reflecting)

    from .base import StageLog

    holder = log if log is not None else StageLog()
    light, _ = load_or_precompute(
        "indirect", key, make, what="the indirect light's gather", log_of=lambda _: holder,
        valid=lambda value: isinstance(value, IndirectLight), nbytes=lambda v: v.nbytes,
        part="indirect light")
    holder.notes["indirect light"] = {
        "bouncing objects": [scene.objects[i].name for i in bouncing], **light.facts}
    return light
