r"""BRDF editing and relighting with global illumination by PCA (Nguyen et al. 2010).

The direct-to-indirect transfer of Hašan et al. 2006, extended as Nguyen et al. 2010 do:

* **View samples** :math:`X` are the pixels of the camera's G-buffer; **gather samples**
  :math:`G` are found by backward photon shooting (Sect. 5.1): a ray leaves the eye
  through a random pixel, reflects at the first hit (uniformly over the hemisphere for
  *diffuse* gather samples, with density :math:`\propto (\omega_o\cdot R(\omega_s))^e`,
  :math:`e = 200`, about the mirror direction of a glossy pixel for *glossy* ones, one
  glossy to six diffuse) and its second hit is a gather sample. The area :math:`|A_g|`
  a gather sample stands for is estimated from uniform surface samples, each given to the
  nearest gather sample (Sect. 5.1, "Sub-area samples").
* The glossy lobe of every object with an analytic BRDF is linearised (Sect. 4,
  :mod:`translucent.materials.brdf_pca`): :math:`f = \rho_d/\pi + \rho_s f_F
  \sum_{j=0}^K c_j(\gamma) b_j(\delta)` with :math:`c_0 = 1`.
* The **glossy transfer** :math:`T_{j,g}(x)` (Eqs. 4 and 7) of basis BRDF
  :math:`f_j = b_j f_F` from gather sample :math:`g` to view sample :math:`x` treats
  :math:`g` as a disk :math:`K_g` of area :math:`|A_g|`; where the disk subtends more
  than the narrowest lobe of the editing range, **sub-area samples** drawn uniformly on
  the disk refine it (Eq. 3 with the pdf :math:`r^2 / (|A_g| |N_g\cdot\omega|)`), stopping
  when the estimate has converged (Sect. 5.1). Visibility and radiance are the gather
  sample's (Eq. 4).
* The **diffuse transfer** :math:`D_g(x) = V \cos\theta_x \cos\theta_g |A_g| /
  (r^2 + |A_g|/\pi)` (the disk's cosine-weighted solid angle, bounded as the disk comes
  close) and the **single-bounce gather matrix** :math:`M_s` between gather samples under
  the Lambertian assumption of Sect. 5.2.
* Every row of :math:`T`, :math:`D` and :math:`M_s` is Haar-transformed over the gather
  samples, laid out on a square by the balanced quadtree of Hašan et al. 2006 (so that
  neighbours on the square are neighbours on the surfaces), and only its largest
  coefficients, weighted by the square root of their support, are kept (Sect. 3.4); the
  budget of basis :math:`j` in :math:`T` is proportional to its eigenvalue (Sect. 7.2).
  Rows are
  stored row-indexed (Sect. 6.1) as 16-bit values with 16-bit indices
  (:class:`~translucent.fast.sparse_transport.QuantisedRows`).
* At run time (Eqs. 9 and 17): direct lighting :math:`L_d` on gather samples,
  :math:`L^w = \sum_{n=0}^{N} L_n^w` with :math:`L_n = \rho_d/\pi \odot M_s^w L_{n-1}^w`,
  then per pixel :math:`\rho_d/\pi\, D^w(x) L^w + \rho_s \sum_j c_j(\gamma) T_j^w(x) L^w`
  plus the exact direct lighting of the pixel.
* **Editing** one object's :math:`\gamma` changes only :math:`\mathbf{c}(\gamma)` (Eq. 15)
  and that object's pixels; the products :math:`T_j^w L^w` are kept while the lights stay.
  **Freezing** (Sect. 6.2) replaces the :math:`K+1` rows of an object that is not being
  edited by the single row :math:`\mathbf{c}^T T^w(x)`, truncated again.
* **Relighting** recomputes :math:`L_d`, the series and the frozen products.

Objects without an analytic BRDF get no PCA transfer (only :math:`D`); the run says so in
its :class:`~translucent.fast.base.StageLog`.

The per-pair work of the precomputation (front-facing tests, shadow rays, the transfer
with its sub-area disks, Haar transform and coefficient selection) runs in compiled,
threaded kernels; shadow rays go through the scene's Mitsuba ray engine
(:mod:`translucent.scenes.raycast`). The fixed terms and PCA variables of
:mod:`translucent.materials.brdfs` are compiled again here, per pair, and tested equal.
Visibility between two gather samples is symmetric, so the gather matrix traces each
unordered pair once and reads the reversed pair's answer back
(:func:`~translucent.fast.brdf_pca_lighting.gather_pair_visibility`).

Limitations inherited from the paper (Table 1): gather samples reflect as Lambertian
surfaces, so light reflected by a glossy surface after the first one (a glossy highlight
seen in a glossy floor, the caustic a glossy floor throws on a wall) is missing; the
camera is fixed. :func:`translucent.reference.brdf_plugins.render_lambertian_gather`
path-traces exactly this transport, the limit the method converges to. Environment lights
are not supported.

References
----------
C. H. Nguyen, M.-H. Kyung, J.-H. Lee, S.-W. Nam: A PCA decomposition for real-time BRDF
editing and relighting with global illumination. Computer Graphics Forum 29(4), 2010.
M. Hašan, F. Pellacini, K. Bala: Direct-to-indirect transfer for cinematic relighting. ACM
TOG 25(3), 2006.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse

from ..errors import InputError
from ..image import Image
from ..materials.brdfs import (
    AnalyticBRDF,
    edited_term,
    fixed_term,
    pca_variable,
    uses_half_angle,
)
from ..materials.homogeneous import Lambertian
from .base import applicability, refuse_inapplicable
from .brdf_pca_lighting import (
    check_lights,
    direct_samples,
)
from .brdf_pca_transfer import (
    Precomputation,
    compute_precomputation,
    diffuse_albedo,
    disk_transfer,
    haar_rows,
    is_glossy_material,
    quantised_product,
    sparse_to_scipy,
    truncate_rows,
)
from .knobs import Knob, KnobSpec

__all__ = [
    "DEFAULT_KNOBS",
    "KNOBS",
    "LADDERS",
    "BRDFPCAState",
    "Precomputation",
    "add_approx_arguments",
    "applies_to",
    "QUICK_KNOBS",
    "approx",
    "disk_transfer",
    "precompute",
]

#: Bumped when the stored precomputation changes meaning (cache key).
FORMAT_VERSION = 3

def _power_of_four(value: int) -> int:
    if value & (value - 1) or int(round(math.log2(value))) % 2:
        raise InputError("must be a power of 4 (the gather samples fill the square of the "
                         "quadtree layout of Hasan et al. 2006): 256, 1024, 4096, 16384, "
                         "65536, ...", field="gather_samples", value=value)
    return value


#: The knobs of :func:`precompute` (Nguyen et al. 2010): validation, cache key,
#: ``translucent approx brdf_pca`` flags and the quality ladder all come from here.
KNOBS = KnobSpec([
    Knob("gather_samples", 16384, "gather samples: 16k in the paper's Cornell box, 64k "
         "elsewhere (Sect. 7.2); a power of 4", kind="int", low=16, high=1 << 22,
         check=_power_of_four),
    Knob("glossy_ratio", 1.0 / 6.0, "glossy gather samples per diffuse one (Sect. 5.1)",
         kind="float", low=0.0, high=1.0),
    Knob("glossy_exponent", 200.0, "e of Eq. 16, 'usually set to 200'", kind="float",
         low=1.0, high=1e5),
    Knob("n_basis", 6, "K, basis BRDFs besides the mean (6 in every scene of Table 5)",
         kind="int", low=1, high=32, flags=("--basis",)),
    Knob("bounces", 2, "n of Eq. 17: bounces among gather samples", kind="int", low=0,
         high=64),
    Knob("subarea", True, "sub-area sampling (Sects. 3.2, 5.1)", kind="bool"),
    Knob("subarea_max", 64, "most points per sub-area disk", kind="int", low=1, high=4096),
    Knob("subarea_tolerance", 0.02, "convergence of the sub-area estimate", kind="float",
         low=0.0, high=1.0),
    Knob("area_samples_per_gather", 8, "uniform surface samples per gather sample for the "
         "areas |A_g|", kind="int", low=1, high=256),
    # Haar coefficients kept per view-sample row of T (over all K + 1 bases), of D, per
    # gather-sample row of M_s, and per row of a frozen c^T T^w
    Knob("transfer_coefficients", 512, "Haar coefficients per view-sample row of T",
         kind="int", low=1, high=1 << 20),
    Knob("diffuse_coefficients", 96, "Haar coefficients per row of D", kind="int", low=1,
         high=1 << 20),
    Knob("gather_coefficients", 96, "Haar coefficients per gather-sample row of M_s",
         kind="int", low=1, high=1 << 20),
    Knob("frozen_coefficients", 192, "Haar coefficients per row of a frozen c^T T^w",
         kind="int", low=1, high=1 << 20),
    Knob("light_samples", 16, "samples per area light for direct lighting", kind="int",
         low=1, high=4096),
    # each block starts a few threaded kernels, which costs ~25 ms on a loaded machine
    Knob("block_pairs", 1 << 22, "(view sample, gather sample) pairs per block of the "
         "transfer computation", kind="int", low=1 << 10, high=1 << 26),
    Knob("seed", 0, "random seed of the samples", kind="int", low=0, high=2**31 - 1),
], ladders={
    # gather samples (Sect. 5.1), PCA basis BRDFs (Sect. 4) and Haar coefficients kept per
    # transfer row (Sect. 3.4)
    "gather samples, PCA and wavelet terms": [
        {"gather_samples": 1024, "n_basis": 1, "transfer_coefficients": 64},
        {"gather_samples": 4096, "n_basis": 2, "transfer_coefficients": 128},
        {"gather_samples": 4096, "n_basis": 4, "transfer_coefficients": 256},
        {},
    ],
})

#: The knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS = KNOBS.defaults

#: Quality ladders of ``bench tradeoff`` and the report.
LADDERS = KNOBS.ladders

#: Cheap knobs for smoke runs and the conformance checks (fast.conformance).
QUICK_KNOBS = dict(gather_samples=256, bounces=1, transfer_coefficients=96,
                   diffuse_coefficients=48, gather_coefficients=48, frozen_coefficients=48,
                   light_samples=4, block_pairs=1 << 14)



# ---------------------------------------------------------------------------------------
# materials and knobs


def applies_to(scene) -> str | None:
    """None when every object is Lambertian or an analytic BRDF and one is an analytic BRDF.

    Nguyen et al. 2010 edit analytic BRDFs of opaque surfaces lit by point-like and area
    lights; translucent media, environment lights and scenes with nothing to edit are not
    theirs.
    """
    for obj in scene.objects:
        if not isinstance(obj.material, (AnalyticBRDF, Lambertian)):
            return (f"object '{obj.name}' has a {type(obj.material).__name__} material; the "
                    "BRDF-editing method takes opaque surfaces (Lambertian or analytic BRDFs)")
    if not any(is_glossy_material(o.material) for o in scene.objects):
        return "no object has an analytic BRDF: there is nothing to edit"
    try:
        check_lights(scene.lights)
    except InputError as error:
        return str(error)
    return None


def _resolve_knobs(knobs: dict) -> dict:
    return KNOBS.resolve(knobs)


def _structure_key(scene) -> list:
    """Return what the precomputation depends on besides geometry and camera.

    Which objects are glossy and their fixed-term parameters: never gamma, rho_s, rho_d
    or the lights.
    """
    out = []
    for obj in scene.objects:
        material = obj.material
        if is_glossy_material(material):
            out.append([obj.name, material.model, material.f0, list(material.lafortune_c)])
        else:
            out.append([obj.name, "diffuse"])
    return out


def precompute(scene, **knobs) -> BRDFPCAState:
    r"""Precompute the transfers of Sects. 3-5 of Nguyen et al. 2010; cached on disk.

    The cache key holds the geometry, the camera, the knobs and which objects carry which
    BRDF model (and its fixed-term parameters ``f0``, ``lafortune_c``) -- never gamma,
    :math:`\rho_s`, :math:`\rho_d` or the lights, which the state edits interactively.

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    BRDFPCAState

    Raises
    ------
    InputError
        When the method does not apply (:func:`applies_to`), or a knob is unknown or out
        of range.
    """
    from ..cache import Cache, content_hash

    refuse_inapplicable(scene, applicability(applies_to, scene),
                        "the BRDF-editing method does not apply")
    resolved = _resolve_knobs(knobs)
    key = content_hash("brdf_pca", FORMAT_VERSION, scene.geometry_key(),
                       scene.camera.cache_key(), resolved, _structure_key(scene))
    cache = Cache("brdf_pca")

    def make():
        started = time.perf_counter()
        data = compute_precomputation(scene, resolved)
        data.log.seconds["total"] = time.perf_counter() - started
        data.log.notes["cache"] = "miss"
        return data

    data, made = cache.load_or_make(key, make,
                                    valid=lambda value: isinstance(value, Precomputation),
                                    what="the BRDF-editing precomputation")
    if not made:
        data.log.notes["cache"] = "hit"
    return BRDFPCAState(scene, data)


# ---------------------------------------------------------------------------------------
# the interactive state


def _combine(matrices, coefficients) -> scipy.sparse.csr_matrix:
    combined = None
    for weight, matrix in zip(coefficients, matrices, strict=True):
        term = sparse_to_scipy(matrix.dequantised()) * float(weight)
        combined = term if combined is None else combined + term
    return combined.tocsr()


class BRDFPCAState:
    r"""The result of :func:`precompute`: edits gamma per object and relights interactively.

    Parameters
    ----------
    scene : Scene
        Its lights and materials are the starting point of editing.
    data : Precomputation

    Attributes
    ----------
    materials : dict
        object name -> current material.
    lights : tuple
    frozen : dict
        object name -> (gamma, frozen rows :math:`\mathbf{c}(\gamma)^T T^w`), Sect. 6.2.
    log : StageLog
    """

    def __init__(self, scene, data: Precomputation):
        self.scene = scene
        self.data = data
        self.log = data.log
        self.knobs = data.knobs
        self.materials = {o.name: o.material for o in scene.objects}
        self.frozen: dict = {}
        self._transfer = {scene.objects[i].name: matrices
                          for i, (_, matrices) in data.transfer.items()}
        self._members = {scene.objects[i].name: rows for i, (rows, _) in data.transfer.items()}
        self._index = {o.name: i for i, o in enumerate(scene.objects)}
        self.lights = tuple(scene.lights)
        self._lit = False
        self._products: dict = {}
        self._glossy_parts: dict = {}
        self._coefficients: dict = {}
        self._albedos: dict = {}

    @property
    def glossy_objects(self) -> list[str]:
        """Names of the objects whose gamma can be edited."""
        return list(self._members)

    def coefficients(self, name) -> np.ndarray:
        r"""Return :math:`\mathbf{c}(\gamma)` of object ``name`` (Eqs. 13, 15), cached by gamma."""
        material = self.materials[name]
        cached = self._coefficients.get(name)
        if cached is None or cached[0] != material.gamma:
            basis = self.data.bases[self._index[name]]
            cached = (material.gamma, basis.coefficients(material.gamma))
            self._coefficients[name] = cached
        return cached[1]

    # -- lighting ----------------------------------------------------------------------
    def _albedo(self, which: str) -> np.ndarray:
        r"""Return :math:`\rho_d/\pi` of every gather (``which="gather"``) or view sample."""
        table = np.array([diffuse_albedo(self.materials[o.name]) for o in self.scene.objects])
        key = table.tobytes()
        cached = self._albedos.get(which)
        if cached is None or cached[0] != key:
            objects = self.data.gather_object if which == "gather" else self.data.view_object
            cached = (key, (table[objects] / math.pi).astype(np.float32))
            self._albedos[which] = cached
        return cached[1]

    def _wavelet(self, values) -> np.ndarray:
        """Return :math:`L^w`: radiance per gather sample (G, 3) in Haar coefficients."""
        return np.ascontiguousarray(haar_rows(np.ascontiguousarray(values.T,
                                                                    dtype=np.float32)).T)

    def _relight(self):
        """Compute direct lighting, the Eq. 17 series and the view-sample caches (relight)."""
        data = self.data
        samples, seed = self.knobs["light_samples"], self.knobs["seed"]
        _, gather_e = direct_samples(self.scene, self.lights, data.gather_position,
                                      data.gather_normal, samples, seed)
        albedo_g = self._albedo("gather")
        direct_g = albedo_g * gather_e.sum(axis=1).astype(np.float32)
        total, current = direct_g.copy(), direct_g
        count = len(direct_g)
        for _ in range(self.knobs["bounces"]):        # Eq. 17
            current = albedo_g * quantised_product(data.gather, self._wavelet(current))[:count]
            total += current
        self._radiance_w = self._wavelet(total)
        wi, view_e = direct_samples(self.scene, self.lights, data.view_position,
                                     data.view_normal, samples, seed + 1)
        albedo_x = self._albedo("view")
        direct = albedo_x * view_e.sum(axis=1)
        indirect = albedo_x * quantised_product(data.diffuse, self._radiance_w)
        self._parts = {"direct": direct, "indirect": indirect, "all": direct + indirect}
        self._view_lighting = {}
        for name, rows in self._members.items():
            material = self.materials[name]
            n_x, out = data.view_normal[rows], data.view_out[rows]
            cos_l = np.einsum("psd,pd->ps", wi[rows], n_x)
            cos_v = np.einsum("pd,pd->p", out, n_x)[:, None]
            l_dot_v = np.einsum("psd,pd->ps", wi[rows], out)
            fixed = fixed_term(material.model, cos_l, cos_v, l_dot_v, f0=material.f0)
            variable = pca_variable(material.model, cos_l, cos_v, l_dot_v,
                                    lafortune_c=material.lafortune_c)
            weight = np.where((cos_l > 0) & (cos_v > 0), fixed, 0.0)[..., None] * view_e[rows]
            self._view_lighting[name] = (variable, weight)
        self._products = {}
        self._glossy_parts = {}
        self._lit = True

    def _glossy(self, name) -> dict:
        """Glossy radiance of object ``name``'s view samples: exact direct, and Eq. 9.

        Cached for the current gamma and lights: an edit recomputes only the edited
        object. While the lights stay, the products :math:`T_j^w L^w` are kept, so a new
        gamma costs one weighted sum of K + 1 vectors per pixel.
        """
        material = self.materials[name]
        cached = self._glossy_parts.get(name)
        key = (material.gamma, tuple(material.rho_s), name in self.frozen)
        if cached is not None and cached[0] == key:
            return cached[1]
        variable, weight = self._view_lighting[name]
        if uses_half_angle(material.model):
            lobe = edited_term(material.model, material.gamma, None, cos_delta=variable)
        else:
            lobe = edited_term(material.model, material.gamma, variable)
        direct = np.einsum("ps,psc->pc", lobe, weight)
        frozen = name in self.frozen
        products = self._products.get(name)
        if products is None:
            products = (quantised_product(self.frozen[name][1], self._radiance_w) if frozen
                        else np.stack([quantised_product(m, self._radiance_w)
                                       for m in self._transfer[name]]))
            self._products[name] = products
        indirect = (products if frozen else
                    np.einsum("j,jpc->pc", self.coefficients(name), products))
        parts = {"direct": material.rho_s * direct, "indirect": material.rho_s * indirect}
        parts["all"] = parts["direct"] + parts["indirect"]
        self._glossy_parts[name] = (key, parts)
        return parts

    def _compose(self, component="all") -> np.ndarray:
        data = self.data
        values = self._parts[component].copy()
        for name, rows in self._members.items():
            values[rows] += self._glossy(name)[component]
        image = np.zeros((data.shape[0] * data.shape[1], 3), dtype=np.float32)
        image[data.pixel] = values
        return image.reshape(data.shape[0], data.shape[1], 3)

    # -- the interactive API -------------------------------------------------------------
    def _set_materials(self, material):
        if material is None:
            return
        glossy = self.glossy_objects
        if isinstance(material, dict):
            updates = material
        elif len(glossy) == 1:
            updates = {glossy[0]: material}
        else:
            raise InputError("several objects have an analytic BRDF: pass a dict "
                             f"{{object name: material}} (objects: {', '.join(glossy)})",
                             field="material", value=type(material).__name__)
        albedo_changed = False
        for name, new in updates.items():
            if name not in self.materials:
                raise InputError(f"no such object; objects: {', '.join(self.materials)}",
                                 field="material", value=name)
            old = self.materials[name]
            glossy = is_glossy_material(old)
            same_kind = glossy == is_glossy_material(new) and (not glossy or (
                old.model == new.model and old.f0 == new.f0
                and old.lafortune_c == new.lafortune_c))
            if not same_kind:
                raise InputError("only gamma, rho_s and rho_d can change without a new "
                                 "precomputation (the model, f0 and the Lafortune lobe are "
                                 "fixed terms)", field=f"material[{name!r}]",
                                 value=getattr(new, "model", type(new).__name__))
            albedo_changed |= not np.array_equal(diffuse_albedo(old), diffuse_albedo(new))
            self.materials[name] = new
            if name in self.frozen and self.frozen[name][0] != new.gamma:
                self.unfreeze(name)
        if albedo_changed:
            self._lit = False

    def render(self, lights=None, material=None, *, component: str = "all") -> Image:
        """Render with new lights and/or materials (None keeps the current ones).

        Parameters
        ----------
        lights : sequence of lights, optional
            Relighting: new direct lighting on gather and view samples, a new series.
        material : AnalyticBRDF or dict, optional
            Editing: one material (when one object has an analytic BRDF) or
            ``{object name: material}``; gamma, rho_s and rho_d may change (rho_d of
            any object also changes the light among gather samples).
        component : {"all", "direct", "indirect"}
            The whole image, the direct lighting of the pixels only, or the light that
            reaches them through gather samples only.

        Returns
        -------
        Image
        """
        started = time.perf_counter()
        if component not in ("all", "direct", "indirect"):
            raise InputError("must be 'all', 'direct' or 'indirect'", field="component",
                             value=component)
        if lights is not None:
            lights = tuple(lights)
            check_lights(lights)
            self.lights = lights
            self._lit = False
        self._set_materials(material)
        if not self._lit:
            self._relight()
        rgb = self._compose(component)
        return Image(rgb, metadata={
            "producer": "brdf_pca", "scene": self.scene.name, "component": component,
            "knobs": self.knobs, "seconds": time.perf_counter() - started,
            "gamma": {name: self.materials[name].gamma for name in self._members},
            "frozen": sorted(self.frozen), "skipped": list(self.log.skipped)})

    def _check_editable(self, name: str, field_name: str) -> None:
        if name not in self._members:
            raise InputError("not an object with an analytic BRDF; editable: "
                             f"{', '.join(self._members)}", field=field_name, value=name)

    def edit(self, object_name: str, gamma: float) -> Image:
        """Set one object's gamma and render: only that object's pixels change (Sect. 6.2)."""
        self._check_editable(object_name, "object")
        material = self.materials[object_name].with_gamma(gamma)
        return self.render(material={object_name: material})

    def relight(self, lights) -> Image:
        """Render with new lights (frozen objects stay frozen)."""
        return self.render(lights=lights)

    def freeze(self, editing: str | None = None) -> float:
        r"""Freeze every glossy object but ``editing`` (Sect. 6.2); return the seconds taken.

        A frozen object's K + 1 rows per view sample become the one row
        :math:`\mathbf{c}(\gamma)^T T^w(x)`, truncated again to ``frozen_coefficients``;
        ``editing=None`` freezes them all (the light-editing mode).
        """
        started = time.perf_counter()
        if editing is not None:
            self._check_editable(editing, "editing")
            self.unfreeze(editing)
        for name, matrices in self._transfer.items():
            if name == editing or name in self.frozen:
                continue
            combined = _combine(matrices, self.coefficients(name))
            rows = truncate_rows(combined, self.knobs["frozen_coefficients"])
            self.frozen[name] = (self.materials[name].gamma, rows.quantised())
            self._products.pop(name, None)
            self._glossy_parts.pop(name, None)
        return time.perf_counter() - started

    def unfreeze(self, name: str) -> None:
        """Bring back object ``name``'s K + 1 rows (to edit it again)."""
        self.frozen.pop(name, None)
        self._products.pop(name, None)
        self._glossy_parts.pop(name, None)

    def storage_bytes(self) -> dict:
        """Bytes of the matrices the interactive path reads (T^w: unfrozen rows and frozen ones)."""
        transfer = sum(m.nbytes for name, ms in self._transfer.items()
                       if name not in self.frozen for m in ms)
        transfer += sum(rows.nbytes for _, rows in self.frozen.values())
        diffuse, gather = self.data.diffuse.nbytes, self.data.gather.nbytes
        return {"transfer": transfer, "diffuse": diffuse, "gather": gather,
                "total": transfer + diffuse + gather}


