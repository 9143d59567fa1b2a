r"""Volumetric path tracing with manifold next-event estimation through one dielectric boundary.

A point, spot or directional light outside a smooth ``dielectric`` boundary cannot be
reached from a medium vertex inside it by ordinary next-event estimation: the shadow ray
stops at the boundary, and no refracted path hits a light of zero size. This integrator
(``volpath_mnee``) is Mitsuba's ``volpath`` (the same free-flight sampling, phase
functions, surface next-event estimation with multiple importance sampling and Russian
roulette rule) plus one more strategy at every medium vertex :math:`v` inside such a
boundary: the connection :math:`v \to y \to \ell` to a light point :math:`\ell` through
the one boundary point :math:`y` where Snell's law holds (Hanika, Droske and Fascione
2015, "Manifold next event estimation").

**The constraint.** With the shading normal :math:`n(y)` pointing out of the medium, the
unit directions :math:`\omega_o = (\ell - y)/|\ell - y|` (to the light; the light's own
direction for a directional light) and :math:`\omega_i = (v - y)/|v - y|` (into the
medium), and :math:`\eta` the relative index inside, Snell's law in vector form is

.. math:: C(y) = P_{n(y)}\,(\omega_o + \eta\,\omega_i) = 0,

:math:`P_n` the projection onto the tangent plane (equal tangential components of
:math:`\sin\theta` times index on both sides; unlike the generalised half vector it does
not vanish at :math:`\eta = 1`). :math:`C` is solved by Newton's method in tangent-plane
coordinates of the surface point (Hanika et al. 2015, Sect. 4): the Jacobian is taken by
central differences of the local first-order model :math:`y + a\,s + b\,t`,
:math:`n + a\,\partial_s n + b\,\partial_t n` (Mitsuba's ``dn_du``, ``dn_dv`` of the
interpolated normals), each step is projected back onto the surface by a ray from
:math:`v`, and a step that does not lower :math:`|C|` is halved (as in the published
specular manifold sampling code of Zeltner, Georgiev and Jakob 2020). The start is the
point where the straight segment from :math:`v` to the light leaves the medium.

**The contribution.** Flux is conserved along the refracted tube of rays (times the
Fresnel transmittance :math:`T`), so the irradiance perpendicular to the refracted ray at
:math:`v` is

.. math:: E_\perp(v) = I(\omega_o)\, T(\omega_o\cdot n)\,
          \frac{|d\omega_\ell|}{|dA_\perp(v)|}\,
          \mathrm{Tr}(v, y)\,\mathrm{Tr}(y, \ell)

(the generalised geometry term of Hanika et al. 2015, Eq. 7, for one refraction; Walter
et al. 2009, "Single scattering in refractive media with triangle mesh boundaries",
Sect. 4): :math:`d\omega_\ell` is the solid angle of the tube at the light and
:math:`dA_\perp` its cross-section at :math:`v`, both per unit area of the boundary, taken
by central differences of the refracted rays of the local model. For a directional light
:math:`I\,d\omega_\ell` becomes the irradiance times the tube's cross-section before the
boundary. The medium vertex adds ``throughput * phase * E_perp``, as ``volpath`` adds
``throughput * phase * I / r^2`` for an unobstructed light.

**Area lights** (any shape with an ``area`` emitter) are connected the same way, from a
point sampled uniformly on the shape's area (intensity :math:`L_e\cos\theta_\ell / p_A`).
A camera path that leaves a medium vertex, refracts once and hits such a light is then
counted only when the solver, started from the same two end points, would not have found
that refraction point; so the two strategies partition the paths exactly, and with the
light made small this integrator must agree with plain ``volpath`` (a test checks it).

**What is not sampled.** Paths from a medium vertex to a delta light through two or more
specular events (an internal reflection and then a refraction; two refractions through a
second object) stay at zero probability, as in ``volpath``. Where the solve does not
converge, or converges to a configuration that is not a refraction (total internal
reflection, the light behind the tangent plane), the connection gives zero: each such case
is counted (:data:`COUNTERS`) and written into the image header, never dropped silently.

**Several refraction paths.** A concave boundary often refracts one light into one point
along several paths, and a convex one does past a lens caustic; the solve from the straight
line finds at most one of them. With ``seeded_solutions`` (set by the conversion where a
dielectric boundary is concave) the others are added by specular manifold sampling (Zeltner,
Georgiev and Jakob 2020, unbiased form): one more solve starts from the boundary point hit
along a uniformly random direction from :math:`v`; a refraction point :math:`y` it reaches
that is not the straight start's is weighted by :math:`1/p(y)`, the inverse probability that
a random start reaches it, estimated without bias by the count of further random starts
until one reaches :math:`y` again (at most :data:`MAX_TRIALS`; a cut count is counted).
The expectation is the sum over every refraction point but the straight start's. Area
lights keep the exact partition above instead. Convex boundaries are left without it: past
the caustic of a sphere at eta 1.3 the missed paths hold about 1 % of the light of an
optically thin sphere, at 2.4x the cost (docs/references.md).
"""

