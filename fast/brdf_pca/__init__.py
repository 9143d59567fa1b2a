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
(:func:`~translucent.fast.brdf_pca.lighting.gather_pair_visibility`).

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

from .knobs import DEFAULT_KNOBS, FORMAT_VERSION, KNOBS, LADDERS, QUICK_KNOBS
from .method import add_approx_arguments, applies_to, approx, model_name, precompute
from .state import BRDFPCAState
from .transfer import Precomputation, disk_transfer

__all__ = [
    "DEFAULT_KNOBS",
    "FORMAT_VERSION",
    "KNOBS",
    "LADDERS",
    "QUICK_KNOBS",
    "BRDFPCAState",
    "Precomputation",
    "add_approx_arguments",
    "applies_to",
    "approx",
    "disk_transfer",
    "model_name",
    "precompute",
]