# ---------------------------------------------------------------------------------------
# command line


def add_approx_arguments(parser) -> None:
    """Add the options of ``translucent approx brdf_pca SCENE``."""
    parser.add_argument("--object", default=None,
                        help="object whose gamma to set (default: the only glossy object)")
    parser.add_argument("--gamma", type=float, default=None,
                        help="editing parameter of --object, in its model's range")
    KNOBS.add_arguments(parser)


def approx(scene, args) -> Image:
    """Precompute (or load) and render ``scene`` for ``translucent approx brdf_pca``."""
    started = time.perf_counter()
    # the edit is checked against the scene before the (slow) precomputation
    glossy = [o.name for o in scene.objects if is_glossy_material(o.material)]
    name = args.object
    if name is None and args.gamma is not None:
        if len(glossy) != 1:
            raise InputError("several objects have an analytic BRDF: name one with --object "
                             f"({', '.join(glossy)})", field="object", value=None)
        name = glossy[0]
    if name is not None and args.gamma is None:
        raise InputError("--object needs --gamma", field="gamma", value=None)
    if name is not None:
        if name not in glossy:
            raise InputError(f"not an object with an analytic BRDF; editable: "
                             f"{', '.join(glossy)}", field="object", value=name)
        scene.object(name).material.with_gamma(args.gamma)  # range-checked
    state = precompute(scene, **KNOBS.from_arguments(args))
    image = state.edit(name, args.gamma) if name is not None else state.render()
    for sentence in state.log.skipped:
        print(f"skipped: {sentence}")
    return image.with_metadata(seconds=time.perf_counter() - started,
                               precompute_seconds=dict(state.log.seconds))