from __future__ import annotations

import numpy as np

from ..backend import mitsuba
from ..scenes.mesh_shape import welded_faces
from .manifold_settings import COUNTERS, INTEGRATOR_NAME, MAX_TRIALS

__all__ = ["INTEGRATOR_NAME", "COUNTERS", "MAX_TRIALS", "register", "counts"]


def register() -> None:
    """Register ``volpath_mnee`` with Mitsuba for the active variant (idempotent)."""
    mi = mitsuba()
    if not mi.variant().startswith(("llvm_", "cuda_")):
        from ..errors import InputError

        raise InputError(f"{INTEGRATOR_NAME} needs a JIT variant (llvm_ad_rgb or "
                         f"cuda_ad_rgb); set TRANSLUCENT_VARIANT", field="variant",
                         value=mi.variant())
    from .manifold_integrator import ManifoldVolpath

    mi.register_integrator(INTEGRATOR_NAME, lambda props: ManifoldVolpath(props))


def counts(mitsuba_scene) -> dict[str, int] | None:
    """Return what the scene's ``volpath_mnee`` integrator counted since loading (None: other)."""
    counters = getattr(mitsuba_scene.integrator(), "counters", None)
    if counters is None:
        return None
    return dict(zip(COUNTERS, (int(c) for c in counters), strict=True))


def boundary_edge_count(vertices, faces) -> int:
    """Return how many edges of a mesh fail to be shared by exactly two opposed faces.

    Vertices are welded by position first
    (:func:`~translucent.scenes.mesh_shape.welded_faces`: a box has separate vertices along
    its edges for its flat normals). 0 for a closed, consistently oriented 2-manifold: the
    inside the solve refracts into is well defined.
    """
    welded = welded_faces(vertices, np.asarray(faces, dtype=np.int64))
    directed = np.concatenate([welded[:, [0, 1]], welded[:, [1, 2]], welded[:, [2, 0]]])
    directed = directed[directed[:, 0] != directed[:, 1]]  # degenerate triangles' edges
    forward, counts = np.unique(directed, axis=0, return_counts=True)
    table = {tuple(edge): count for edge, count in zip(forward.tolist(), counts.tolist(),
                                                        strict=True)}
    bad = 0
    for (a, b), count in table.items():
        if count != 1 or table.get((b, a), 0) != 1:
            bad += 1
    return bad


def check_closed_boundaries(scene, indices) -> None:
    """Refuse a dielectric boundary (objects ``indices`` of ``scene``) that is not closed.

    Raises
    ------
    InputError
        Naming the scene file, the object's mesh and how many edges are open or
        inconsistently oriented.
    """
    from ..errors import InputError

    for index in indices:
        obj = scene.objects[index]
        bad = boundary_edge_count(obj.mesh.vertices, obj.mesh.faces)
        if bad:
            raise InputError(
                f"{INTEGRATOR_NAME} refracts through the boundary of a medium, which must "
                f"be a closed, consistently oriented mesh; {bad} edges are open or "
                f"inconsistently oriented", file=scene.source,
                field=f"objects[{index}].mesh", value=obj.name)
