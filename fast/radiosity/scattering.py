"""The scattering matrix S of a material (Sheng et al. 2014, Eq. 7-8, 16, Sect. 5.2-5.3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ...errors import InputError
from ...materials.dipole import dipole_depths
from ...materials.homogeneous import Dipole
from ...materials.profiles import (
    DipoleProfile,
    MixedProfiles,
    RadialGrid,
    RadialProfile,
    ScaledProfile,
    SlabProfile,
    profile_for,
    radial_cumulative_integral,
)
from ..knobs import DEFAULT_PROFILE, radial_profile
from .diffusion_escape import (
    finite_object_gain,
    source_escape_probability,
)
from .form_factors import Patches
from .geometry import ObjectScattering, ScatteringGeometry
from .kernels import (
    COMPILED_PRODUCT_ENTRIES,
    add_rows,
    compiled_energy_correction,
    compiled_mixed_profile,
    compiled_rgb_product,
    scatter_product,
)


@dataclass(eq=False)
class ScatteringMatrix:
    """S for the three RGB channels, one sparsity pattern (Sheng et al. 2014, Sect. 5.3).

    Parameters
    ----------
    indptr, indices : ndarray
        CSR pattern (rows: exit patch, columns: incident patch).
    data : ndarray, shape (nnz, 3)
        Dimensionless scattering factors.
    """

    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    #: the objects' geometry corrections, each a :class:`GeometryBlock`, added to the
    #: sparse factors in every product (knob ``geometry``)
    blocks: tuple = ()

    @property
    def size(self) -> int:
        """The number of patches P."""
        return len(self.indptr) - 1

    def channel(self, c: int) -> sparse.csr_matrix:
        """Return the sparse factors of channel ``c`` as a CSR matrix (shares the pattern).

        Without the geometry :attr:`blocks`; :meth:`channel_dot` and :meth:`dense_channel`
        include them.
        """
        return sparse.csr_matrix((self.data[:, c], self.indices, self.indptr),
                                 shape=(self.size, self.size))

    def channel_dot(self, c: int, vector) -> np.ndarray:
        """``S_c @ vector`` with the geometry blocks, shape (P,)."""
        out = self.channel(c) @ vector
        for block in self.blocks:
            out[block.members] += block.left @ (block.right[c] @ vector[block.members])
        return out

    def dense_channel(self, c: int, dtype=np.float32) -> np.ndarray:
        """S of channel ``c`` as a dense (P, P) array, the geometry blocks added."""
        out = self.channel(c).toarray().astype(dtype)
        for block in self.blocks:
            out[np.ix_(block.members, block.members)] += \
                (block.left @ block.right[c]).astype(dtype)
        return out

    def dot(self, vectors) -> np.ndarray:
        """``S_c @ vectors[:, c]`` for c = R, G, B; shape (P, 3).

        Large matrices take one compiled pass over the shared pattern for the three
        channels (a Jacobi sweep multiplies by S once per iteration, Sect. 5.3); a
        geometry block costs two thin products per channel.
        """
        vectors = np.asarray(vectors)
        if len(self.indices) < COMPILED_PRODUCT_ENTRIES:
            out = np.stack([self.channel(c) @ vectors[:, c] for c in range(3)], axis=1)
        else:
            out = np.empty((self.size, 3))
            compiled_rgb_product()(self.indptr, self.indices, self.data,
                                    np.ascontiguousarray(vectors, np.float64), out)
        for block in self.blocks:
            clusters = np.einsum("ckn,nc->kc", block.right, vectors[block.members])
            out[block.members] += block.left @ clusters
        return out

    def power_column_sums(self, area) -> np.ndarray:
        r""":math:`\sum_j A_j S_{ji} / A_i` per patch and channel, shape (P, 3) (Eq. 15)."""
        area = np.asarray(area, dtype=np.float64)
        sums = np.stack([self.channel(c).T @ area for c in range(3)], axis=1)
        for block in self.blocks:
            exit_area = block.left.T @ area[block.members]  # (K,)
            sums[block.members] += np.einsum("k,ckn->nc", exit_area, block.right)
        return sums / area[:, None]

    @property
    def bytes(self) -> int:
        """Memory of the three channels, the shared pattern and the geometry blocks."""
        return int(self.data.nbytes + self.indices.nbytes + self.indptr.nbytes
                   + sum(block.bytes for block in self.blocks))


@dataclass(eq=False)
class GeometryBlock:
    r"""One object's geometry correction in S, as a product of thin factors.

    :math:`S^{geo}_{ji} = \sum_m W_{jm}\,R^c_{mi}` over the object's patches ``members``,
    with :math:`W` the exit patches' weights over the object's surface clusters and
    :math:`R^c = f_c\,C^c\,W^T \mathrm{diag}(A_i)` (:mod:`translucent.fast.object_geometry`):
    the response :math:`C` between clusters per unit power entering, the patches' areas in
    mm^2 and :math:`f_c` the profile's total over the dipole's (its entry transmittance
    included), so that the correction carries the profile's own energy.

    Parameters
    ----------
    members : ndarray of int, shape (n,)
        The object's patches.
    left : scipy.sparse.csr_matrix, shape (n, K)
        Exit weights :math:`W`.
    right : ndarray, shape (3, K, n)
        :math:`R^c`.
    """

    members: np.ndarray
    left: sparse.csr_matrix
    right: np.ndarray

    @property
    def bytes(self) -> int:
        """Memory of the two factors."""
        left = self.left
        return int(self.right.nbytes + self.members.nbytes + left.data.nbytes
                   + left.indices.nbytes + left.indptr.nbytes)


def scattering_profile(material, profile: str = DEFAULT_PROFILE):
    r"""Return the radial profile S is filled from for ``material`` (None: opaque, S = P).

    With the knob ``profile`` at its default, :func:`~translucent.materials.profiles.profile_for`
    as the paper fills S: the classical dipole times the diffuse entry transmittance
    :math:`T_{in}(\eta)` (Sheng et al. 2014, Sect. 6.1). Another ``profile`` (a value of
    the knob, :func:`~translucent.fast.knobs.radial_profile`) is made from each Dipole
    medium instead -- a Dipole material, or the Dipoles of a heterogeneous object -- times
    the same :math:`T_{in}`: E is the irradiance outside the boundary and every registered
    profile is per unit power entering. Tabulated and slab profiles are the material's
    own and are kept.

    Parameters
    ----------
    material : Dipole, RadialProfile, MixedProfiles or Lambertian
    profile : str
        A value of the ``profile`` knob.

    Returns
    -------
    RadialProfile, MixedProfiles or None
    """
    found = profile_for(material)
    if profile == DEFAULT_PROFILE or found is None:
        return found
    if isinstance(found, DipoleProfile):
        return _from_dipole(found, profile)
    if isinstance(found, MixedProfiles):
        return MixedProfiles([_from_dipole(p, profile) if isinstance(p, DipoleProfile) else p
                              for p in found.profiles], found.face_labels, name=found.name,
                             volume_labels=found.volume_labels, volume_key=found.volume_key)
    return found


def _from_dipole(dipole_profile: DipoleProfile, profile: str) -> RadialProfile:
    """Return the profile ``profile`` of a dipole profile's medium, times its entry term."""
    made = radial_profile(profile, dipole_profile.dipole)
    return made if dipole_profile.entry == 1.0 else ScaledProfile(made, dipole_profile.entry)


