r"""Translucent radiosity: diffuse inter-reflection combined with subsurface scattering.

Sheng, Shi, Wang, Narasimhan: Translucent radiosity: efficiently combining diffuse
inter-reflection and subsurface scattering. IEEE TVCG 20(7), 2014.

The scene is cut into patches; the radiosity (exitance) :math:`B` of every patch solves

.. math:: B = \sum_{N \ge 1} (SF)^{N-1} SE = (I - SF)^{-1} SE \qquad \text{(Eq. 14)}

with :math:`E` the irradiance from the lights, :math:`F` the form factors (irradiance of
patch i from the radiosity of patch j, :mod:`translucent.fast.radiosity.form_factors`) and
:math:`S` the scattering factors: :math:`S_{ji}` takes the irradiance of patch i to the
radiosity of patch j through the material (Eq. 7-8). For an opaque Lambertian patch
:math:`S = P = \mathrm{diag}(\rho)` and Eq. 14 is classical radiosity (Eq. 2).

Scattering factors (Eq. 8, Sect. 5.2). With the exit point at the centroid :math:`c_j`,

.. math:: S_{ji} = \frac{1}{A_j}\int_{A_i}\int_{A_j} s\,dA_j\,dA_i
          \approx \int_{A_i} s(d(x, c_j))\,dA_x,

where :math:`s(r)` is a 1D profile (:mod:`translucent.materials.profiles`; the dipole, or
another registered one by the knob ``profile``) of the
shortest optical distance :math:`d` (:mod:`translucent.fast.radiosity.optical_distance`). The
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
object's own shape over the half-space's (:mod:`translucent.fast.radiosity.diffusion_escape`: one
finite-volume solve per channel on a voxel grid of the object, ``diffusion_voxels_per_axis``
cells along its longest side), the light added spread over the column's patches in
proportion to the fluence of the dipole's source with its mirror image in the entry
patch's tangent plane (zero on that plane: the extra light is what the half-space would
carry past the object's other faces).
The measured effect and cost are in docs/radiosity.md.

Solving (Sect. 5.3): Jacobi iteration :math:`B \leftarrow SE + SFB` (the paper's solver) or
GMRES / BiCGSTAB from :mod:`scipy.sparse.linalg`, to a relative residual
:math:`\|SE - (I - SF)B\| / \|SE\|` of 0.5 %. Before any iteration the condition of Eq. 15 is
checked; where objects inter-reflect, a material that breaks it raises
:class:`~translucent.errors.InputError` naming the object, patch, channel and column sum.
A lone convex object has no series to diverge (:math:`B = SE`): a profile that reflects
more than it receives (photon beam diffusion near albedo 1) is rendered as it is and
reported (``convergence["energy_conserving"]``). A Jacobi sweep's change is the residual of the
iterate it started from, so that iterate is returned with its :math:`FB` (which the image
needs): every product of SF advances or checks, none is spent twice. Successive frames
start from the earlier frames' solutions projected on the new irradiance
(:meth:`RadiosityState.solve`): 2 products per frame on a sliding light.

Relighting with :math:`T = (I - SF)^{-1}S` (Sect. 6.4): T is dense, :math:`3P^2` float32, and
is precomputed (knob ``transfer="auto"``) at a relighting once the solves since the last
material change have taken as long as its build is estimated to take (the ski-rental rule:
at most twice the cost of the better choice in hindsight, however many frames follow), and
only when it fits the ``transfer_budget_mb`` knob: P <= 6,688 at the default 512 MB; the
dense solve needs about five times that while it runs. Without form factors T would be S
itself and is not built. Whether T and a low-rank T pay is measured in docs/radiosity.md.

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

The package, one concept a module: :mod:`.knobs` (knobs and constants),
:mod:`.geometry` (the material-independent scattering geometry), :mod:`.scattering` (S of a
material, Eq. 7-8 and 16), :mod:`.solve` (Eq. 14-15), :mod:`.lighting` (E),
:mod:`.state` (relighting and editing), :mod:`.method` (the fast-method contract) and
:mod:`.kernels` (the compiled CPU loops).
"""

from .geometry import ObjectScattering, ScatteringGeometry, scattering_geometry
from .kernels import COMPILED_PRODUCT_ENTRIES
from .knobs import (
    COMPONENTS,
    DEFAULT_KNOBS,
    FORMAT_VERSION,
    HALF_SPACE_KNOBS,
    HETEROGENEOUS_RULE,
    KNOBS,
    LADDERS,
    QUICK_KNOBS,
    RUNTIME_KNOBS,
    SOLVERS,
    ConvergenceError,
)
from .lighting import AreaLightShadows, direct_irradiance
from .method import add_approx_arguments, applies_to, approx, precompute
from .scattering import ScatteringMatrix, scattering_matrix
from .solve import (
    check_convergence,
    form_factor_bounds,
    form_factor_product,
    solve_radiosity,
    transfer_matrix,
)
from .state import RadiosityState

__all__ = [
    "COMPILED_PRODUCT_ENTRIES",
    "COMPONENTS",
    "DEFAULT_KNOBS",
    "HALF_SPACE_KNOBS",
    "HETEROGENEOUS_RULE",
    "KNOBS",
    "LADDERS",
    "QUICK_KNOBS",
    "FORMAT_VERSION",
    "RUNTIME_KNOBS",
    "SOLVERS",
    "AreaLightShadows",
    "ConvergenceError",
    "ObjectScattering",
    "RadiosityState",
    "ScatteringGeometry",
    "ScatteringMatrix",
    "add_approx_arguments",
    "applies_to",
    "approx",
    "check_convergence",
    "direct_irradiance",
    "form_factor_bounds",
    "form_factor_product",
    "precompute",
    "scattering_geometry",
    "scattering_matrix",
    "solve_radiosity",
    "transfer_matrix",
]
