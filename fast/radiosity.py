r"""Translucent radiosity: diffuse inter-reflection combined with subsurface scattering.

Sheng, Shi, Wang, Narasimhan: Translucent radiosity: efficiently combining diffuse
inter-reflection and subsurface scattering. IEEE TVCG 20(7), 2014.

The scene is cut into patches; the radiosity (exitance) :math:`B` of every patch solves

.. math:: B = \sum_{N \ge 1} (SF)^{N-1} SE = (I - SF)^{-1} SE \qquad \text{(Eq. 14)}

with :math:`E` the irradiance from the lights, :math:`F` the form factors (irradiance of
patch i from the radiosity of patch j, :mod:`translucent.fast.form_factors`) and
:math:`S` the scattering factors: :math:`S_{ji}` takes the irradiance of patch i to the
radiosity of patch j through the material (Eq. 7-8). For an opaque Lambertian patch
:math:`S = P = \mathrm{diag}(\rho)` and Eq. 14 is classical radiosity (Eq. 2).

Scattering factors (Eq. 8, Sect. 5.2). With the exit point at the centroid :math:`c_j`,

.. math:: S_{ji} = \frac{1}{A_j}\int_{A_i}\int_{A_j} s\,dA_j\,dA_i
          \approx \int_{A_i} s(d(x, c_j))\,dA_x,

where :math:`s(r)` is a 1D profile (:mod:`translucent.materials.profiles`) of the
shortest optical distance :math:`d` (:mod:`translucent.fast.optical_distance`). The
normalisation by :math:`A_j` (the paper prints :math:`A_i`; the two agree for equal
patches) makes :math:`B_j = \sum_i S_{ji} E_i` an exitance for patches of any size, and the
energy condition of Eq. 15 reads :math:`\sum_j A_j S_{ji} / A_i < 1` (the power-form
column sums). The integral over the incident patch uses its sub-triangle centroids, 100
on a patch's neighbours, fewer as the distance grows (``m^2`` with ``m`` falling
exponentially), the centroid alone beyond a threshold, nothing beyond max_d. The patch's
own term, where the profile peaks, is integrated in polar coordinates about the centroid
against the exact cumulative integral of the tabulated profile (``self_term="polar"``,
the default; ``"samples"`` uses 100 samples as the paper does -- the bench measures both).

Every sample stores only the profile-grid segment and offset of its distance (Sect. 5.2:
"each index contains [...] profile indices and offsets"), gathered in a sparse operator
``W`` (pairs x grid nodes): a change of translucency re-tabulates the profile and computes
``S.data = W @ table`` for the three channels at once, nothing else.

Finite objects (knob ``finite_object_energy``, on by default; beyond the paper, whose
Sect. 7 names the limitation). The semi-infinite dipole sends light that a small object
re-emits through its other faces into a half-space that is not there: in the Cornell-box
block (30 x 60 x 30 mm) at a quarter of skim milk's scattering it re-emits 0.77 / 0.77 /
0.61 (R, G, B) of the light entering the top where a photon random walk in the box gives
0.97 / 0.95 / 0.81. Each translucent patch's column of S is therefore brought to the power
sum :math:`g_i\int s`, with :math:`g_i` the escape probability of diffusion in the
object's own shape over the half-space's (:mod:`translucent.fast.diffusion_escape`: one
finite-volume solve per channel on a voxel grid of the object, ``diffusion_voxels_per_axis``
cells along its longest side), the light added spread over the column's patches in
proportion to the fluence of the dipole's source with its mirror image in the entry
patch's tangent plane (zero on that plane: the extra light is what the half-space would
carry past the object's other faces).
Measured against index-matched Mitsuba references (block mean, radiosity / reference,
R G B): skim milk x0.25 0.77 0.81 0.72 -> 0.96 0.94 0.90; x1 0.89 0.90 0.86 -> 0.92 0.94
0.94; x8 1.00 1.05 1.12 -> 1.03 1.08 1.14 (gain 1.00-1.03); the bowl (Chicken1, a 6 mm
wall, gain about 2 in red and green) 0.83 0.62 0.63 -> 1.08 0.89 0.77, its relative MSE
0.024 -> 0.014. What remains at x1 and in blue is mostly the dipole's own
deficit against transport (1-11 % in the random walk, the object's size aside).
Cost on the bench's 25,080-patch box (Marble block of 3,920 patches, 8,160 cells; gain
0.99-1.07 in a block of 165 x 330 mm): precomputation +2.2 s, a translucency change 0.033
-> 0.077 s re-indexing and 0.076 -> 0.12 s with the solve (8 fps; the paper's 4), load 1.4.

Solving (Sect. 5.3): Jacobi iteration :math:`B \leftarrow SE + SFB` (the paper's solver) or
GMRES / BiCGSTAB from :mod:`scipy.sparse.linalg`, to a relative residual
:math:`\|SE - (I - SF)B\| / \|SE\|` of 0.5 %. Before any iteration the condition of Eq. 15 is
checked; a material that breaks it raises :class:`~translucent.errors.InputError` naming
the object, patch, channel and column sum. A Jacobi sweep's change is the residual of the
iterate it started from, so that iterate is returned with its :math:`FB` (which the image
needs): every product of SF advances or checks, none is spent twice. Successive frames
start from the earlier frames' solutions projected on the new irradiance
(:meth:`RadiosityState.solve`): 2 products per frame on a sliding light.

A whole relighting frame of the bench's 25,080-patch box at 96 x 96 (patch irradiance with
16 shadow rays per patch, warm-started Jacobi, image with 16 shadow rays per diffuse pixel):
0.056-0.078 s, 17.9-12.9 fps at load averages 0.7-1.2 on 2 cores, against 0.184-0.208 s
(5.4-4.8 fps) before the frame path below in the same runs; the solve is now the largest
part (0.023-0.038 s: the product SE, then one F and one S product per Jacobi sweep, 1 or
2 sweeps; the compiled products run on both cores, F 9-11 ms against 16-21 ms on one).

Relighting with :math:`T = (I - SF)^{-1}S` (Sect. 6.4): T is dense, :math:`3P^2` float32, and
is precomputed (at the first relighting after a material change, knob ``transfer="auto"``)
only when that fits the ``transfer_budget_mb`` knob: P <= 6,688 at the default 512 MB; the
dense solve needs about five times that while it runs. It does not pay on this CPU:
at 6,270 patches T took 44 s and relit at 75.1 fps against 75.0 fps for the warm-started
iterative solve (``translucent bench radiosity`` on 2 idle cores; 187 s, 13.5 and 14.3 fps
at a load average of 9): a frame reads :math:`12P^2` bytes of T against about 8 bytes per
form factor and product for Jacobi.
Neither does a low-rank T: the inter-reflection operator :math:`F(I - SF)^{-1}S` of the
25,080-patch box has a flat spectrum (ray-cast F, near-field corners), and its randomized
rank-128 approximation misses B by 24 % (rank 32: 35 %) and saves at most two products as
a starting guess (bench).

Images: direct lighting of diffuse surfaces is evaluated per pixel through the G-buffer
(the paper's hybrid that removes per-patch shadow artifacts), the global part
:math:`FB` and the radiosity of translucent surfaces come from the patch solution,
averaged to the vertices and interpolated: both linear maps are multiplied into one sparse
(pixels x patches) matrix per camera, so a frame's image is two sparse products.

A relighting frame moves only the lights: the shadow rays of rectangular area lights
(patches and diffuse pixels) start from points offset once (:class:`AreaLightShadows`),
their cosines and rays come from two compiled loops and each light's rays go to the ray
engine in one call (knob ``shadow_ray_engine``); the result is that of
:func:`direct_irradiance` to round-off. Other lights take :func:`direct_irradiance`.

:meth:`RadiosityState.components` gives the decomposition of the paper's Fig. 6: direct
only, inter-reflection only (translucent patches as diffuse ones of the same total
reflectance), subsurface only (:math:`B = SE`), and both.
"""

from __future__ import annotations

import functools
import math
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse import linalg as sparse_linalg
from scipy.spatial import cKDTree

from ..errors import InputError, check_count
from ..image import Image
from ..materials.dipole import dipole_depths
from ..materials.homogeneous import Lambertian
from ..materials.profiles import (
    DipoleProfile,
    MixedProfiles,
    RadialGrid,
    RadialProfile,
    SlabProfile,
    profile_for,
    radial_cumulative_integral,
)
from ..materials.solid import SolidMedium
from ..scenes.scene import (
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    SphereAreaLight,
    SpotLight,
)
from .base import StageLog, refuse_inapplicable, with_defaults
from .diffusion_escape import (
    DiffusionGrid,
    diffusion_grid,
    finite_object_gain,
    source_escape_probability,
    voxel_size_for,
)
from .form_factors import Patches, build_patches, form_factors, needs_form_factors
from .optical_distance import (
    closed_surface,
    is_convex,
    optical_distances,
    subdivision_barycentrics,
    voxelize,
)
from .solid_inputs import mixed_profiles_from_solid, surface_scene

__all__ = [
    "COMPONENTS",
    "DEFAULT_KNOBS",
    "SOLVERS",
    "AreaLightShadows",
    "ConvergenceError",
    "RadiosityState",
    "ScatteringGeometry",
    "ScatteringMatrix",
    "add_approx_arguments",
    "applies_to",
    "approx",
    "check_convergence",
    "form_factor_bounds",
    "direct_irradiance",
    "form_factor_product",
    "precompute",
    "scattering_geometry",
    "scattering_matrix",
    "solve_radiosity",
    "transfer_matrix",
]

#: Version of the precomputed data layout (part of the cache key).
FORMAT_VERSION = 5

#: Knobs of :func:`precompute` and their defaults.
DEFAULT_KNOBS: dict = {
    # patches and form factors
    "triangles_per_patch": 1,        # 1: triangles; n > 1: coplanar neighbours merged
    "rays_per_patch": 256,           # form-factor rays from each patch
    "form_factor_threshold": 0.0,    # F entries below this are dropped
    # scattering factors
    "max_distance_mm": None,         # max_d; None: where every profile keeps 99.9 %
    "profile_energy_cutoff": 1e-3,   # energy fraction beyond max_d when it is derived
    "self_samples": 100,             # samples on a patch's nearest neighbours (m^2)
    "sample_falloff": 2.0,           # m falls as exp(-distance / (this x patch radius))
    "centroid_beyond": 8.0,          # centroid only beyond this many patch radii
    "self_term": "polar",            # "polar" (exact profile integral) or "samples"
    "voxels_per_axis": 48,           # voxel grid of a concave object, along its longest side
    "profile_samples": 2048,         # radial grid nodes of the tabulated profiles
    "mix_points": 8,                 # points along a path for heterogeneous fractions
    "sheet_thickness_mm": None,      # thin (open) translucent sheets: slab thickness
    "finite_object_energy": True,    # S columns carry the object's diffusion escape (gain)
    "diffusion_voxels_per_axis": 32,  # its finite-volume grid, along the longest side
    # solving and lighting
    "solver": "jacobi",              # "jacobi", "gmres" or "bicgstab"
    "tolerance": 5e-3,               # relative residual (the paper's 0.5 %)
    "max_iterations": 2000,
    "warm_start": True,              # start from the earlier frames' solutions
    "transfer": "auto",              # "auto": T at the first relighting when it fits; "never"
    "transfer_budget_mb": 512,       # T fits when 3 P^2 float32 do (P <= 6,688 at 512 MB)
    "light_samples": 16,             # samples per area light / environment per point
    "diffuse_light_samples": None,   # per diffuse patch (its E feeds only F B); None: as above
    "shadow_ray_engine": "auto",     # relighting's shadow rays: "auto", "embree", "mitsuba"
    "seed": 0,
}

#: Knobs that only steer solving and lighting: not part of the precomputation's cache key.
RUNTIME_KNOBS = ("solver", "tolerance", "max_iterations", "warm_start", "transfer",
                 "transfer_budget_mb", "light_samples", "diffuse_light_samples",
                 "shadow_ray_engine")

#: The iterative solvers.
SOLVERS = ("jacobi", "gmres", "bicgstab")

