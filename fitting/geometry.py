r"""Exact radial geometry of square pixels: disc-rectangle overlaps, the radial grid.

A pixel of a capture integrates the exitance over its square footprint. To compare a radial
profile :math:`f(\rho)` with the mean of the pixels of an annulus, this module splits each
pixel into the rings of a radial grid by exact disc-rectangle intersection areas, so that
the central pixels (where the profile is sharpest) are integrated exactly rather than
point-sampled.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

__all__ = ["RadialGrid", "disc_quadrant_area", "disc_rectangle_area", "radial_grid"]

#: Ratio of successive nodes of the geometric radial grid. A profile linear between nodes
#: then misrepresents one that varies on the scale of r (the dipole near its sources) by
#: ~1e-4 relative in annulus means (measured against 24x-supersampled pixels): well below
#: the 1e-3 standard error of the best-measured annuli of a 16-bit capture.
GRID_RATIO = 1.02


def disc_quadrant_area(x, y, radius):
    r"""Signed area of the disc of ``radius`` about the origin within the box [0, x] x [0, y].

    The sign is that of :math:`x y`, which makes rectangle areas follow by inclusion and
    exclusion (see :func:`disc_rectangle_area`). For :math:`x, y \ge 0` with
    :math:`x' = \min(x, R)`, :math:`y' = \min(y, R)`: :math:`x'y'` when the corner lies in
    the disc, else :math:`y' x_c + F(x') - F(x_c)` with :math:`x_c = \sqrt{R^2 - y'^2}` and
    :math:`F(t) = \tfrac12(t\sqrt{R^2 - t^2} + R^2 \arcsin(t/R))`.

    Parameters
    ----------
    x, y : array_like
        Box corner, any unit of length.
    radius : array_like
        Disc radius, same unit, >= 0.

    Returns
    -------
    ndarray
        Area, unit squared; broadcast shape of the inputs.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    sign = np.sign(x) * np.sign(y)
    xp = np.minimum(np.abs(x), radius)
    yp = np.minimum(np.abs(y), radius)
    inside = xp * xp + yp * yp <= radius * radius
    xc = np.sqrt(np.clip(radius * radius - yp * yp, 0.0, None))

    def primitive(t):
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(radius > 0, t / np.where(radius > 0, radius, 1.0), 0.0)
        return 0.5 * (t * np.sqrt(np.clip(radius * radius - t * t, 0.0, None))
                      + radius * radius * np.arcsin(np.clip(ratio, -1.0, 1.0)))

    partial = yp * xc + primitive(xp) - primitive(xc)
    return sign * np.where(inside, xp * yp, partial)


def disc_rectangle_area(radius, x0, x1, y0, y1):
    r"""Area of the disc of ``radius`` about the origin within the rectangle [x0, x1] x [y0, y1].

    Inclusion-exclusion over the signed quadrant areas of :func:`disc_quadrant_area`.
    Exact up to rounding; broadcasts.

    Parameters
    ----------
    radius : array_like
        >= 0, any unit of length.
    x0, x1, y0, y1 : array_like
        Rectangle bounds, same unit, ``x0 <= x1``, ``y0 <= y1``.

    Returns
    -------
    ndarray
        Area, unit squared, in [0, (x1 - x0)(y1 - y0)].
    """
    return (disc_quadrant_area(x1, y1, radius) - disc_quadrant_area(x0, y1, radius)
            - disc_quadrant_area(x1, y0, radius) + disc_quadrant_area(x0, y0, radius))


@dataclass(frozen=True)
class RadialGrid:
    """Nodes of a radial grid, mm: 0, then geometric from ``nodes[1]`` to ``nodes[-1]``.

    A radial function is represented by its values at the nodes and interpolated linearly
    in r between them.
    """

    nodes: np.ndarray

    @property
    def size(self) -> int:
        """Number of nodes."""
        return int(self.nodes.size)

    @property
    def r_max(self) -> float:
        """Largest node, mm."""
        return float(self.nodes[-1])


def radial_grid(r_max_mm: float, resolution_mm: float,
                max_spacing_mm: float | None = None) -> RadialGrid:
    """Build a grid from 0 to ``r_max_mm``: 0, geometric from ``resolution_mm``, then uniform.

    Successive nodes grow by :data:`GRID_RATIO` until their spacing reaches
    ``max_spacing_mm``; from there on they are equally spaced. The geometric part resolves
    a profile that varies on the scale of r (near the incident point), the uniform part one
    that decays exponentially (far from it).

    Parameters
    ----------
    r_max_mm : float
        Outermost node, mm, > ``resolution_mm``.
    resolution_mm : float
        First non-zero node, mm, > 0: below it the profile is taken as linear.
    max_spacing_mm : float, optional
        Largest spacing, mm (default: no limit).

    Returns
    -------
    RadialGrid
    """
    if not (np.isfinite(r_max_mm) and np.isfinite(resolution_mm) and
            0 < resolution_mm < r_max_mm):
        raise InputError("need 0 < resolution_mm < r_max_mm", field="r_max_mm",
                         value=(resolution_mm, r_max_mm))
    spacing = np.inf if max_spacing_mm is None else float(max_spacing_mm)
    if not spacing > 0:
        raise InputError("must be > 0", field="max_spacing_mm", value=max_spacing_mm)
    # geometric until the step r (ratio - 1) reaches the spacing limit
    switch = min(r_max_mm, max(resolution_mm, spacing / (GRID_RATIO - 1.0)))
    count = int(np.ceil(np.log(switch / resolution_mm) / np.log(GRID_RATIO))) + 1
    geometric = np.geomspace(resolution_mm, switch, max(count, 1))
    nodes = [[0.0], geometric]
    if switch < r_max_mm:
        steps = int(np.ceil((r_max_mm - switch) / spacing))
        nodes.append(np.linspace(switch, r_max_mm, steps + 1)[1:])
    return RadialGrid(np.concatenate(nodes))
