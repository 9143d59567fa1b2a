"""The interactive state of the BRDF-editing method: edit gamma per object, relight.

Eqs. 9, 15 and 17 of Nguyen et al. 2010 at run time, and the freezing of Sect. 6.2.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse

from ...errors import InputError
from ...image import Image
from ...materials.brdfs import (
    edited_term,
    fixed_term,
    pca_variable,
    uses_half_angle,
)
from ..sparse_transport import product_rgb_per_row
from ..wavelets import haar2d_forward_in_place
from .kernels import block_reflection
from .knobs import KNOBS
from .lighting import check_lights, direct_samples
from .transfer import (
    Precomputation,
    diffuse_albedo,
    haar_rows,
    is_glossy_material,
    material_parameters,
    quantised_product,
    sparse_to_scipy,
    truncate_rows,
)

#: A gather sample closer to a block's centre than this many times the block's radius plus
#: its disk's sends the block no glossy light (:func:`~.kernels.block_reflection`): there
#: the direction to the centre stands for none of the block's pixels. Measured on
#: ``glossy`` (docs/brdf_pca.md): without it the box's and the floor's pixels where they
#: meet came out up to 5x too bright.
REFLECTION_GUARD = 2.0

__all__ = ["BRDFPCAState"]


def _lobe(material, variable) -> np.ndarray:
    """Return the edited term f_E(gamma) of ``material`` at its PCA variable."""
    if uses_half_angle(material.model):
        return edited_term(material.model, material.gamma, None, cos_delta=variable)
    return edited_term(material.model, material.gamma, variable)


def _glossy_weight(material, cos_l, cos_v, l_dot_v) -> np.ndarray:
    """Return f_F f_E(gamma) of ``material``, zero where either cosine is not positive."""
    fixed = fixed_term(material.model, cos_l, cos_v, l_dot_v, f0=material.f0)
    variable = pca_variable(material.model, cos_l, cos_v, l_dot_v,
                            lafortune_c=material.lafortune_c)
    return np.where((cos_l > 0) & (cos_v > 0), fixed * _lobe(material, variable), 0.0)


#: The most bytes the blocks' vectors of gather radiance may take (float32, B x 3 x G): a
#: knob asking for more is refused before anything is allocated.
REFLECTION_MAX_BYTES = 4 << 30


def _check_reflection_bytes(blocks: int, gathers: int) -> None:
    needed = 4 * 3 * blocks * gathers
    if needed > REFLECTION_MAX_BYTES:
        raise InputError(f"{blocks} blocks x {gathers} gather samples need "
                         f"{needed / 2**30:.1f} GiB of gather radiance (at most "
                         f"{REFLECTION_MAX_BYTES / 2**30:.0f}): ask for fewer blocks",
                         field="reflection_blocks", value=blocks)


def reflection_blocks(shape, pixel, view_object, view_position, size: int):
    """Return the block of each view sample and each block's centre (the mean position).

    A block is a ``size`` x ``size`` square of pixels and one object in it: a gather
    sample's BRDF is evaluated towards the centre for every view sample of the block.

    Returns
    -------
    block : ndarray of int64, (P,)
    centre : ndarray, (B, 3)
    radius : ndarray, (B,)
        The farthest view sample of each block from its centre.
    """
    width = shape[1]
    rows, columns = np.divmod(np.asarray(pixel, dtype=np.int64), width)
    square = (rows // size) * (-(-width // size)) + columns // size
    view_object = np.asarray(view_object, dtype=np.int64)
    keys = square * (int(view_object.max(initial=0)) + 1) + view_object
    _, block = np.unique(keys, return_inverse=True)
    counts = np.bincount(block)
    centre = np.stack([np.bincount(block, weights=view_position[:, k]) for k in range(3)],
                      axis=1) / counts[:, None]
    radius = np.zeros(len(centre))
    np.maximum.at(radius, block, np.linalg.norm(view_position - centre[block], axis=1))
    return block.astype(np.int64), centre, radius


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
    run_knobs : dict, optional
        The knobs that are not part of the precomputation (``gather_reflection``,
        ``reflection_blocks``): they override those stored with ``data``.

    Attributes
    ----------
    materials : dict
        object name -> current material.
    lights : tuple
    frozen : dict
        object name -> (gamma, frozen rows :math:`\mathbf{c}(\gamma)^T T^w`), Sect. 6.2.
    log : StageLog
    """

    def __init__(self, scene, data: Precomputation, run_knobs: dict | None = None):
        self.scene = scene
        self.data = data
        self.log = data.log
        self.knobs = {**{name: KNOBS.knobs[name].default for name in KNOBS.unkeyed},
                      **data.knobs, **(run_knobs or {})}
        self._blocks = None
        self._reflection_w = None
        self._reflection_edits: list = []
        # the objects whose gather samples reflect by their BRDF: every one with a basis
        self._reflecting = [scene.objects[i].name for i in sorted(data.bases)]
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
        gather_wi, gather_e = direct_samples(self.scene, self.lights, data.gather_position,
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
        self._gather_light = (gather_wi, gather_e)
        self._reflection_edits = []
        self._reflection_w = (self._brdf_reflection()
                              if self.knobs["gather_reflection"] == "brdf" else None)
        indirect = albedo_x * self._product(data.diffuse, slice(None))
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

    def _product(self, matrix, rows) -> np.ndarray:
        """Return rows of ``matrix`` (view samples ``rows``) times the gather radiance.

        L^w, plus with ``gather_reflection`` "brdf" the vector of each row's block: the
        gather samples' BRDF reflection of their direct light (:meth:`_brdf_reflection`).
        """
        product = quantised_product(matrix, self._radiance_w)
        if self._reflection_w is not None:
            product += self._per_block_product(matrix, self._reflection_w, rows)
        return product

    def _per_block_product(self, matrix, vectors, rows) -> np.ndarray:
        """Return rows of ``matrix`` (view samples ``rows``), each times its block's vector."""
        out = np.empty((matrix.rows, 3), dtype=np.float32)
        product_rgb_per_row(matrix.indptr, matrix.packed, matrix.scales, matrix.index_bits,
                            vectors, self._blocks[0][rows], out)
        return out

    def _apply_reflection_edits(self) -> None:
        """Bring the gather samples' BRDF reflection up to edits of gamma or rho_s.

        Only the edited objects' gather samples are evaluated again (their new part less
        their old one); the products of every row with the change are added to the kept
        ones. No shadow ray, no Eq. 17 series: an edit is not a relighting.
        """
        change = self._brdf_reflection(self._reflection_edits)
        self._reflection_edits = []
        self._reflection_w += change
        added = self._albedo("view") * self._per_block_product(self.data.diffuse, change,
                                                                 slice(None))
        indirect = self._parts["indirect"] + added
        self._parts = {"direct": self._parts["direct"], "indirect": indirect,
                       "all": self._parts["direct"] + indirect}
        for name, products in self._products.items():
            rows = self._members[name]
            self._products[name] = products + (
                self._per_block_product(self.frozen[name][1], change, rows)
                if name in self.frozen else
                np.stack([self._per_block_product(m, change, rows)
                          for m in self._transfer[name]]))
        self._glossy_parts = {}

    def _brdf_reflection(self, edits=None) -> np.ndarray:
        """Return, per block of pixels, the glossy radiance the gather samples send it (Haar).

        Each gather sample on an object with an analytic BRDF reflects the light that
        reaches it directly towards the block's centre by rho_s f_F f_E(gamma), f_E by its
        PCA (Eq. 10; its diffuse term is in L^w already): Haar coefficients over the gather
        square, channels first (B, 3, G), one vector a block (:func:`reflection_blocks`,
        :func:`~.kernels.block_reflection`). With ``edits``, ``[(object name, old material,
        new material), ...]``: the change those edits make, the edited objects alone.
        """
        data = self.data
        if self._blocks is None:
            self._blocks = reflection_blocks(data.shape, data.pixel, data.view_object,
                                             data.view_position, self._reflection_tile())
        _, centre, radius = self._blocks
        _check_reflection_bytes(len(centre), len(data.gather_position))
        wi, irradiance = self._gather_light
        radiance = np.zeros((len(centre), 3, len(data.gather_position)), dtype=np.float32)
        lit = irradiance.max(axis=(1, 2), initial=0.0) > 0
        for name, material, coefficients, rho_s in self._reflection_terms(edits):
            # the gather samples of this object that the lights reach
            found = np.flatnonzero((data.gather_object == self._index[name]) & lit)
            if not len(found):
                continue
            basis = self.data.bases[self._index[name]]
            block_reflection(centre, radius, data.gather_position[found],
                             data.gather_normal[found],
                             np.sqrt(data.gather_area[found] / math.pi), found,
                             np.ascontiguousarray(wi[found]),
                             np.ascontiguousarray(irradiance[found] * rho_s),
                             coefficients, REFLECTION_GUARD,
                             *material_parameters(material, basis), radiance)
        side = int(round(math.sqrt(radiance.shape[2])))
        haar2d_forward_in_place(radiance.reshape(-1, side, side))
        return radiance

    def _reflection_terms(self, edits=None) -> list:
        """Return ``(object, material, c, rho_s)`` whose reflections :meth:`_brdf_reflection` sums.

        Every glossy object's, or each edit's change: one term with c(new) - c(old) where
        rho_s stays (the kernel is linear in c), else the new term and the old one negated.
        """
        def basis(name):
            return self.data.bases[self._index[name]]

        if edits is None:  # every glossy object, seen by the camera or not
            return [(name, self.materials[name],
                     basis(name).coefficients(self.materials[name].gamma),
                     self.materials[name].rho_s) for name in self._reflecting]
        terms = []
        for name, old, new in edits:
            new_c, old_c = (basis(name).coefficients(m.gamma) for m in (new, old))
            if np.array_equal(old.rho_s, new.rho_s):
                terms.append((name, new, new_c - old_c, new.rho_s))
            else:
                terms += [(name, new, new_c, new.rho_s), (name, old, old_c, -old.rho_s)]
        return terms

    def _reflection_tile(self) -> int:
        """Pixels on a side of a block: about ``reflection_blocks`` blocks over the view samples."""
        return max(1, round(math.sqrt(len(self.data.pixel) / self.knobs["reflection_blocks"])))

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
        direct = np.einsum("ps,psc->pc", _lobe(material, variable), weight)
        frozen = name in self.frozen
        products = self._products.get(name)
        if products is None:
            rows = self._members[name]
            products = (self._product(self.frozen[name][1], rows) if frozen
                        else np.stack([self._product(m, rows) for m in self._transfer[name]]))
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
            # gather samples that reflect by their BRDF send every pixel new light
            if glossy and self.knobs["gather_reflection"] == "brdf" and (
                    old.gamma != new.gamma or not np.array_equal(old.rho_s, new.rho_s)):
                self._reflection_edits.append((name, old, new))
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
        elif self._reflection_edits:
            self._apply_reflection_edits()
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
        """Set one object's gamma and render (Sect. 6.2).

        Only that object's pixels change, but with ``gather_reflection`` "brdf", whose gather
        samples send every pixel the light the object's BRDF reflects.
        """
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