#: The bounce decomposition of Sheng et al. 2014, Fig. 6.
COMPONENTS = ("direct", "interreflection", "subsurface", "both")

#: Gauss-Legendre nodes per triangle edge for the polar self term: the integrand along an
#: edge is C(sqrt(h^2 + s^2)) h / (h^2 + s^2), smooth; 8 nodes integrate a constant
#: profile over a triangle to 1e-12 and the dipole to 1e-6.
POLAR_NODES = 8

#: Earlier frames whose solutions start a relighting solve (:meth:`RadiosityState.solve`):
#: on the bench's sliding light, 6 frames cut the Jacobi products per frame from 3 (the last
#: frame's inter-reflection alone) to 2.
WARM_START_FRAMES = 6

#: Residual growth (over the smallest seen) that stops an iteration as diverging.
DIVERGENCE_FACTOR = 1e3


class ConvergenceError(RuntimeError):
    """The radiosity iteration did not reach its tolerance; carries the numbers.

    Attributes
    ----------
    residual : float
        The relative residual reached.
    iterations : int
    """

    def __init__(self, message: str, *, residual: float, iterations: int):
        super().__init__(message)
        self.residual = residual
        self.iterations = iterations


# ---------------------------------------------------------------------------------------
# scattering geometry: distances, samples, profile indices (material independent)


@dataclass(eq=False)
class ObjectScattering:
    """The cached scattering samples of one translucent object.

    Parameters
    ----------
    object_index : int
    patches : ndarray of int
        Its global (front) patch indices.
    blocks : list of (str, ndarray, ndarray)
        ``(kind, pair_position, self_position)``: where the pairs and the patches' own
        terms land in the data of S, and which profile (``"reflection"`` or
        ``"transmission"``) fills them. One block for a solid object; four for a two-sided
        sheet (front-front and back-back by reflection, across by transmission, Sheng et
        al. 2014, Sect. 6.1).
    sample_operator : scipy.sparse.csr_matrix, shape (pairs, K)
        Interpolation weights (mm^2) of every sample onto the profile grid: the S entries
        of the pairs are ``sample_operator @ table``.
    self_cumulative, self_segment : scipy.sparse.csr_matrix, shape (patches, K)
        The polar self term: ``self_cumulative @ C + self_segment @ table`` with C the
        cumulative radial integral of the table (None when ``self_term="samples"``).
        These three are kept for heterogeneous objects only (None otherwise).
    operators : list of (str, csr_matrix, csr_matrix or None, csr_matrix or None)
        Per block, ``(kind, samples, cumulative, segment)`` with their rows moved to the
        positions of the entries in the data of S (shape nnz x K): a translucency change
        is ``data += samples @ table + cumulative @ C + segment @ table``, no scatter.
    samples : dict or None
        Heterogeneous objects only: ``pair``, ``weight`` (mm^2), ``distance`` (mm), and
        ``fractions`` (pairs x materials), ``patch_label``.
    diffusion : DiffusionGrid or None
        The finite-volume grid of a closed object when the knob ``finite_object_energy``
        is on (:mod:`translucent.fast.diffusion_escape`).
    facts : dict
        Counts and timings for the report.
    """

    object_index: int
    patches: np.ndarray
    blocks: list
    sample_operator: sparse.csr_matrix | None
    self_cumulative: sparse.csr_matrix | None
    self_segment: sparse.csr_matrix | None
    samples: dict | None
    facts: dict = field(default_factory=dict)
    operators: list = field(default_factory=list)
    diffusion: DiffusionGrid | None = None


@dataclass(eq=False)
class ScatteringGeometry:
    """Everything S needs that does not depend on the material (Sheng et al. 2014, Sect. 5.2).

    Parameters
    ----------
    indptr, indices : ndarray
        The CSR pattern of S (rows: exit patch j, columns: incident patch i), diagonal
        included for every patch.
    diagonal_position : ndarray of int, shape (P,)
        Position of each patch's diagonal entry in the data.
    grid : RadialGrid
        The profile grid; its ``max_radius`` is the cut-off max_d (mm).
    objects : dict of int to ObjectScattering
        The translucent objects.
    sheets : tuple of int
        The translucent objects that are thin two-sided sheets.
    sheet_thickness_mm : float or None
        Thickness that turns a Dipole on a sheet into a :class:`SlabProfile`.
    """

    indptr: np.ndarray
    indices: np.ndarray
    diagonal_position: np.ndarray
    grid: RadialGrid
    objects: dict
    sheets: tuple = ()
    sheet_thickness_mm: float | None = None

    @property
    def nnz(self) -> int:
        """Stored entries of S (per channel)."""
        return len(self.indices)

    @property
    def bytes(self) -> int:
        """Memory held by the cached operators and pattern."""
        total = self.indptr.nbytes + self.indices.nbytes + self.diagonal_position.nbytes
        for item in self.objects.values():
            matrices = [item.sample_operator, item.self_cumulative, item.self_segment]
            matrices += [m for _, *ops in item.operators for m in ops]
            for matrix in matrices:
                if matrix is not None:
                    total += matrix.data.nbytes + matrix.indices.nbytes + matrix.indptr.nbytes
            total += sum(a.nbytes + b.nbytes for _, a, b in item.blocks)
            if item.samples:
                total += sum(np.asarray(v).nbytes for v in item.samples.values())
        return int(total)


def _samples_per_edge(distance, radius, knobs) -> np.ndarray:
    """M (samples = m^2) for each pair: Sheng et al. 2014, Sect. 5.2, decreasing with distance."""
    most = max(1, int(round(math.sqrt(knobs["self_samples"]))))
    m = np.rint(most * np.exp(-distance / (knobs["sample_falloff"] * radius)))
    m = np.clip(m, 1, most).astype(np.int64)
    return np.where(distance > knobs["centroid_beyond"] * radius, 1, m)


def _polar_self_nodes(patches: Patches, members: np.ndarray):
    r"""Nodes of the polar integral of :math:`s(|x - c|)` over each patch about its centroid.

    :math:`\int_{A} s(|x-c|)\,dA = \sum_{\text{edges}} \pm\int C(\rho(\varphi))\,d\varphi` with
    :math:`C(\rho) = \int_0^\rho s(r) r\,dr`; along an edge at distance h from c,
    :math:`d\varphi = h\,ds / (h^2 + s^2)` and :math:`\rho = \sqrt{h^2 + s^2}`.

    Returns
    -------
    rows : ndarray of int
        Index into ``members``.
    rho : ndarray
        mm.
    weight : ndarray
        Radians (signed).
    """
    mm = patches.mm_per_unit
    rows, faces = patches.faces_of(members)
    corners = patches.triangles[faces] * mm
    center = patches.centroid[members][rows] * mm
    normal = patches.normal[members][rows]
    nodes, weights = np.polynomial.legendre.leggauss(POLAR_NODES)
    t, w = 0.5 * (nodes + 1.0), 0.5 * weights
    out_rows, out_rho, out_weight = [], [], []
    for edge in range(3):
        a, b = corners[:, edge], corners[:, (edge + 1) % 3]
        direction = b - a
        length = np.linalg.norm(direction, axis=1)
        unit = direction / length[:, None]
        s_a = np.einsum("ij,ij->i", a - center, unit)
        foot = a - s_a[:, None] * unit
        h = np.linalg.norm(foot - center, axis=1)
        orientation = np.sign(np.einsum("ij,ij->i", np.cross(a - center, b - center), normal))
        keep = (h > 1e-12 * length) & (orientation != 0)
        s = s_a[:, None] + length[:, None] * t[None, :]
        rho = np.sqrt(h[:, None] ** 2 + s**2)
        weight = orientation[:, None] * h[:, None] / rho**2 * length[:, None] * w[None, :]
        out_rows.append(np.repeat(rows[keep], len(t)))
        out_rho.append(rho[keep].ravel())
        out_weight.append(weight[keep].ravel())
    return np.concatenate(out_rows), np.concatenate(out_rho), np.concatenate(out_weight)


def _self_operators(grid: RadialGrid, count: int, rows, rho, weight):
    r"""Sparse operators of the polar self term on the profile grid (exact for the table).

    :math:`C(\rho) = C_k + h_k[s_k a(f) + s_{k+1} b(f)]` on segment k at offset f, with
    :math:`a = r_k(f - f^2/2) + h_k(f^2/2 - f^3/3)`, :math:`b = r_k f^2/2 + h_k f^3/3`.
    """
    # radii at or beyond max_d land on the last segment with f = 1: C(max_d) exactly
    k, f = grid.locate(rho)
    f = f.astype(np.float64)
    radius = grid.radius
    left = radius[k]
    h = radius[k + 1] - left
    a = h * (left * (f - f * f / 2) + h * (f * f / 2 - f**3 / 3))
    b = h * (left * f * f / 2 + h * f**3 / 3)
    shape = (count, grid.samples)
    cumulative = sparse.coo_matrix((weight, (rows, k)), shape=shape).tocsr()
    segment = sparse.coo_matrix((np.concatenate([weight * a, weight * b]),
                                 (np.concatenate([rows, rows]), np.concatenate([k, k + 1]))),
                                shape=shape).tocsr()
    return cumulative, segment


def _at_positions(operator: sparse.csr_matrix, positions, size: int) -> sparse.csr_matrix:
    """Move the rows of ``operator`` to ``positions`` of a (size x K) operator."""
    coo = operator.tocoo()
    return sparse.csr_matrix((coo.data, (np.asarray(positions)[coo.row], coo.col)),
                             shape=(size, operator.shape[1]))


