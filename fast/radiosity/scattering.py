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

    def channel(self, c: int) -> sparse.csr_matrix:
        """S of channel ``c`` as a CSR matrix (shares the pattern)."""
        size = len(self.indptr) - 1
        return sparse.csr_matrix((self.data[:, c], self.indices, self.indptr),
                                 shape=(size, size))

    def dot(self, vectors) -> np.ndarray:
        """``S_c @ vectors[:, c]`` for c = R, G, B; shape (P, 3).

        Large matrices take one compiled pass over the shared pattern for the three
        channels (a Jacobi sweep multiplies by S once per iteration, Sect. 5.3).
        """
        vectors = np.asarray(vectors)
        if len(self.indices) < COMPILED_PRODUCT_ENTRIES:
            return np.stack([self.channel(c) @ vectors[:, c] for c in range(3)], axis=1)
        out = np.empty((len(self.indptr) - 1, 3))
        compiled_rgb_product()(self.indptr, self.indices, self.data,
                                np.ascontiguousarray(vectors, np.float64), out)
        return out

    def power_column_sums(self, area) -> np.ndarray:
        r""":math:`\sum_j A_j S_{ji} / A_i` per patch and channel, shape (P, 3) (Eq. 15)."""
        area = np.asarray(area, dtype=np.float64)
        return np.stack([self.channel(c).T @ area for c in range(3)], axis=1) / area[:, None]

    @property
    def bytes(self) -> int:
        """Memory of the three channels and the shared pattern."""
        return int(self.data.nbytes + self.indices.nbytes + self.indptr.nbytes)


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
                      profile: str = DEFAULT_PROFILE) -> ScatteringMatrix:
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
    chosen = profile
    grid = geometry.grid
    data = np.zeros((geometry.nnz, 3))
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
            if item.diffusion is not None and isinstance(profile, DipoleProfile):
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
    return ScatteringMatrix(geometry.indptr, geometry.indices, data)


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