def _object_profile_tables(profile: RadialProfile, grid: RadialGrid, kind: str = "reflection"):
    table = profile.tabulate(grid, kind)
    return table, radial_cumulative_integral(grid.radius, table)


def scattering_matrix(geometry: ScatteringGeometry, scene, patches: Patches,
                      materials: dict | None = None, *,
                      profile: str = DEFAULT_PROFILE,
                      geometries: dict | None = None) -> ScatteringMatrix:
    """Build S from the cached geometry and the materials: one sparse product per object.

    Sheng et al. 2014, Sect. 4-5.2: "the subsurface scattering matrix is then computed by
    just indexing, based on distances, into the reflection/transmission profiles";
    heterogeneous objects mix their profiles per sample with Eq. 16.

    Parameters
    ----------
    geometry : ScatteringGeometry
    scene : Scene
    patches : Patches
    materials : dict of str to material, optional
        Overrides of the scene's materials by object name.
    profile : str
        The knob ``profile``: the radial profile made from Dipole media
        (:func:`scattering_profile`).
    geometries : dict of str to ObjectGeometry, optional
        The objects' geometry corrections (knob ``geometry``,
        :func:`~translucent.fast.object_geometry.object_geometries`): each such object with
        a Dipole material gets its :class:`GeometryBlock`, in place of the escape gain of
        the knob ``finite_object_energy``.

    Returns
    -------
    ScatteringMatrix

    Raises
    ------
    InputError
        A translucent material on an object that was opaque at precomputation, an opaque
        one where S was precomputed (it still works: S = P), an unsupported material, or
        a profile with NaN / negative values.
    """
    materials = materials or {}
    geometries = geometries or {}
    chosen = profile
    grid = geometry.grid
    data = np.zeros((geometry.nnz, 3))
    blocks = []
    for index, obj in enumerate(scene.objects):
        material = materials.get(obj.name, obj.material)
        profile = _sheet_profile(scattering_profile(material, chosen), index, geometry,
                                 obj.name, chosen if isinstance(material, Dipole) else None)
        members = patches.of_object(index)
        if profile is None:
            data[geometry.diagonal_position[members]] = material.albedo
            continue
        item = geometry.objects.get(index)
        if item is None:
            raise InputError(f"object '{obj.name}' was opaque when the scattering factors "
                             "were precomputed: precompute with it translucent",
                             field="material", value=getattr(material, "name", "") or
                             type(material).__name__)
        # a thin sheet has two blocks of each kind (its two faces): tabulate once per kind
        tables: dict = {}
        if not isinstance(profile, MixedProfiles):
            for kind, pair_position, own_position in item.blocks:
                if kind not in tables:
                    tables[kind] = _object_profile_tables(profile, grid, kind)
                table, cumulative = tables[kind]
                scatter_product(item.sample_operator, table, pair_position, data)
                if item.self_cumulative is not None:
                    data[own_position] += (item.self_cumulative @ cumulative
                                           + item.self_segment @ table)
            shape = geometries.get(obj.name)
            if shape is not None and isinstance(material, Dipole) and \
                    index not in geometry.sheets:
                blocks.append(geometry_block(shape, patches, members, material, profile,
                                             chosen))
            elif item.diffusion is not None and isinstance(profile, DipoleProfile):
                _carry_finite_object_energy(data, geometry, patches, item, profile)
            continue
        if item.samples is None:
            raise InputError(f"a heterogeneous material on '{obj.name}' needs its face labels "
                             "at precomputation: precompute with the MixedProfiles material",
                             field="material", value=profile.name)
        labels = item.samples["patch_label"]
        for kind, pair_position, own_position in item.blocks:
            if kind not in tables:
                # the self term of every patch with each label's homogeneous profile
                own_values = [] if item.self_cumulative is None else [
                    item.self_cumulative @ cumulative + item.self_segment @ table
                    for table, cumulative in (_object_profile_tables(homogeneous, grid, kind)
                                              for homogeneous in profile.profiles)]
                tables[kind] = (mixed_values(item, profile, grid, kind), own_values)
            pair_values, own_values = tables[kind]
            add_rows(pair_values, pair_position, data)
            for label, values in enumerate(own_values):
                mine = labels == label
                data[own_position[mine]] += values[mine]
    return ScatteringMatrix(geometry.indptr, geometry.indices, data, tuple(blocks))


