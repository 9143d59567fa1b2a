"""The settings of ``volpath_mnee`` (:mod:`translucent.reference.manifold_nee`).

Shared by the module that registers the integrator and its Dr.Jit code
(:mod:`translucent.reference.manifold_integrator`), so that neither imports the other.
"""

from __future__ import annotations

__all__ = ["COUNTERS", "DIFFERENCE_STEP", "INTEGRATOR_NAME", "MAX_ITERATIONS", "MAX_TRIALS",
           "MIN_STEP", "POSITION_PRECISION", "ROULETTE_TRANSMITTANCE", "SAME_POINT",
           "SEEDED_FRACTION", "TOLERANCE"]

#: The name under which the integrator is registered with Mitsuba.
INTEGRATOR_NAME = "volpath_mnee"

#: What the integrator counts, in this order (read with :func:`counts`).
COUNTERS = (
    "connections",        # medium vertices whose shadow ray met a dielectric boundary
    "solved",             # ... whose Newton solve converged to a valid refraction
    "not_converged",      # the solve ran out of iterations or step length
    "not_refraction",     # converged to total internal reflection or a back-facing light
    "area_hits_kept",     # refracted hits of an area light the solver would not have found
    "seeded_found",       # other refraction points found from a random seed (concave)
    "trials_capped",      # ... whose inverse probability ran out of trials (MAX_TRIALS)
)

#: Newton iterations before a solve is given up.
MAX_ITERATIONS = 32

#: A solve has converged when the tangential Snell mismatch :math:`|C|` (a sine) is below
#: this (float32 positions give about 1e-6).
TOLERANCE = 2e-5

#: Relative precision of a float32 position (a few units in the last place): a vertex at
#: distance d from its refraction point y knows the direction to it only to about this
#: times (1 + |y|) / d, which is added to :data:`TOLERANCE`.
POSITION_PRECISION = 8.0 * 2.0**-24

#: Step of the central differences, as a fraction of the distance from the medium vertex to
#: the boundary plus the scene's size.
DIFFERENCE_STEP = 1e-3

#: A connection whose straight segment to the boundary transmits less than this (in its
#: clearest channel) is made with probability transmittance / this and weighted by the
#: inverse (Russian roulette: unbiased; the refracted segment is close to the straight
#: one, so the weight stays near this value's inverse times the contribution).
ROULETTE_TRANSMITTANCE = 0.05

#: A proposed Newton step shorter than this fraction of a full step ends the solve.
MIN_STEP = 1.0 / 1024.0

#: Seeded solves (specular manifold sampling) spent on estimating the inverse probability
#: of a refraction point found from a random seed: the count of trials until a seed
#: reaches it again is unbiased for that inverse (Zeltner et al. 2020, Sect. 4.3); a count
#: cut here loses the fraction (1 - p)^MAX_TRIALS of the point's light, and is counted.
MAX_TRIALS = 256

#: Two solves reached the same refraction point when they end closer than this fraction of
#: the vertex's distance to it plus the scene's size.
SAME_POINT = 1e-3

#: The fraction of the connections that make the seeded search (each found point weighted
#: by its inverse: unbiased). Further refraction points are rare where most connections
#: have one (0.015 % of the connections on a Skin1 torus), and a search costs about two
#: solves, so searching at every connection tripled the render time.
SEEDED_FRACTION = 0.25