def _pair_fractions(centroids_mm, face_centroids_mm, face_labels, exit_local, incident_local,
                    materials: int, points: int, volume_labels=None,
                    mm_per_unit: float = 1.0) -> np.ndarray:
    """Fraction of the segment between two patch centroids inside each material.

    The material at a point is ``volume_labels(point)`` where the object has a volume
    (a solid medium; points in scene units), otherwise that of the nearest surface face
    (the paper's checkerboard block is labelled on its surface).

    Returns
    -------
    ndarray of uint8, shape (pairs, materials)
        How many of the ``points`` along each segment lie in each material: the fraction
        times ``points``, stored as counts (a byte per pair and material, where float64
        fractions of all pairs of a 4608-patch sphere with 16 materials took 2.7 GB).
    """
    if volume_labels is None:
        tree = cKDTree(face_centroids_mm)
    t = (np.arange(points) + 0.5) / points
    fractions = np.zeros((len(exit_local), materials), dtype=np.uint8)
    chunk = max(1, (1 << 20) // points)
    for start in range(0, len(exit_local), chunk):
        stop = min(len(exit_local), start + chunk)
        a = centroids_mm[exit_local[start:stop]]
        b = centroids_mm[incident_local[start:stop]]
        along = a[:, None] + t[None, :, None] * (b - a)[:, None]
        if volume_labels is None:
            _, nearest = tree.query(along.reshape(-1, 3))
            labels = face_labels[nearest].reshape(stop - start, points)
        else:
            labels = volume_labels(along.reshape(-1, 3) / mm_per_unit).reshape(stop - start,
                                                                                points)
        # one count of every (pair, material): M comparisons of every point took 10 s
        # on a 32-medium gradient
        rows = np.repeat(np.arange(stop - start), points) * materials
        fractions[start:stop] = np.bincount(rows + labels.reshape(-1),
                                            minlength=(stop - start) * materials
                                            ).reshape(stop - start, materials)
    return fractions


def scattering_geometry(scene, patches: Patches, translucent: list[int], *,
                        max_distance_mm: float, knobs: dict, log: StageLog | None = None,
                        sheet_thickness_mm: float | None = None) -> ScatteringGeometry:
    """Distances, samples and profile indices of every scattering factor (Sect. 5.2).

    Parameters
    ----------
    scene : Scene
    patches : Patches
    translucent : list of int
        Indices of the translucent objects (the others get a diagonal S = P).
    max_distance_mm : float
        The cut-off max_d, mm.
    knobs : dict
        :data:`DEFAULT_KNOBS` entries ``self_samples``, ``sample_falloff``,
        ``centroid_beyond``, ``self_term``, ``voxels_per_axis``, ``profile_samples``,
        ``mix_points``, ``finite_object_energy``, ``diffusion_voxels_per_axis``.
    log : StageLog, optional
        Receives what was skipped (voxel grids of convex objects) and the timings.
    sheet_thickness_mm : float, optional
        Thickness of the thin sheets (objects whose patches have twins, see
        :func:`~translucent.fast.form_factors.build_patches`): a Dipole on a sheet becomes
        the reflection and transmission of a slab this thick.

    Returns
    -------
    ScatteringGeometry
    """
    log = log if log is not None else StageLog()
    grid = RadialGrid(max_distance_mm, knobs["profile_samples"])
    mm = patches.mm_per_unit
    rows_all = [np.arange(len(patches))]
    cols_all = [np.arange(len(patches))]
    # every block of entries appended to the pattern: (object, kind, pairs, self) slices
    segments: dict = {}
    filled = [len(patches)]

    def append(rows, cols):
        rows_all.append(rows)
        cols_all.append(cols)
        filled.append(filled[-1] + len(rows))
        return filled[-2], filled[-1]

    sheets = []
    per_object = []
    for index in translucent:
        obj = scene.objects[index]
        started = time.perf_counter()
        members = patches.of_object(index)
        members = members[~patches.is_back[members]]
        twins = patches.twin[members]
        if (twins >= 0).any():
            sheets.append(index)
        centroids = patches.centroid[members] * mm
        radius = patches.radius[members] * mm
        mesh = obj.mesh
        facts = {"patches": int(len(members))}
        if is_convex(mesh.vertices, mesh.faces):
            voxels = None
            log.skip(f"no voxel grid for '{obj.name}': a convex object, the shortest path "
                     "inside is the straight line (Euclidean distance)")
        else:
            size = float(np.ptp(mesh.vertices, axis=0).max()) * mm
            voxels = voxelize(mesh.vertices[mesh.faces] * mm, size / knobs["voxels_per_axis"],
                              fill=closed_surface(mesh.faces, mesh.vertices))
            facts["voxels"] = int(voxels.nodes)
            facts["voxel_size_mm"] = float(voxels.voxel_size)
        tree = cKDTree(centroids)
        reach = max_distance_mm + float(radius.max())
        undirected = tree.query_pairs(reach, output_type="ndarray")
        exit_local = np.concatenate([undirected[:, 0], undirected[:, 1]])
        incident_local = np.concatenate([undirected[:, 1], undirected[:, 0]])
        if knobs["self_term"] == "samples":
            exit_local = np.concatenate([exit_local, np.arange(len(members))])
            incident_local = np.concatenate([incident_local, np.arange(len(members))])
        delta = np.linalg.norm(centroids[exit_local] - centroids[incident_local], axis=1)
        keep = delta <= max_distance_mm + radius[incident_local]
        exit_local, incident_local, delta = exit_local[keep], incident_local[keep], delta[keep]
        m = _samples_per_edge(delta, radius[incident_local], knobs)
        # one inside test per patch pair, shared by its samples (voxel resolution anyway)
        pair_inside = voxels.segment_inside(centroids[exit_local], centroids[incident_local]) \
            if voxels is not None else None
        pair_rows, pair_faces = patches.faces_of(members[incident_local])
        pair_m = m[pair_rows]
        sample_points, sample_pair, sample_weight = [], [], []
        for value in np.unique(pair_m):
            chosen = np.flatnonzero(pair_m == value)
            barycentric = subdivision_barycentrics(int(value))
            corners = patches.triangles[pair_faces[chosen]] * mm
            sample_points.append(np.einsum("sk,nkd->nsd", barycentric, corners).reshape(-1, 3))
            sample_pair.append(np.repeat(pair_rows[chosen], len(barycentric)))
            sample_weight.append(np.repeat(patches.triangle_area[pair_faces[chosen]] * mm * mm
                                           / value**2, len(barycentric)))
        sample_pair = np.concatenate(sample_pair) if sample_pair else np.zeros(0, np.int64)
        sample_weight = np.concatenate(sample_weight) if sample_weight else np.zeros(0)
        # one call for every sample: each exit voxel's Dijkstra search runs once, not once
        # per sample count
        sample_distance = optical_distances(
            voxels, centroids[exit_local[sample_pair]],
            np.concatenate(sample_points) if sample_points else np.zeros((0, 3)),
            max_distance_mm, inside=None if voxels is None else pair_inside[sample_pair])
        inside = np.isfinite(sample_distance)
        sample_pair, sample_weight = sample_pair[inside], sample_weight[inside]
        sample_distance = sample_distance[inside]
        k, f = grid.locate(sample_distance)
        f = f.astype(np.float64)
        operator = sparse.coo_matrix(
            (np.concatenate([sample_weight * (1.0 - f), sample_weight * f]),
             (np.concatenate([sample_pair, sample_pair]), np.concatenate([k, k + 1]))),
            shape=(len(exit_local), grid.samples)).tocsr()
        operator.sum_duplicates()
        self_cumulative = self_segment = None
        if knobs["self_term"] == "polar":
            rows, rho, weight = _polar_self_nodes(patches, members)
            self_cumulative, self_segment = _self_operators(grid, len(members), rows,
                                                            np.minimum(rho, max_distance_mm),
                                                            weight)
        samples = None
        if isinstance(obj.material, MixedProfiles):
            material = obj.material
            if len(material.face_labels) != len(mesh.faces):
                raise InputError(f"needs one label per face of '{obj.name}' "
                                 f"({len(mesh.faces)})", field="face_labels",
                                 value=len(material.face_labels))
            start = patches.face_offset[index]
            first_face = patches.patch_faces[patches.patch_face_start[members]] - start
            samples = {
                "pair": sample_pair, "weight": sample_weight, "distance": sample_distance,
                "fractions": _pair_fractions(centroids, mesh.face_centroids * mm,
                                             material.face_labels, exit_local, incident_local,
                                             len(material.profiles), knobs["mix_points"],
                                             material.volume_labels, mm),
                "mix_points": knobs["mix_points"],
                "patch_label": material.face_labels[first_face],
            }
        blocks = [("reflection", append(members[exit_local], members[incident_local]), None)]
        if index in sheets:
            # the same samples serve both faces: same side by reflection, across by
            # transmission (Sheng et al. 2014, Sect. 6.1, the petals)
            blocks.append(("reflection", append(twins[exit_local], twins[incident_local]),
                           "twin-twin"))
            blocks.append(("transmission", append(members[exit_local], twins[incident_local]),
                           append(members, twins)))
            blocks.append(("transmission", append(twins[exit_local], members[incident_local]),
                           append(twins, members)))
        segments[index] = blocks
        diffusion = None
        if knobs["finite_object_energy"] and index not in sheets:
            triangles = mesh.vertices[mesh.faces] * mm
            voxel = voxel_size_for(triangles, knobs["diffusion_voxels_per_axis"])
            try:
                diffusion = diffusion_grid(triangles, voxel)
                facts["diffusion_cells"] = int(diffusion.cells)
            except InputError:
                log.skip(f"no finite-object energy for '{obj.name}': no cell of the "
                         f"diffusion grid ({voxel:.3g} mm) lies inside it; raise "
                         "diffusion_voxels_per_axis")
        facts.update({"pairs": int(len(exit_local)), "samples": int(len(sample_pair)),
                      "seconds": time.perf_counter() - started})
        per_object.append((index, members, len(exit_local), operator, self_cumulative,
                           self_segment, samples, facts, diffusion))
        log.seconds[f"scattering '{obj.name}'"] = facts["seconds"]
        log.notes.setdefault("scattering", {})[obj.name] = facts
    rows = np.concatenate(rows_all)
    cols = np.concatenate(cols_all)
    order = np.lexsort((cols, rows))
    position = np.empty(len(order), dtype=np.int64)
    position[order] = np.arange(len(order))
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=len(patches)))])
    diagonal = position[:len(patches)]
    geometry_size = len(order)
    objects = {}
    for index, members, _, operator, self_c, self_s, samples, facts, diffusion in per_object:
        blocks = []
        for kind, (lo, hi), own in segments[index]:
            if own is None:
                own_position = diagonal[members]
            elif own == "twin-twin":
                own_position = diagonal[patches.twin[members]]
            else:
                own_position = position[own[0]:own[1]]
            blocks.append((kind, position[lo:hi], own_position))
        operators = [(kind, _at_positions(operator, pairs, geometry_size),
                      None if self_c is None else _at_positions(self_c, own, geometry_size),
                      None if self_s is None else _at_positions(self_s, own, geometry_size))
                     for kind, pairs, own in blocks]
        if samples is None:  # the local operators serve the heterogeneous mixing only
            operator = self_c = self_s = None
        objects[index] = ObjectScattering(index, members, blocks, operator, self_c, self_s,
                                          samples, facts, operators, diffusion)
    return ScatteringGeometry(indptr.astype(np.int64), cols[order].astype(np.int32), diagonal,
                              grid, objects, tuple(sheets), sheet_thickness_mm)