def geometry_block(shape, patches: Patches, members, material: Dipole,
                   profile: RadialProfile, chosen: str = DEFAULT_PROFILE) -> GeometryBlock:
    """Return the :class:`GeometryBlock` of one object's patches ``members``.

    ``shape`` is the object's :class:`~translucent.fast.object_geometry.ObjectGeometry`;
    the patches enter and leave at their centroids, each standing for its area. ``profile``
    is the one S is filled from (:func:`scattering_profile`: the knob's profile ``chosen``
    times the entry transmittance); the correction is made for the knob's profile per unit
    power entering and carries the same entry term.
    """
    weights = shape.weights(patches.centroid[members], patches.normal[members])
    base = None if chosen == DEFAULT_PROFILE else radial_profile(chosen, material)
    base_total = (base if base is not None
                  else DipoleProfile(material, entry_fresnel=False)).total()
    entry_term = np.divide(profile.total(), base_total, out=np.ones(3), where=base_total > 0)
    response = shape.response(material, base)  # (K, K, 3): exit, entry
    area = patches.area[members] * patches.mm_per_unit ** 2
    entry = np.asarray((weights.T.multiply(area[None, :])).todense())  # (K, n)
    right = np.stack([entry_term[c] * (response[:, :, c] @ entry) for c in range(3)])
    return GeometryBlock(np.asarray(members), weights.tocsr(), right)


