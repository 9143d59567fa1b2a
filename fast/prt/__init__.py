r"""PRT editing and relighting of homogeneous translucent materials (Wang et al. 2008).

The diffuse BSSRDF (Eq. 2) with the dipole profile expanded in a PCA basis,
:math:`R_d(r, \sigma) \approx \sum_k b_k(r) s_k(\sigma)` (Eq. 4,
:mod:`translucent.materials.dipole_pca`), turns Eq. 1 into K precomputed transfers
(Eq. 5-7):

.. math::
    B(x, \omega_o) = \frac{F_t(\eta, \omega_o)}{\pi} \sum_k s_k(\sigma)\,
    \sum_i T_k(x, x_i)\,E(x_i), \qquad T_k(x, x_i) = b_k(\lVert x - x_i\rVert)\,A_i

from uniform illumination samples :math:`x_i` (area :math:`A_i`) on the object to every
vertex :math:`x`, with :math:`E` the irradiance of Eq. 6 (Fresnel-weighted, shadowed).

Precomputation (:func:`precompute`), per translucent object:

1. ``samples = m x 4^n`` uniform surface samples, split into ``m`` parts by median cuts,
   each laid out on a ``2^n x 2^n`` square by a balanced quadtree (Hašan et al. 2006);
2. every row of every :math:`T_k` is transformed by the 2D Haar wavelet over those squares
   and cut to its largest coefficients (energy threshold and term budget: Eq. 8), then
   quantised to 16-bit values with 16-bit indices (14/18 bits beyond 2^16 samples);
3. on meshes that are geometry images (``Mesh.grid_shape``) with more than
   ``spatial_min_vertices`` vertices, a second pass transforms each :math:`T_k` along the
   vertices with the CDF 9/7 wavelet and keeps its largest coefficients (Eq. 9-10); smaller
   meshes and unparameterised ones skip it, as in the paper.

The first pass runs on compiled kernels over all cores (``workers``) with a progress bar;
the result is cached on disk keyed by the object's geometry and the knobs (never by lights
or material).

Interactive path (``state.render(lights=None, material=None)``):

* relighting: irradiance :math:`E` at the samples from point, spot, directional, area
  (rectangle, sphere) and environment lights, with shadows from ``scenes`` ray queries
  (environment: precomputed wavelet-compressed visibility per sample, built only when the
  scene has an environment light); Haar transform of :math:`E`; one sparse product of the
  quantised matrix with :math:`E^w` gives all :math:`v_k = T_k^w E^w` (Eq. 8);
* editing: :math:`s_k(\sigma)` per RGB channel re-weights the cached :math:`v_k`
  (Eq. 7/10; no transfer product is redone), inverse CDF 9/7 where spatially compressed,
  then :math:`F_t(\eta, \omega_o)/\pi` per pixel through the camera G-buffer. Changing
  :math:`\eta` changes :math:`F_t(\eta, \omega_i)` inside :math:`E`, so it relights.

The knob ``profile`` expands another registered radial profile than the dipole: its basis
is built by the same procedure over that profile's family and cached
(:mod:`.profile_basis`); the default is the dipole's shipped basis.

The method is split by concept: :mod:`.knobs`, :mod:`.transfer` (samples and the two
passes), :mod:`.profile_basis` (the basis over another profile), :mod:`.lighting`,
:mod:`.state` and :mod:`.method`.

References
----------
Wang, Cheslack-Postava, Wang, Luebke, Chen, Hua, Peng, Bao: Real-time editing and
relighting of homogeneous translucent materials. The Visual Computer 24 (2008).
Hašan, Pellacini, Bala: Direct-to-indirect transfer for cinematic relighting. ACM TOG 25(3)
(2006).
"""

from __future__ import annotations

from .knobs import (
    DEFAULT_KNOBS,
    ENERGY_BLEND_END,
    ENERGY_BLEND_START,
    FRESNEL_RANK,
    KNOBS,
    LADDERS,
    LOCAL_BLEND_END,
    LOCAL_BLEND_START,
    LOCAL_KERNEL_WIDTH,
    QUICK_KNOBS,
)
from .lighting import (
    EnvironmentTransfer,
    fresnel_cosine_factors,
    precompute_environment,
    sample_irradiance,
)
from .method import (
    add_approx_arguments,
    applies_to,
    approx,
    material_from_arguments,
    precompute,
    scored_objects,
)
from .state import PRTState, brute_force_radiance, projection_blend, single_colour
from .transfer import IlluminationSamples, ObjectTransfer, illumination_samples

__all__ = [
    "DEFAULT_KNOBS",
    "KNOBS",
    "LADDERS",
    "QUICK_KNOBS",
    "applies_to",
    "scored_objects",
    "precompute",
    "PRTState",
    "ObjectTransfer",
    "IlluminationSamples",
    "illumination_samples",
    "sample_irradiance",
    "brute_force_radiance",
    "projection_blend",
    "add_approx_arguments",
    "approx",
    "LOCAL_BLEND_START",
    "LOCAL_BLEND_END",
    "ENERGY_BLEND_START",
    "ENERGY_BLEND_END",
    "LOCAL_KERNEL_WIDTH",
    "FRESNEL_RANK",
    "fresnel_cosine_factors",
    "single_colour",
    "material_from_arguments",
    "EnvironmentTransfer",
    "precompute_environment",
]