# ---------------------------------------------------------------------------------------
# the scattering matrix of a material


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
        _compiled_rgb_product()(self.indptr, self.indices, self.data,
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


def _object_profile_tables(profile: RadialProfile, grid: RadialGrid, kind: str = "reflection"):
    table = profile.tabulate(grid, kind)
    return table, radial_cumulative_integral(grid.radius, table)


def scattering_matrix(geometry: ScatteringGeometry, scene, patches: Patches,
                      materials: dict | None = None) -> ScatteringMatrix:
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
    grid = geometry.grid
    data = np.zeros((geometry.nnz, 3))
    for index, obj in enumerate(scene.objects):
        material = materials.get(obj.name, obj.material)
        profile = _sheet_profile(profile_for(material), index, geometry, obj.name)
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
            for kind, samples, cumulative_operator, segment_operator in item.operators:
                if kind not in tables:
                    tables[kind] = _object_profile_tables(profile, grid, kind)
                table, cumulative = tables[kind]
                data += samples @ table
                if cumulative_operator is not None:
                    data += cumulative_operator @ cumulative + segment_operator @ table
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
                tables[kind] = (_mixed_values(item, profile, grid, kind), own_values)
            pair_values, own_values = tables[kind]
            data[pair_position] += pair_values
            for label, values in enumerate(own_values):
                mine = labels == label
                data[own_position[mine]] += values[mine]
    return ScatteringMatrix(geometry.indptr, geometry.indices, data)


def _carry_finite_object_energy(data, geometry: ScatteringGeometry, patches: Patches,
                                item: ObjectScattering, profile: DipoleProfile) -> None:
    r"""Give the object's columns of S the re-emission of diffusion in its own shape.

    Column i (incident patch i) is brought to the power sum :math:`g_i\int s`: the
    profile's semi-infinite total (at most the entry transmittance times
    :func:`~translucent.fast.diffusion_escape.source_escape_probability`, so that no column
    exceeds what diffusion lets out of the object) times the gain of
    :func:`~translucent.fast.diffusion_escape.finite_object_gain` (1 in a large object,
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
    _compiled_energy_correction()(
        geometry.indptr, geometry.indices, data, in_object, np.ascontiguousarray(area),
        np.ascontiguousarray(patches.centroid * mm), np.ascontiguousarray(patches.normal),
        np.asarray(z_r, np.float64), np.asarray(dipole.sigma_tr, np.float64), target,
        applied)
    item.facts["finite_object_gain"] = {"min": gain.min(axis=0).tolist(),
                                        "mean": gain.mean(axis=0).tolist(),
                                        "max": gain.max(axis=0).tolist()}


@functools.cache
def _compiled_energy_correction():
    """Compile the two passes of :func:`_carry_finite_object_energy` over S's entries."""
    import numba

    @numba.njit(inline="always", fastmath=True)
    def fluence(centroid, normal, row, column, z_r, sigma_tr):  # pragma: no cover
        # the dipole's real source below the entry patch and its mirror image above it
        real = image = 0.0
        for d in range(3):
            offset = centroid[row, d] - centroid[column, d]
            real += (offset + z_r * normal[column, d]) ** 2
            image += (offset - z_r * normal[column, d]) ** 2
        real = max(math.sqrt(real), 1e-12)
        image = max(math.sqrt(image), 1e-12)
        return max(math.exp(-sigma_tr * real) / real - math.exp(-sigma_tr * image) / image, 0.0)

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def correct(indptr, indices, data, in_object, area, centroid, normal, z_r, sigma_tr,
                target, applied):  # pragma: no cover - compiled
        size = len(indptr) - 1
        # the weights A_j * fluence, once (in parallel: no entry shares its slot)
        weight = np.zeros((len(indices), 3), np.float32)
        for row in numba.prange(size):
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if in_object[column]:
                    for c in range(3):
                        if applied[c]:
                            weight[k, c] = area[row] * fluence(centroid, normal, row, column,
                                                               z_r[c], sigma_tr[c])
        current = np.zeros((size, 3))
        norm = np.zeros((size, 3))
        for row in range(size):  # serial: columns gather from every row
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if in_object[column]:
                    for c in range(3):
                        current[column, c] += area[row] * data[k, c]
                        norm[column, c] += weight[k, c]
        for column in range(size):
            for c in range(3):
                current[column, c] /= area[column]
        for row in numba.prange(size):
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if not in_object[column]:
                    continue
                for c in range(3):
                    if not applied[c]:
                        continue
                    missing = target[column, c] - current[column, c]
                    if missing > 0.0:
                        if norm[column, c] > 0.0:
                            data[k, c] += missing * area[column] * weight[k, c] \
                                / (area[row] * norm[column, c])
                    elif current[column, c] > 0.0:
                        data[k, c] *= target[column, c] / current[column, c]

    return correct


def _sheet_profile(profile, index: int, geometry: ScatteringGeometry, name: str):
    """Turn a Dipole's profile on a thin sheet into the slab's reflection and transmission."""
    if index not in geometry.sheets or not isinstance(profile, DipoleProfile):
        return profile
    if geometry.sheet_thickness_mm is None:
        raise InputError(f"object '{name}' is a thin (open) sheet: give the knob "
                         "sheet_thickness_mm, or a profile with transmission (SlabProfile, "
                         "a table or two-exponential form)", field="sheet_thickness_mm",
                         value=None)
    return SlabProfile(profile.dipole, geometry.sheet_thickness_mm,
                       entry_fresnel=profile.entry_fresnel)


#: Samples of Eq. 16 evaluated at once: the (samples x 3) values of a chunk stay near
#: 100 MB whatever the object (all pairs of a 4608-patch sphere: 23 M samples).
MIXED_CHUNK_VALUES = 4_000_000


@functools.lru_cache(maxsize=1)
def _compiled_mixed_profile():
    """Compile Eq. 16 per sample, visiting only the materials a path crosses.

    A path of ``mix_points`` points crosses at most that many of the M materials; the
    array form evaluated every material at every sample (M = 32 for a gradient: 30 of
    32 terms were the factor 1), which took half of a heterogeneous precomputation.
    """
    import numba

    @numba.njit(parallel=True, fastmath=False, cache=True)
    def mixed(distance, counts, pair, points, weight, zero, tables, max_radius,
              out):  # pragma: no cover - compiled
        samples_k = tables.shape[1]
        materials = tables.shape[0]
        for i in numba.prange(len(distance)):
            row = pair[i]
            mean0 = mean1 = mean2 = 0.0
            ratio0 = ratio1 = ratio2 = 1.0
            for m in range(materials):
                count = counts[row, m]
                if count == 0:
                    continue
                fraction = count / points
                mean0 += zero[m, 0] * fraction
                mean1 += zero[m, 1] * fraction
                mean2 += zero[m, 2] * fraction
                # RadialGrid.locate: nodes r_k = max_radius (k / (K - 1))^2
                r = min(max(fraction * distance[i], 0.0), max_radius)
                position = math.sqrt(r / max_radius) * (samples_k - 1)
                k = min(int(math.floor(position)), samples_k - 2)
                left = max_radius * (k / (samples_k - 1)) ** 2
                right = max_radius * ((k + 1) / (samples_k - 1)) ** 2
                f = min(max((r - left) / (right - left), 0.0), 1.0)
                for c in range(3):
                    value = tables[m, k, c] * (1.0 - f) + tables[m, k + 1, c] * f
                    ratio = value / zero[m, c] if zero[m, c] > 0 else 0.0
                    if c == 0:
                        ratio0 *= ratio
                    elif c == 1:
                        ratio1 *= ratio
                    else:
                        ratio2 *= ratio
            out[i, 0] = mean0 * ratio0 * weight[i]
            out[i, 1] = mean1 * ratio1 * weight[i]
            out[i, 2] = mean2 * ratio2 * weight[i]

    return mixed


def _mixed_values(item: ObjectScattering, profile: MixedProfiles, grid: RadialGrid,
                  kind: str = "reflection"):
    """Eq. 16 summed per patch pair over the pair's samples, shape (pairs, 3).

    Equal to :func:`~translucent.materials.profiles.mixed_profile` at every sample (a
    test compares the two), compiled because it runs on every sample of every pair.
    """
    samples = item.samples
    tables = np.ascontiguousarray(np.stack([p.tabulate(grid, kind) for p in profile.profiles]),
                                  dtype=np.float64)
    zero = np.ascontiguousarray(tables[:, 0])
    pairs = item.sample_operator.shape[0]  # kept for heterogeneous objects
    out = np.zeros((pairs, 3))
    counts = np.ascontiguousarray(samples["fractions"])
    mixed = _compiled_mixed_profile()
    values = np.empty((min(MIXED_CHUNK_VALUES, len(samples["distance"])), 3))
    for start in range(0, len(samples["distance"]), MIXED_CHUNK_VALUES):
        pair = np.ascontiguousarray(samples["pair"][start:start + MIXED_CHUNK_VALUES])
        chunk = values[:len(pair)]
        mixed(np.ascontiguousarray(samples["distance"][start:start + MIXED_CHUNK_VALUES],
                                   dtype=np.float64),
              counts, pair, float(samples["mix_points"]),
              np.ascontiguousarray(samples["weight"][start:start + MIXED_CHUNK_VALUES],
                                   dtype=np.float64),
              zero, tables, float(grid.max_radius), chunk)
        for c in range(3):
            out[:, c] += np.bincount(pair, chunk[:, c], minlength=pairs)
    return out


# ---------------------------------------------------------------------------------------
# convergence and solving


def form_factor_bounds(F, patches: Patches) -> dict:
    """Row sums and power-form column sums of F, the F half of the bound of Eq. 15."""
    if F is None or F.nnz == 0:
        return {"max_form_factor_row_sum": 0.0, "max_form_factor_power_column_sum": 0.0}
    power = (F.T @ patches.area) / patches.area
    return {"max_form_factor_row_sum": float(np.asarray(F.sum(axis=1)).max()),
            "max_form_factor_power_column_sum": float(power.max())}


def check_convergence(S: ScatteringMatrix, F, patches: Patches, *,
                      form_factor_facts: dict | None = None) -> dict:
    r"""Check the convergence condition of Sheng et al. 2014, Eq. 15, before solving.

    :math:`\|S\|_1 < 1` in power form: the energy leaving every patch through the material
    is less than what enters it. With :math:`\|F\| \le 1` (row sums of ray-cast form
    factors never exceed 1) the spectral radius of :math:`SF` is below
    :math:`\max_i\sum_j A_j S_{ji}/A_i \cdot \max_j \sum_k A_k F_{kj}/A_j`.

    Returns
    -------
    dict
        ``max_scattering_column_sum`` (and where: ``patch``, ``object``, ``channel``),
        ``max_form_factor_row_sum``, ``max_form_factor_power_column_sum``,
        ``spectral_radius_bound``.

    Raises
    ------
    InputError
        When a column sum of S reaches 1: the material returns more light than it
        receives and the series of Eq. 14 diverges. The message names the object, patch,
        channel and value.
    """
    sums = S.power_column_sums(patches.area)
    patch, channel = np.unravel_index(int(np.argmax(sums)), sums.shape)
    largest = float(sums[patch, channel])
    object_name = patches.object_names[patches.object_of[patch]]
    report = {"max_scattering_column_sum": largest, "patch": int(patch),
              "object": object_name, "channel": "RGB"[channel]}
    report.update(form_factor_facts if form_factor_facts is not None
                  else form_factor_bounds(F, patches))
    report["spectral_radius_bound"] = largest * report["max_form_factor_power_column_sum"]
    if not largest < 1.0:
        raise InputError(
            f"the scattering factors break the convergence condition of Eq. 15 (Sheng et al. "
            f"2014): patch {patch} of '{object_name}' sends {largest:.4f} of the light it "
            f"receives back out in channel {'RGB'[channel]} (must be < 1); the material "
            "reflects more energy than it receives -- check its profile (total reflectance "
            "< 1) and the cut-off max_d", field="material", value=largest)
    return report


#: Below this many form factors scipy's product is as fast as the compiled one.
COMPILED_PRODUCT_ENTRIES = 200_000


@functools.lru_cache(maxsize=1)
def _compiled_rgb_product():
    """Compile ``out = A @ x`` for x (P, 3): data (nnz,) shared by R, G, B (F) or (nnz, 3) (S).

    ``data.ndim`` is part of the array type: each layout compiles to its own tight loop (a
    single loop indexing (nnz, 1) data was measured 20-35 % slower on F).
    """
    import numba

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def product(indptr, indices, data, x, out):  # pragma: no cover - compiled
        for row in numba.prange(len(indptr) - 1):
            red = green = blue = 0.0
            for k in range(indptr[row], indptr[row + 1]):
                column = indices[k]
                if data.ndim == 2:
                    red += data[k, 0] * x[column, 0]
                    green += data[k, 1] * x[column, 1]
                    blue += data[k, 2] * x[column, 2]
                else:
                    value = data[k]
                    red += value * x[column, 0]
                    green += value * x[column, 1]
                    blue += value * x[column, 2]
            out[row, 0], out[row, 1], out[row, 2] = red, green, blue

    return product


def form_factor_product(F, B) -> np.ndarray:
    """``F @ B`` for the three channels of B (P, 3) in one pass over F.

    The product of every Jacobi iteration (Sheng et al. 2014, Sect. 5.3): a compiled,
    multi-threaded loop reads each form factor once for R, G and B; scipy's product
    casts the float32 matrix for a float64 right-hand side and is 1.5 to 3 times slower
    on large F (measured in the radiosity bench).
    """
    if F.nnz < COMPILED_PRODUCT_ENTRIES:
        return np.asarray(F @ B)
    out = np.empty((F.shape[0], 3))
    _compiled_rgb_product()(F.indptr, F.indices, F.data,
                            np.ascontiguousarray(B, np.float64), out)
    return out


def _relative_residual(S: ScatteringMatrix, F, B, source):
    """Relative residual per channel of B and the product F B it needed (None without F)."""
    global_irradiance = form_factor_product(F, B) if F is not None else None
    residual = source - B + S.dot(global_irradiance) if F is not None else source - B
    norm = np.linalg.norm(source, axis=0)
    return np.linalg.norm(residual, axis=0) / np.where(norm > 0, norm, 1.0), global_irradiance


def solve_radiosity(S: ScatteringMatrix, F, source, *, solver: str = "jacobi",
                    tolerance: float = 5e-3, max_iterations: int = 2000,
                    initial=None) -> tuple[np.ndarray, dict]:
    r"""Solve :math:`(I - SF)B = \text{source}` (Sheng et al. 2014, Eq. 14, Sect. 5.3).

    ``source`` is :math:`SE`, or any right-hand side (an emission L in the classical
    :math:`S = P` case, Eq. 2).

    Parameters
    ----------
    S : ScatteringMatrix
    F : scipy.sparse matrix or None
        Form factors (None: no inter-reflection, B = source).
    source : ndarray, shape (P, 3)
    solver : str
        ``"jacobi"`` (:math:`B \leftarrow \text{source} + SFB`), ``"gmres"`` or
        ``"bicgstab"``.
    tolerance : float
        Relative residual :math:`\|\text{source} - (I - SF)B\| / \|\text{source}\|` per
        channel (0.5 % in the paper).
    max_iterations : int
    initial : ndarray, shape (P, 3), optional
        Starting guess (default: the source, the first bounce). The stopping rule is the
        residual of the iterate, so a good guess saves iterations and changes nothing else.

    Returns
    -------
    B : ndarray, shape (P, 3)
    info : dict
        ``iterations`` (the largest over channels; matrix-vector products of SF for
        Krylov methods), ``residual`` (per channel, recomputed), ``solver``.

    Raises
    ------
    ConvergenceError
        When the residual does not reach ``tolerance`` in ``max_iterations``, becomes
        non-finite or grows by :data:`DIVERGENCE_FACTOR`, or when a non-negative source
        gives a negative radiosity (a Krylov solver converges to the solution of
        :math:`(I - SF)B = \text{source}` even where the series of Eq. 14 diverges,
        spectral radius of SF >= 1): no garbage is returned.
    """
    if solver not in SOLVERS:
        raise InputError(f"unknown solver; valid: {', '.join(SOLVERS)}", field="solver",
                         value=solver)
    source = np.asarray(source, dtype=np.float64)
    if F is None or F.nnz == 0:
        return source.copy(), {"iterations": 0, "residual": [0.0, 0.0, 0.0], "solver": solver}
    start = source if initial is None else np.asarray(initial, dtype=np.float64)
    if solver == "jacobi":
        B, iterations, residual, global_irradiance = _jacobi(S, F, source, tolerance,
                                                             max_iterations, start)
    else:
        B, iterations = _krylov(S, F, source, solver, tolerance, max_iterations, start)
        residual, global_irradiance = _relative_residual(S, F, B, source)
    if (source >= 0).all() and (B < -tolerance * np.abs(B).max(axis=0)).any():
        raise ConvergenceError(f"{solver} returned a negative radiosity for a non-negative source:"
                               " the series of Eq. 14 diverges (spectral radius of SF >= 1)",
                               residual=float(residual.max()), iterations=int(iterations))
    return B, {"iterations": int(iterations), "residual": residual.tolist(), "solver": solver,
               "global_irradiance": global_irradiance}


def _jacobi(S, F, source, tolerance, max_iterations, start):
    r"""Jacobi sweeps; return B, the products of SF, the residual and F B of that B.

    The sweep from :math:`B_k` computes :math:`B_{k+1} = \text{source} + SFB_k`, whose
    change :math:`B_{k+1} - B_k` is exactly the residual of :math:`B_k`: the iterate that
    passes the test is returned with its :math:`FB_k` (the image's inter-reflected
    irradiance), so no product is spent on checking or on the image.
    """
    B = start.copy()
    norm = np.linalg.norm(source, axis=0)
    norm = np.where(norm > 0, norm, 1.0)
    smallest = np.inf
    largest = np.inf
    for iteration in range(1, max_iterations + 1):
        global_irradiance = form_factor_product(F, B)
        updated = source + S.dot(global_irradiance)
        residual = np.linalg.norm(updated - B, axis=0) / norm
        largest = float(residual.max())
        if not np.isfinite(largest) or largest > DIVERGENCE_FACTOR * smallest:
            raise ConvergenceError(f"Jacobi iteration diverges: relative residual {largest:.3g}"
                                   f" after {iteration} iterations (smallest {smallest:.3g})",
                                   residual=largest, iterations=iteration)
        if largest <= tolerance:
            return B, iteration, residual, global_irradiance
        smallest = min(smallest, largest)
        B = updated
    raise ConvergenceError(f"Jacobi iteration reached a relative residual of {largest:.3g}"
                           f" after {max_iterations} iterations, above the tolerance "
                           f"{tolerance:g}: the spectral radius of SF is close to 1 (albedo near "
                           "1); raise max_iterations or use solver='gmres'",
                           residual=largest, iterations=max_iterations)


def _krylov(S, F, source, solver, tolerance, max_iterations, start):
    size = len(source)
    B = np.zeros_like(source)
    most = 0
    method = sparse_linalg.gmres if solver == "gmres" else sparse_linalg.bicgstab
    for c in range(3):
        S_c = S.channel(c)
        products = [0]

        def matvec(x, S_c=S_c, products=products):
            products[0] += 1
            return x - S_c @ (F @ x)

        operator = sparse_linalg.LinearOperator((size, size), matvec=matvec, dtype=np.float64)
        if not np.any(source[:, c]):
            continue
        solution, status = method(operator, source[:, c], x0=start[:, c].copy(),
                                  rtol=tolerance, atol=0.0, maxiter=max_iterations)
        if status != 0 or not np.all(np.isfinite(solution)):
            residual = float(np.linalg.norm(source[:, c] - matvec(solution))
                             / np.linalg.norm(source[:, c]))
            raise ConvergenceError(f"{solver} stopped with status {status} in channel "
                                   f"{'RGB'[c]} at relative residual {residual:.3g}",
                                   residual=residual, iterations=products[0])
        B[:, c] = solution
        most = max(most, products[0])
    return B, most


def transfer_matrix(S: ScatteringMatrix, F) -> list[np.ndarray]:
    r"""Compute the relighting operator :math:`T = (I - SF)^{-1}S` per channel (float32).

    Sheng et al. 2014, Sect. 6.4: with T, relighting is :math:`B = TE`, one matrix-vector
    product per channel. Costs :math:`O(P^3)` time and :math:`3P^2` floats.
    """
    size = len(S.indptr) - 1
    dense_F = F.toarray().astype(np.float64) if F is not None else np.zeros((size, size))
    out = []
    for c in range(3):
        S_c = S.channel(c).toarray()
        system = np.eye(size) - S_c @ dense_F
        out.append(np.linalg.solve(system, S_c).astype(np.float32))
    return out


# ---------------------------------------------------------------------------------------
# direct lighting


def _environment_radiance(light, directions) -> np.ndarray:
    """Radiance arriving from ``directions`` (pointing away from the scene), (N, 3)."""
    if isinstance(light, ConstantEnvironment):
        return np.broadcast_to(light.radiance, directions.shape).copy()
    # Mitsuba's envmap: u = atan2(x, -z) / 2pi, v = acos(y) / pi, pixel centres
    height, width = light.radiance.shape[:2]
    u = (np.arctan2(directions[:, 0], -directions[:, 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(directions[:, 1], -1.0, 1.0)) / np.pi
    col = np.clip((u * width).astype(int), 0, width - 1)
    row = np.clip((v * height).astype(int), 0, height - 1)
    return light.radiance[row, col].astype(np.float64) * light.scale


def _cosine_directions(normals, count, rng):
    from .form_factors import stratified_cosine_directions

    return stratified_cosine_directions(normals, count, rng)


def direct_irradiance(scene, points, normals, *, lights=None, samples: int = 16,
                      seed: int = 0, visible=None, trace=None) -> np.ndarray:
    """Irradiance from the lights at surface points, with shadows (W m^-2 in scene units).

    The :math:`E` of Sheng et al. 2014, Eq. 7 (per patch) and of the per-pixel direct
    lighting of diffuse surfaces (Sect. 6.1, the hybrid of [36], [37]). Point, spot
    (Mitsuba's linear angular falloff) and directional lights are exact; rectangular and
    spherical area lights and environments are integrated with ``samples`` stratified
    samples per point.

    Parameters
    ----------
    scene : Scene
    points, normals : ndarray, shape (N, 3)
        Scene units; unit normals on the lit side.
    lights : sequence, optional
        Default ``scene.lights``.
    samples : int
    seed : int
    visible, trace : callable, optional
        Ray queries (default :mod:`translucent.scenes.raycast`).

    Returns
    -------
    ndarray, shape (N, 3)
    """
    if visible is None or trace is None:
        from ..scenes import raycast

        visible = visible or raycast.visible
        trace = trace or raycast.trace
    lights = scene.lights if lights is None else tuple(lights)
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    rng = np.random.default_rng(seed)
    total = np.zeros((len(points), 3))
    if len(points) == 0:
        return total
    for light in lights:
        if isinstance(light, (PointLight, SpotLight)):
            to_light = light.position - points
            distance2 = np.einsum("ij,ij->i", to_light, to_light)
            direction = to_light / np.sqrt(distance2)[:, None]
            cosine = np.clip(np.einsum("ij,ij->i", normals, direction), 0.0, None)
            strength = cosine / distance2
            if isinstance(light, SpotLight):
                strength = strength * light.falloff(-direction)
            lit = strength > 0
            if lit.any():
                seen = visible(scene, points[lit], light.position, normals_a=normals[lit])
                strength[np.flatnonzero(lit)[~seen]] = 0.0
            total += strength[:, None] * light.intensity
        elif isinstance(light, DirectionalLight):
            cosine = np.clip(normals @ -light.direction, 0.0, None)
            lit = cosine > 0
            if lit.any():
                hits = trace(scene, points[lit] + 1e-5 * normals[lit], -light.direction)
                cosine[np.flatnonzero(lit)[hits.hit]] = 0.0
            total += cosine[:, None] * light.irradiance
        elif isinstance(light, RectangularAreaLight):
            total += _area_light_irradiance(scene, light, points, normals, samples, rng, visible)
        elif isinstance(light, SphereAreaLight):
            total += _sphere_light_irradiance(scene, light, points, normals, samples, rng,
                                              trace)
        elif isinstance(light, (ConstantEnvironment, ImageEnvironment)):
            directions = _cosine_directions(normals, samples, rng)
            flat = directions.reshape(-1, 3)
            origins = np.repeat(points + 1e-5 * normals, samples, axis=0)
            hits = trace(scene, origins, flat)
            radiance = _environment_radiance(light, flat) * (~hits.hit)[:, None]
            total += np.pi * radiance.reshape(len(points), samples, 3).mean(axis=1)
        else:
            raise InputError("translucent radiosity cannot light with this light type",
                             field="lights", value=type(light).__name__)
    return total


def _area_light_positions(light, samples, rng) -> np.ndarray:
    """Stratified sample positions on a rectangular light, (samples, 3) scene units."""
    side = int(np.ceil(np.sqrt(samples)))
    cells = np.arange(side * side)[:samples]
    u = (cells % side + rng.random(samples)) / side * 2.0 - 1.0
    v = (cells // side + rng.random(samples)) / side * 2.0 - 1.0
    return light.center + u[:, None] * light.u_axis + v[:, None] * light.v_axis


def _area_light_irradiance(scene, light, points, normals, samples, rng, visible):
    """Stratified samples on the rectangle, one visibility query per sample position.

    One query for all samples at once was measured no faster on 25,080 patches x 16
    samples (0.51-0.95 s against 0.47-0.51 s, the same run): its temporaries outweigh the
    per-call cost of the ray engine. Relighting takes :class:`AreaLightShadows` instead.
    """
    positions = _area_light_positions(light, samples, rng)
    result = np.zeros((len(points), 3))
    for position in positions:
        to_light = position - points
        distance2 = np.einsum("ij,ij->i", to_light, to_light)
        direction = to_light / np.sqrt(distance2)[:, None]
        cos_point = np.clip(np.einsum("ij,ij->i", normals, direction), 0.0, None)
        cos_light = np.clip(-(direction @ light.normal), 0.0, None)
        strength = cos_point * cos_light / distance2
        lit = strength > 0
        if lit.any():
            seen = visible(scene, points[lit], position, normals_a=normals[lit])
            strength[np.flatnonzero(lit)[~seen]] = 0.0
        result += strength[:, None]
    return result * light.radiance * light.area / len(positions)


@functools.lru_cache(maxsize=1)
def _compiled_shadow_rays():
    """Compile the per-frame loops of :class:`AreaLightShadows` (geometry and rays)."""
    import numba

    @numba.njit(parallel=True, cache=True)
    def strengths(points, normals, positions, light_normal, out):  # pragma: no cover
        # the expressions and their order are those of _area_light_irradiance
        for i in numba.prange(len(points)):
            for s in range(len(positions)):
                x = positions[s, 0] - points[i, 0]
                y = positions[s, 1] - points[i, 1]
                z = positions[s, 2] - points[i, 2]
                distance2 = x * x + y * y + z * z
                length = math.sqrt(distance2)
                x, y, z = x / length, y / length, z / length
                cos_point = max(normals[i, 0] * x + normals[i, 1] * y + normals[i, 2] * z, 0.0)
                cos_light = max(-(x * light_normal[0] + y * light_normal[1]
                                  + z * light_normal[2]), 0.0)
                out[i, s] = cos_point * cos_light / distance2

    @numba.njit(parallel=True, cache=True)
    def rays(starts, positions, lit, count, offset,  # pragma: no cover - compiled
             origins, directions, tmax, close):
        # the segment of visible() with normals_a given, written in the engine's float32
        for k in numba.prange(len(lit)):
            i, s = lit[k] // count, lit[k] % count
            x = positions[s, 0] - starts[i, 0]
            y = positions[s, 1] - starts[i, 1]
            z = positions[s, 2] - starts[i, 2]
            length = math.sqrt(x * x + y * y + z * z)
            for d in range(3):
                origins[k, d] = starts[i, d]
            close[k] = length <= 2.0 * offset
            if close[k]:
                # close enough to count as visible (no ray)
                directions[k, 0], directions[k, 1], directions[k, 2] = 0.0, 0.0, 1.0
                tmax[k] = 0.0
            else:
                directions[k, 0], directions[k, 1] = x / length, y / length
                directions[k, 2] = z / length
                tmax[k] = max(length - offset, 0.0)

    return strengths, rays


class AreaLightShadows:
    """Surface points lit by rectangular area lights every frame: shadow rays without overhead.

    The per-frame part of :func:`direct_irradiance` (Sheng et al. 2014, Eq. 7, and the
    per-pixel direct light of Sect. 6.1) for points that stay put while the lights move:
    the offset ray origins of :func:`translucent.scenes.raycast.visible` are computed once,
    the cosines and the rays of all samples in two compiled loops, and every shadow ray of
    a light in one call of the ray engine. Same samples, same rays, same result as
    :func:`direct_irradiance` (up to float rounding).

    Parameters
    ----------
    scene : Scene
    points, normals : ndarray, (N, 3)
        Scene units; normals of unit length on the lit side.
    engine : {"auto", "embree", "mitsuba"}, optional
        Ray engine of the shadow rays (knob ``shadow_ray_engine``); default: the scene's.
    """

    def __init__(self, scene, points, normals, engine=None):
        from ..scenes.raycast import OFFSET_FRACTION, ray_engine

        self.scene = scene
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.engine = ray_engine(scene, engine)
        # the offset of visible(): the bounding box, hence the diagonal, is every engine's
        self.offset = self.engine.diagonal * OFFSET_FRACTION
        # a lit point faces the light: visible() moves it along +normal
        length = np.linalg.norm(self.normals, axis=-1)
        self.starts = self.points + (self.offset / np.where(length > 0, length, 1.0))[:, None] \
            * self.normals

    @staticmethod
    def handles(lights) -> bool:
        """Return True when every light is a rectangular area light (else: the general path)."""
        return all(isinstance(light, RectangularAreaLight) for light in lights)

    def irradiance(self, lights, samples: int, seed: int) -> np.ndarray:
        """Irradiance at the points, (N, 3): :func:`direct_irradiance` for the same arguments."""
        strengths, rays = _compiled_shadow_rays()
        rng = np.random.default_rng(seed)
        total = np.zeros((len(self.points), 3))
        strength = np.empty((len(self.points), samples))
        for light in lights:
            positions = _area_light_positions(light, samples, rng)
            strengths(self.points, self.normals, positions,
                      np.asarray(light.normal, dtype=np.float64), strength)
            lit = np.flatnonzero(strength.ravel() > 0)
            origins = np.empty((len(lit), 3), dtype=np.float32)
            directions = np.empty((len(lit), 3), dtype=np.float32)
            tmax = np.empty(len(lit), dtype=np.float32)
            close = np.empty(len(lit), dtype=np.bool_)
            rays(self.starts, positions, lit, samples, self.offset, origins, directions, tmax,
                 close)
            blocked = self.engine.occluded_unit(origins, directions, tmax)
            strength.ravel()[lit[blocked & ~close]] = 0.0
            total += strength.sum(axis=1)[:, None] * (light.radiance * light.area / samples)
        return total


def _sphere_light_irradiance(scene, light, points, normals, samples, rng, trace):
    """Cone sampling of the sphere's solid angle: E = (2 pi (1 - cos a) / N) sum L cos V."""
    to_center = light.center - points
    distance = np.linalg.norm(to_center, axis=1)
    axis = to_center / distance[:, None]
    sin_max = np.clip(light.radius / distance, 0.0, 1.0)
    cos_max = np.sqrt(1.0 - sin_max**2)
    result = np.zeros(len(points))
    helper = np.where(np.abs(axis[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    tangent = np.cross(helper, axis)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(axis, tangent)
    for _ in range(samples):
        cos_theta = 1.0 - rng.random(len(points)) * (1.0 - cos_max)
        sin_theta = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, None))
        phi = 2 * np.pi * rng.random(len(points))
        direction = (cos_theta[:, None] * axis + (sin_theta * np.cos(phi))[:, None] * tangent
                     + (sin_theta * np.sin(phi))[:, None] * bitangent)
        cosine = np.clip(np.einsum("ij,ij->i", normals, direction), 0.0, None)
        lit = cosine > 0
        if lit.any():
            reach = distance[lit] - light.radius
            hits = trace(scene, points[lit] + 1e-5 * normals[lit], direction[lit],
                         np.maximum(reach, 0.0))
            cosine[np.flatnonzero(lit)[hits.hit]] = 0.0
        result += cosine
    solid_angle = 2 * np.pi * (1.0 - cos_max)
    return (solid_angle * result / samples)[:, None] * light.radiance


def _emitters_seen(scene, gbuffer) -> np.ndarray:
    """Radiance of area lights and environments seen directly by the camera, (H, W, 3)."""
    image = np.zeros(gbuffer.shape + (3,))
    directions = -gbuffer.view_direction
    origin = scene.camera.origin
    depth = np.where(gbuffer.hit, gbuffer.depth, np.inf)
    for light in scene.lights:
        if isinstance(light, RectangularAreaLight):
            denominator = directions @ light.normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((light.center - origin) @ light.normal) / denominator
            point = origin + t[..., None] * directions
            u = (point - light.center) @ light.u_axis / (light.u_axis @ light.u_axis)
            v = (point - light.center) @ light.v_axis / (light.v_axis @ light.v_axis)
            seen = (denominator < 0) & (t > 0) & (t < depth) & (np.abs(u) <= 1) & (np.abs(v) <= 1)
            image[seen] = light.radiance
        elif isinstance(light, SphereAreaLight):
            relative = origin - light.center
            b = directions @ relative
            c = relative @ relative - light.radius**2
            disc = b * b - c
            t = -b - np.sqrt(np.clip(disc, 0.0, None))
            seen = (disc > 0) & (t > 0) & (t < depth)
            image[seen] = light.radiance
        elif isinstance(light, (ConstantEnvironment, ImageEnvironment)):
            background = ~gbuffer.hit
            image[background] += _environment_radiance(light, directions[background])
    return image


# ---------------------------------------------------------------------------------------
# the precomputed state


def _materials_of(scene, material) -> dict:
    """Material overrides by object name: one material for every translucent object, or a dict."""
    if material is None:
        return {}
    if isinstance(material, dict):
        overrides = dict(material)
        for name in material:
            scene.object(name)
    else:
        overrides = {o.name: material for o in scene.objects
                     if profile_for(o.material) is not None}
    # a solid medium is read at this object's faces (solid_inputs)
    return {name: mixed_profiles_from_solid(value, scene.object(name).mesh).material
            if isinstance(value, SolidMedium) else value for name, value in overrides.items()}


class RadiosityState:
    """The result of :func:`precompute`: relights and changes translucency interactively.

    Attributes
    ----------
    scene : Scene
    patches : Patches
    form_factors : scipy.sparse.csr_matrix or None
        None when no patch sees another.
    geometry : ScatteringGeometry
    knobs : dict
    log : StageLog
    S : ScatteringMatrix
        For the current materials.
    transfer : list of ndarray or None
        :math:`T = (I - SF)^{-1}S` per channel when it fits ``transfer_budget_mb``.
    convergence : dict
        The report of :func:`check_convergence` for the current materials.
    """

    def __init__(self, scene, patches, F, geometry, knobs, log):
        self.scene = scene
        self.patches = patches
        self.form_factors = F
        self.geometry = geometry
        self.knobs = knobs
        self.log = log
        self.materials: dict = {}
        self.transfer = None
        # the patch centroids, nudged off the surface, and the patch rows per light-sample
        # group: fixed by the geometry, so every frame's patch_irradiance reuses them
        self._patch_points = patches.centroid + 1e-6 * patches.radius[:, None] * patches.normal
        translucent = np.isin(patches.object_of, list(geometry.objects))
        self._translucent_rows = np.flatnonzero(translucent)
        self._diffuse_rows = np.flatnonzero(~translucent)
        self._solved = None                 # (B, F B) of the last solve, for image()
        # the F half of the bound of Eq. 15 does not change with the materials
        self._form_factor_facts = form_factor_bounds(F, patches)
        self._shadow_points: dict = {}      # AreaLightShadows per point set and engine
        self._interreflected = None         # S F B of the last solve (warm start)
        self._cached_gbuffer = None
        self._cached_image_operators = None
        self.set_material(None)

    # -- materials ---------------------------------------------------------------------

    def set_material(self, material) -> float:
        """Rebuild S for new materials; return the seconds it took.

        ``material``: one material for every translucent object, or a dict by object name.
        This is the translucency-change step of Sheng et al. 2014, Sect. 5.2.
        """
        started = time.perf_counter()
        overrides = _materials_of(self.scene, material)
        self.materials = {**self.materials, **overrides}
        self.S = scattering_matrix(self.geometry, self.scene, self.patches, self.materials)
        self.convergence = check_convergence(self.S, self.form_factors, self.patches,
                                             form_factor_facts=self._form_factor_facts)
        self._energy_beyond_cutoff()
        self.transfer = None
        self._transfer_materials = None
        self._frames = []  # (E, B - SE) of earlier frames: stale once S changes
        return time.perf_counter() - started

    def _energy_beyond_cutoff(self):
        max_d = self.geometry.grid.max_radius
        lost = {}
        for index in self.geometry.objects:
            obj = self.scene.objects[index]
            profile = profile_for(self.materials.get(obj.name, obj.material))
            profiles = profile.profiles if isinstance(profile, MixedProfiles) else (profile,)
            for item in profiles:
                total = item.total()
                inside = item.total(max_radius=max_d)
                fraction = float(np.max(1.0 - inside / np.where(total > 0, total, 1.0)))
                lost[obj.name] = max(lost.get(obj.name, 0.0), fraction)
        self.log.notes["energy_beyond_max_d"] = lost
        worst = max(lost.values(), default=0.0)
        if worst > 10 * self.knobs["profile_energy_cutoff"]:
            warnings.warn(f"the profile keeps {worst:.1%} of its energy beyond max_d = "
                          f"{max_d:g} mm; precompute with a larger max_distance_mm",
                          stacklevel=3)

    def _scene_with_materials(self):
        scene = self.scene
        for name, material in self.materials.items():
            scene = scene.with_material(name, material)
        return scene

    # -- solving -----------------------------------------------------------------------

    def transfer_fits(self) -> bool:
        """Return True when 3 P^2 float32 numbers fit ``transfer_budget_mb`` (the rule for T).

        Memory decides, since T's cost is its size: 12 P^2 bytes read per frame and an
        O(P^3) solve that holds about five P x P float64 arrays at once. Where it fits it
        is measured as fast as the warm-started iterative solve, not faster (the module
        docstring has the numbers); set ``transfer="never"`` to skip its precomputation.
        """
        size = len(self.patches)
        return 3 * size * size * 4 <= self.knobs["transfer_budget_mb"] * 2**20

    def precompute_transfer(self) -> float | None:
        """Compute T for the current materials when it fits; returns seconds (None: skipped)."""
        if not self.transfer_fits():
            sentence = (f"no precomputed T: 3 x {len(self.patches)}^2 float32 = "
                        f"{3 * len(self.patches) ** 2 * 4 / 2**20:.0f} MB exceeds "
                        f"transfer_budget_mb = {self.knobs['transfer_budget_mb']}; relighting "
                        "iterates instead")
            if sentence not in self.log.skipped:
                self.log.skip(sentence)
            return None
        started = time.perf_counter()
        self.transfer = transfer_matrix(self.S, self.form_factors)
        return time.perf_counter() - started

    def patch_irradiance(self, lights=None) -> np.ndarray:
        """Direct irradiance E of every patch (at its centroid), shape (P, 3).

        Translucent patches take ``light_samples`` per area light; diffuse ones take
        ``diffuse_light_samples`` when it is set: their E reaches the image only through the
        form factors, which average it over everything a pixel's surface sees (the image's
        own direct light is per pixel), so fewer shadow rays cost little there. Measured
        against the index-matched Mitsuba references at 96 x 96 (the slow tests): 4 rays
        instead of 16 move the Cornell box from relative MSE 0.00775 / HDR-FLIP 0.160 to
        0.00795 / 0.169 (the bowl: 0.0236 / 0.267 either way) and cut the 25,080-patch
        irradiance from 0.029 to 0.012 s; it stays off by default.

        Rectangular area lights go through :class:`AreaLightShadows` (set up once per point
        set), other lights through :func:`direct_irradiance`; the two agree to round-off.
        """
        p = self.patches
        samples = self.knobs["light_samples"]
        diffuse_samples = self.knobs.get("diffuse_light_samples")
        groups = [("all", slice(None), samples)]
        if diffuse_samples is not None and diffuse_samples != samples:
            groups = [("translucent", self._translucent_rows, samples),
                      ("diffuse", self._diffuse_rows, diffuse_samples)]
        lights = self.scene.lights if lights is None else tuple(lights)
        E = np.zeros((len(p), 3))
        for name, rows, count in groups:
            E[rows] = self._direct_irradiance(("patches", name), self._patch_points[rows],
                                              p.normal[rows], lights, count, self.knobs["seed"])
        return E

    def _direct_irradiance(self, key, points, normals, lights, samples, seed) -> np.ndarray:
        """:func:`direct_irradiance` at a fixed point set, named by ``key``.

        Rectangular area lights go through the point set's :class:`AreaLightShadows`, built
        once per key and ray engine; other lights through :func:`direct_irradiance`.
        """
        if not AreaLightShadows.handles(lights):
            return direct_irradiance(self.scene, points, normals, lights=lights,
                                     samples=samples, seed=seed)
        key = key + (self.knobs["shadow_ray_engine"],)
        if key not in self._shadow_points:
            self._shadow_points[key] = AreaLightShadows(self.scene, points, normals,
                                                        self.knobs["shadow_ray_engine"])
        return self._shadow_points[key].irradiance(lights, samples, seed)

    def solve(self, irradiance, component: str = "both") -> tuple[np.ndarray, dict]:
        """Radiosity B (P, 3) for patch irradiance E, for one bounce component (Fig. 6)."""
        if component not in COMPONENTS:
            raise InputError(f"unknown component; valid: {', '.join(COMPONENTS)}",
                             field="component", value=component)
        if component in ("direct", "interreflection"):
            local = self.S.power_column_sums(self.patches.area)
            diagonal = ScatteringMatrix(np.arange(len(local) + 1), np.arange(len(local)),
                                        local)
            source = local * irradiance
            if component == "direct":
                return source, {"iterations": 0, "solver": "none"}
            return self._solve(diagonal, source)
        source = self.S.dot(irradiance)
        if component == "subsurface":
            return source, {"iterations": 0, "solver": "none"}
        if self.transfer is not None:
            B = np.stack([self.transfer[c] @ irradiance[:, c].astype(np.float32)
                          for c in range(3)], axis=1).astype(np.float64)
            return B, {"iterations": 0, "solver": "transfer"}
        initial = self._warm_start(irradiance, source) if self.knobs["warm_start"] else None
        B, info = self._solve(self.S, source, initial)
        self._interreflected = B - source
        self._frames = (self._frames + [(np.array(irradiance, dtype=np.float64), B - source)])[
            -WARM_START_FRAMES:]
        info["warm_start"] = initial is not None
        return B, info

    def forget_frames(self) -> None:
        """Drop the earlier frames that warm-start the next solve (a cold start follows)."""
        self._frames = []
        self._interreflected = None

    def _warm_start(self, irradiance, source):
        r"""Return the starting guess from earlier frames (None: the first frame).

        Relighting: B is linear in E, so the new E is projected on the last frames'
        irradiances, :math:`E \approx \sum_k \alpha_k E_k` (least squares per channel), and
        the guess is :math:`\sum_k \alpha_k B_k + S(E - \sum_k \alpha_k E_k)` (the projection
        of earlier solutions of Fischer 1998, Comput. Methods Appl. Mech. Engrg. 163). After a
        translucency change (S new, E the same) the last inter-reflected part
        :math:`SFB` is added to the new :math:`SE`. The residual test decides either way.
        """
        if self._frames:
            guess = np.array(source, dtype=np.float64)
            for c in range(3):
                irradiances = np.stack([E[:, c] for E, _ in self._frames])   # (k, P)
                # least squares through the k x k normal equations (matrix products): the
                # SVD of lstsq on (P, k) and einsum cost more than the rest of the frame
                weights = np.linalg.lstsq(irradiances @ irradiances.T,
                                          irradiances @ irradiance[:, c], rcond=None)[0]
                # sum_k a_k B_k + S(E - sum_k a_k E_k) = SE + sum_k a_k (B_k - S E_k): the
                # frames keep their inter-reflected parts, so the guess needs no product of S
                guess[:, c] += weights @ np.stack([part[:, c] for _, part in self._frames])
            return guess
        return None if self._interreflected is None else source + self._interreflected

    def _solve(self, S, source, initial=None):
        """Solve with the knobs; keep F B of the result for :meth:`image`."""
        B, info = solve_radiosity(S, self.form_factors, source, solver=self.knobs["solver"],
                                  tolerance=self.knobs["tolerance"],
                                  max_iterations=self.knobs["max_iterations"], initial=initial)
        global_irradiance = info.pop("global_irradiance", None)
        self._solved = (B, global_irradiance) if global_irradiance is not None else None
        return B, info

    # -- images ------------------------------------------------------------------------

    def _gbuffer(self):
        if self._cached_gbuffer is None:
            from ..scenes.raycast import gbuffer

            self._cached_gbuffer = gbuffer(self.scene)
        return self._cached_gbuffer

    def _image_operators(self, scene) -> dict:
        """Per-camera linear maps from patch values to pixels, built once (:meth:`image`).

        The vertex averages of :meth:`Patches.vertex_values` followed by the barycentric
        interpolation of the G-buffer are linear in the patch values: their product is one
        sparse (pixels x patches) matrix per kind of surface, so a frame's image costs two
        sparse products instead of an average and an interpolation per object.
        """
        lambertian = tuple(obj.material if isinstance(obj.material, Lambertian) else None
                           for obj in scene.objects)
        cached = self._cached_image_operators
        if cached is not None and cached["lambertian"] == lambertian:
            return cached
        gb = self._gbuffer()
        object_id = gb.object_id.reshape(-1)
        behind = np.einsum("hwd,hwd->hw", gb.geometric_normal, gb.view_direction).reshape(-1) < 0
        diffuse, diffuse_weights, translucent, translucent_weights = [], [], [], []
        for index, obj in enumerate(scene.objects):
            pixels = np.flatnonzero(object_id == index)
            if not len(pixels):
                continue
            if lambertian[index] is not None:
                diffuse.append(pixels)
                diffuse_weights.append(self._pixel_weights(gb, index, obj.mesh, pixels))
                continue
            if index in self.geometry.sheets:
                # a two-sided sheet shows the face turned towards the camera
                pixels = np.concatenate([pixels[~behind[pixels]], pixels[behind[pixels]]])
                weights = sparse.vstack([
                    self._pixel_weights(gb, index, obj.mesh, pixels[~behind[pixels]]),
                    self._pixel_weights(gb, index, obj.mesh, pixels[behind[pixels]],
                                        back=True)])
            else:
                weights = self._pixel_weights(gb, index, obj.mesh, pixels)
            translucent.append(pixels)
            translucent_weights.append(weights)
        size = len(self.patches)

        def stacked(blocks):
            return sparse.vstack(blocks).tocsr() if blocks else sparse.csr_matrix((0, size))

        diffuse = np.concatenate(diffuse) if diffuse else np.zeros(0, dtype=np.int64)
        albedo = np.zeros((len(diffuse), 3))
        for index, material in enumerate(lambertian):
            if material is not None:
                albedo[object_id[diffuse] == index] = material.albedo
        points = gb.position.reshape(-1, 3)[diffuse]
        normals = gb.geometric_normal.reshape(-1, 3)[diffuse]
        facing = np.sign(np.einsum("ij,ij->i", normals,
                                   gb.view_direction.reshape(-1, 3)[diffuse]))
        shading = gb.normal.reshape(-1, 3)[diffuse] * np.where(facing == 0, 1.0, facing)[:, None]
        self._cached_image_operators = {
            "lambertian": lambertian, "diffuse": diffuse, "diffuse_weights":
            stacked(diffuse_weights), "translucent": np.concatenate(translucent) if translucent
            else np.zeros(0, dtype=np.int64), "translucent_weights": stacked(translucent_weights),
            "albedo_over_pi": albedo / np.pi, "points": points + 1e-6 * normals * facing[:, None],
            "shading": shading}
        return self._cached_image_operators

    def _pixel_weights(self, gb, index, mesh, pixels, back=False) -> sparse.csr_matrix:
        """(pixels x patches) weights: area-weighted vertex averages, then barycentrics."""
        to_vertices = self.patches.vertex_average(index, mesh, back=back)
        triangles = gb.triangle_id.reshape(-1)[pixels]
        to_pixels = sparse.csr_matrix(
            (gb.barycentrics.reshape(-1, 3)[pixels].ravel(),
             (np.repeat(np.arange(len(pixels)), 3), np.asarray(mesh.faces)[triangles].ravel())),
            shape=(len(pixels), len(mesh.vertices)))
        return (to_pixels @ to_vertices).tocsr()

    def image(self, B, lights=None, component: str = "both") -> np.ndarray:
        r"""Compose the image (H, W, 3) from the patch radiosity B.

        Diffuse surfaces: :math:`\rho/\pi (E_{direct} + FB)` with the direct part per pixel;
        translucent surfaces: :math:`B/\pi` interpolated from the vertices (both through
        the per-camera weights of :meth:`_image_operators`).
        """
        gb = self._gbuffer()
        scene = self._scene_with_materials()
        operators = self._image_operators(scene)
        lights = scene.lights if lights is None else tuple(lights)
        rgb = np.zeros((gb.shape[0] * gb.shape[1], 3))
        if self.form_factors is None or component not in ("interreflection", "both"):
            global_irradiance = np.zeros_like(B)
        elif self._solved is not None and self._solved[0] is B:
            # the solver's last product: F B of exactly this B
            global_irradiance = self._solved[1]
        else:
            global_irradiance = form_factor_product(self.form_factors, B)
        diffuse = operators["diffuse"]
        rgb[operators["translucent"]] = operators["translucent_weights"] @ B / np.pi
        if len(diffuse):
            direct = self._direct_irradiance(("pixels",), operators["points"],
                                             operators["shading"], lights,
                                             self.knobs["light_samples"], self.knobs["seed"] + 1)
            rgb[diffuse] = operators["albedo_over_pi"] * (
                operators["diffuse_weights"] @ global_irradiance + direct)
        rgb = rgb.reshape(gb.shape + (3,))
        rgb += _emitters_seen(scene.with_lights(lights), gb)
        return rgb

    def render(self, lights=None, material=None, component: str = "both") -> Image:
        """Render with new lights and/or material (None keeps the current ones).

        A new material rebuilds S (the translucency change of Sect. 5.2) and drops T; new
        lights recompute E and solve, or multiply by T (Sect. 6.4). With the knob
        ``transfer="auto"`` the first relighting after a material change computes T when
        it fits ``transfer_budget_mb`` (:meth:`transfer_fits`); translucency changes
        always iterate, since T would have to be inverted again.
        """
        started = time.perf_counter()
        facts = {}
        if material is not None:
            facts["material_seconds"] = self.set_material(material)
        if lights is not None and self.transfer is None and self.knobs["transfer"] == "auto" \
                and component == "both" and self.transfer_fits():
            # relighting: one O(P^3) solve now, one product per channel per frame after
            facts["transfer_seconds"] = self.precompute_transfer()
        light_started = time.perf_counter()
        E = self.patch_irradiance(lights)
        facts["irradiance_seconds"] = time.perf_counter() - light_started
        solve_started = time.perf_counter()
        B, info = self.solve(E, component)
        facts["solve_seconds"] = time.perf_counter() - solve_started
        image_started = time.perf_counter()
        rgb = self.image(B, lights, component)
        facts["image_seconds"] = time.perf_counter() - image_started
        seconds = time.perf_counter() - started
        return Image(rgb.astype(np.float32), metadata={
            "producer": "radiosity", "component": component,
            "knobs": {k: v for k, v in self.knobs.items()}, "seconds": seconds,
            "patches": len(self.patches), "iterations": info.get("iterations", 0),
            "solver": info.get("solver"), "residual": info.get("residual"),
            "convergence": self.convergence, "skipped": list(self.log.skipped), **facts})

    def components(self, lights=None) -> dict[str, Image]:
        """Render the bounce decomposition of Sheng et al. 2014, Fig. 6, as images."""
        E = self.patch_irradiance(lights)
        out = {}
        for component in COMPONENTS:
            B, info = self.solve(E, component)
            out[component] = Image(self.image(B, lights, component).astype(np.float32),
                                   metadata={"producer": "radiosity", "component": component,
                                             "iterations": info.get("iterations", 0)})
        return out


# ---------------------------------------------------------------------------------------
# the fast-method contract


def applies_to(scene) -> str | None:
    """None when every material is Lambertian, a Dipole, a RadialProfile or MixedProfiles.

    Translucent radiosity assumes diffuse surfaces and isotropic multiple scattering
    (Sheng et al. 2014, Sect. 1, 7); glossy BRDFs and SubEdit textures are not modelled.
    """
    scene, _ = surface_scene(scene, mixed_profiles_from_solid)
    translucent = False
    for obj in scene.objects:
        try:
            profile = profile_for(obj.material)
        except InputError:
            return (f"object '{obj.name}' has a {type(obj.material).__name__} material; "
                    "translucent radiosity takes diffuse (Lambertian) surfaces and dipole or "
                    "tabulated radial profiles only")
        translucent |= profile is not None
    if not translucent:
        return "no translucent object: this is classical radiosity (every S entry is an albedo)"
    return None


def _resolve_knobs(scene, knobs: dict) -> dict:
    resolved = with_defaults(knobs, DEFAULT_KNOBS)
    if resolved["self_term"] not in ("polar", "samples"):
        raise InputError("must be 'polar' or 'samples'", field="self_term",
                         value=resolved["self_term"])
    if resolved["transfer"] not in ("auto", "never"):
        raise InputError("must be 'auto' or 'never'", field="transfer", value=resolved["transfer"])
    if resolved["solver"] not in SOLVERS:
        raise InputError(f"unknown solver; valid: {', '.join(SOLVERS)}", field="solver",
                         value=resolved["solver"])
    for name in ("tolerance", "sample_falloff", "centroid_beyond", "transfer_budget_mb"):
        if not float(resolved[name]) > 0:
            raise InputError("must be > 0", field=name, value=resolved[name])
    for name in ("rays_per_patch", "self_samples", "voxels_per_axis", "profile_samples",
                 "max_iterations", "light_samples", "mix_points"):
        check_count(resolved[name], name)
    if resolved["mix_points"] > 255:
        raise InputError("must be <= 255 (points per segment are counted in a byte)",
                         field="mix_points", value=resolved["mix_points"])
    check_count(resolved["diffusion_voxels_per_axis"], "diffusion_voxels_per_axis", minimum=4)
    if not isinstance(resolved["finite_object_energy"], bool):
        raise InputError("must be true or false", field="finite_object_energy",
                         value=resolved["finite_object_energy"])
    if resolved["max_distance_mm"] is None:
        radii = []
        for obj in scene.objects:
            profile = profile_for(obj.material)
            profiles = profile.profiles if isinstance(profile, MixedProfiles) else \
                ((profile,) if profile is not None else ())
            radii += [p.support_radius(resolved["profile_energy_cutoff"]) for p in profiles]
        resolved["max_distance_mm"] = float(max(radii, default=1.0))
    elif not float(resolved["max_distance_mm"]) > 0:
        raise InputError("must be > 0 mm", field="max_distance_mm",
                         value=resolved["max_distance_mm"])
    elif not math.isfinite(float(resolved["max_distance_mm"])):
        raise InputError("must be a finite distance > 0 mm (or None: from the profiles)",
                         field="max_distance_mm", value=resolved["max_distance_mm"])
    diffuse_samples = resolved["diffuse_light_samples"]
    if diffuse_samples is not None and (int(diffuse_samples) != diffuse_samples
                                        or diffuse_samples < 1):
        raise InputError("must be None (as light_samples) or an integer >= 1",
                         field="diffuse_light_samples", value=diffuse_samples)
    from ..scenes.raycast import RAY_ENGINES

    if resolved["shadow_ray_engine"] not in RAY_ENGINES:
        raise InputError(f"unknown ray engine; valid: {', '.join(RAY_ENGINES)}",
                         field="shadow_ray_engine", value=resolved["shadow_ray_engine"])
    thickness = resolved["sheet_thickness_mm"]
    if thickness is not None and not float(thickness) > 0:
        raise InputError("must be > 0 mm", field="sheet_thickness_mm", value=thickness)
    return resolved


def precompute(scene, **knobs) -> RadiosityState:
    """Patches, form factors, optical distances and scattering samples; cached on disk.

    Sheng et al. 2014, Sect. 5.1-5.2. The cache key holds the geometry, which objects are
    translucent (and the labels of heterogeneous ones) and the knobs -- never the lights or
    the homogeneous materials, so relighting and translucency changes reuse it. With
    ``max_distance_mm=None`` the cut-off comes from the scene's profiles (part of the key).

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    RadiosityState
    """
    from ..cache import Cache, content_hash

    scene, solid_notes = surface_scene(scene, mixed_profiles_from_solid)
    reason = applies_to(scene)
    if reason is not None and not reason.startswith("no translucent"):
        refuse_inapplicable(scene, reason, "radiosity does not apply")
    resolved = _resolve_knobs(scene, knobs)
    translucent = [i for i, o in enumerate(scene.objects) if profile_for(o.material) is not None]
    # an open translucent surface is a thin sheet of constant thickness, lit from both
    # sides (the rose petals of Sheng et al. 2014, Sect. 6.1)
    sheets = [i for i in translucent
              if not closed_surface(scene.objects[i].mesh.faces, scene.objects[i].mesh.vertices)]
    labels = {scene.objects[i].name: scene.objects[i].material.face_labels
              for i in translucent if isinstance(scene.objects[i].material, MixedProfiles)}
    geometry_knobs = {k: v for k, v in resolved.items() if k not in RUNTIME_KNOBS}
    key = content_hash("radiosity", FORMAT_VERSION, scene.geometry_key(), geometry_knobs,
                       [scene.objects[i].name for i in translucent], labels)
    cache = Cache("radiosity")
    stored = cache.load_pickle(key)
    if stored is not None:
        patches, F, geometry, log = stored
        log.notes["cache"] = "hit"
        if solid_notes:
            log.notes["solid medium"] = solid_notes
        return RadiosityState(scene, patches, F, geometry, resolved, log)
    log = StageLog()
    started = time.perf_counter()
    patches = build_patches(scene, triangles_per_patch=resolved["triangles_per_patch"],
                            two_sided=sheets)
    for index in sheets:
        log.notes.setdefault("thin sheets", []).append(scene.objects[index].name)
    log.seconds["patches"] = time.perf_counter() - started
    log.notes["patches"] = len(patches)
    reason = needs_form_factors(scene)
    if reason is not None:
        log.skip(reason)
        F = None
    else:
        started = time.perf_counter()
        F, facts = form_factors(scene, patches, rays_per_patch=resolved["rays_per_patch"],
                                threshold=resolved["form_factor_threshold"],
                                seed=resolved["seed"])
        log.seconds["form_factors"] = time.perf_counter() - started
        log.notes["form_factors"] = facts
    started = time.perf_counter()
    geometry = scattering_geometry(scene, patches, translucent,
                                   max_distance_mm=resolved["max_distance_mm"], knobs=resolved,
                                   log=log, sheet_thickness_mm=resolved["sheet_thickness_mm"])
    log.seconds["scattering"] = time.perf_counter() - started
    log.notes["scattering_bytes"] = geometry.bytes
    log.notes["max_distance_mm"] = resolved["max_distance_mm"]
    log.notes["cache"] = "miss"
    if solid_notes:
        log.notes["solid medium"] = solid_notes
    cache.store_pickle(key, (patches, F, geometry, log))
    return RadiosityState(scene, patches, F, geometry, resolved, log)


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx radiosity SCENE``."""
    parser.add_argument("--material", default=None,
                        help="for every translucent object: a measured material name "
                             "(Jensen et al. 2001 table, e.g. Marble) or a CSV profile table "
                             "(r in mm, then 1 or 3 reflection columns, optionally as many "
                             "transmission columns)")
    parser.add_argument("--component", default="both", choices=COMPONENTS,
                        help="bounce component of Sheng et al. 2014, Fig. 6 (default: both)")
    parser.add_argument("--solver", default=DEFAULT_KNOBS["solver"], choices=SOLVERS)
    parser.add_argument("--rays", type=int, default=DEFAULT_KNOBS["rays_per_patch"],
                        help="form-factor rays per patch")
    parser.add_argument("--max-distance", type=float, default=None,
                        help="scattering cut-off max_d in mm (default: from the profiles)")
    parser.add_argument("--triangles-per-patch", type=int,
                        default=DEFAULT_KNOBS["triangles_per_patch"])
    parser.add_argument("--semi-infinite", action="store_true",
                        help="the dipole as the paper uses it, without the finite-object "
                             "energy (knob finite_object_energy)")


def approx(scene, args) -> Image:
    """Precompute (or load) and render ``scene`` for ``translucent approx radiosity``."""
    from pathlib import Path

    from ..materials import measured_medium
    from ..materials.profiles import TabulatedProfile

    started = time.perf_counter()
    material = None
    if args.material and Path(args.material).is_file():
        material = TabulatedProfile.from_file(args.material)
    elif args.material:
        material = measured_medium(args.material)
    if material is not None:
        targets = _materials_of(scene, material)
        if not targets:
            raise InputError(f"no translucent object in scene {scene.name!r} to give it to",
                             field="material", value=args.material)
        for name in targets:
            scene = scene.with_material(name, material)
    state = precompute(scene, solver=args.solver, rays_per_patch=args.rays,
                       max_distance_mm=args.max_distance,
                       triangles_per_patch=args.triangles_per_patch,
                       finite_object_energy=not args.semi_infinite)
    image = state.render(component=args.component)
    for sentence in state.log.skipped:
        print(f"skipped: {sentence}")
    print(f"patches {len(state.patches)}, iterations {image.metadata['iterations']}, "
          f"max column sum of S {state.convergence['max_scattering_column_sum']:.4f}")
    return image.with_metadata(seconds=time.perf_counter() - started,
                               precompute_seconds=dict(state.log.seconds))