def _carry_finite_object_energy(data, geometry: ScatteringGeometry, patches: Patches,
                                item: ObjectScattering, profile: DipoleProfile) -> None:
    r"""Give the object's columns of S the re-emission of diffusion in its own shape.

    Column i (incident patch i) is brought to the power sum :math:`g_i\int s`: the
    profile's semi-infinite total (at most the entry transmittance times
    :func:`~translucent.fast.radiosity.diffusion_escape.source_escape_probability`, so that
    no column exceeds what diffusion lets out of the object) times the gain of
    :func:`~translucent.fast.radiosity.diffusion_escape.finite_object_gain` (1 in a large object,
    above 1 where the object is comparable to the diffusion length :math:`1/\sigma_{tr}`).
    The light added is light the half-space would have absorbed deep below the surface,
    so it is spread over the column's patches past the entry patch's tangent plane, with
    the weight :math:`A_j\,(e^{-\sigma_{tr}r_1}/r_1 - e^{-\sigma_{tr}r_2}/r_2)` (the
    fluence of the dipole's real source at depth :math:`z_r`, :math:`r_1` from the exit
    centroid, and of its mirror image, :math:`r_2`): zero on the plane, within a few
    diffusion lengths of the entry. A column above its target (a profile folded round the
    edges of a large object) is scaled down instead. Writes ``data``.
    """
    members = item.patches
    area = patches.area
    mm = patches.mm_per_unit
    dipole = profile.dipole
    # a channel without absorption (or without scattering) has no diffusion length: the
    # dipole already returns all of it (or none), and its columns are left as they are
    channels = np.flatnonzero((dipole.sigma_a > 0) & (dipole.sigma_s_prime > 0))
    gain = np.ones((len(members), 3))
    ceiling = np.ones(3)
    if len(channels):
        sigma_a, sigma_s_prime = dipole.sigma_a[channels], dipole.sigma_s_prime[channels]
        gain[:, channels] = finite_object_gain(item.diffusion, patches.centroid[members] * mm,
                                               patches.normal[members], sigma_a,
                                               sigma_s_prime, dipole.eta)
        # never more than the object's own escape probability (times the entry transmittance)
        ceiling[channels] = profile.entry * source_escape_probability(sigma_a, sigma_s_prime,
                                                                      dipole.eta)
    size = len(area)
    in_object = np.zeros(size, dtype=bool)
    in_object[members] = True
    target = np.zeros((size, 3))
    target[members] = np.minimum(profile.total(), ceiling)[None, :] * gain
    applied = np.zeros(3, dtype=bool)
    applied[channels] = True
    z_r, _ = dipole_depths(dipole.sigma_a, dipole.sigma_s_prime, dipole.eta)
    compiled_energy_correction()(
        geometry.indptr, geometry.indices, data, in_object, np.ascontiguousarray(area),
        np.ascontiguousarray(patches.centroid * mm), np.ascontiguousarray(patches.normal),
        np.asarray(z_r, np.float64), np.asarray(dipole.sigma_tr, np.float64), target,
        applied)
    item.facts["finite_object_gain"] = {"min": gain.min(axis=0).tolist(),
                                        "mean": gain.mean(axis=0).tolist(),
                                        "max": gain.max(axis=0).tolist()}




def _sheet_profile(profile, index: int, geometry: ScatteringGeometry, name: str,
                   made_from: str | None = None):
    """Turn a Dipole's profile on a thin sheet into the slab's reflection and transmission.

    Only the dipole has a slab form here (:class:`SlabProfile`, the multipole): another
    profile made from a Dipole (``made_from``, the knob's value) on a sheet would lose the
    light the sheet transmits, and is refused.
    """
    if index in geometry.sheets and made_from not in (None, DEFAULT_PROFILE) and \
            not profile.has_transmission:
        raise InputError(f"object '{name}' is a thin (open) sheet, lit from both sides: "
                         f"profile {made_from!r} has no transmission (only the dipole has a "
                         "slab form, SlabProfile); use profile 'dipole'", field="profile",
                         value=made_from)
    if index not in geometry.sheets or not isinstance(profile, DipoleProfile):
        return profile
    if geometry.sheet_thickness_mm is None:
        raise InputError(f"object '{name}' is a thin (open) sheet: give the knob "
                         "sheet_thickness_mm, or a profile with transmission (SlabProfile, "
                         "a table or two-exponential form)", field="sheet_thickness_mm",
                         value=None)
    return SlabProfile(profile.dipole, geometry.sheet_thickness_mm,
                       entry_fresnel=profile.entry_fresnel)


def mixed_values(item: ObjectScattering, profile: MixedProfiles, grid: RadialGrid,
                  kind: str = "reflection"):
    """Eq. 16 summed per patch pair over the pair's samples, shape (pairs, 3).

    Equal to :func:`~translucent.materials.profiles.mixed_profile` at every sample (a
    test compares the two), compiled because it runs on every sample of every pair.
    """
    samples = item.samples
    tables = np.ascontiguousarray(np.stack([p.tabulate(grid, kind) for p in profile.profiles]),
                                  dtype=np.float64)
    zero = np.ascontiguousarray(tables[:, 0])
    pairs = item.sample_operator.shape[0]
    pair, distance, weight = samples["pair"], samples["distance"], samples["weight"]
    if len(pair) > 1 and (np.diff(pair) < 0).any():  # scattering_geometry's are in pair order
        order = np.argsort(pair, kind="stable")
        pair, distance, weight = pair[order], distance[order], weight[order]
    starts = np.searchsorted(pair, np.arange(pairs + 1)).astype(np.int64)
    out = np.zeros((pairs, 3))
    compiled_mixed_profile()(np.ascontiguousarray(distance), np.ascontiguousarray(
        samples["fractions"]), starts, float(samples["mix_points"]),
        np.ascontiguousarray(weight), zero, tables, float(grid.max_radius), out)
    return out


