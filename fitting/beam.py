r"""The finite beam: its irradiance profile and its convolution with a radial profile.

Two beam shapes (the sidecar's ``beam_profile``): ``"gaussian"``, of 1/e^2 radius
:math:`w`, below; and ``"top_hat"``, a uniform disk of radius :math:`a` (a fibre or an
aperture), :math:`B(\rho) = 1 / (\pi a^2)` for :math:`\rho \le a`, whose angularly
integrated kernel is the arc of the circle of radius :math:`s` about the axis that lies
inside the disk about :math:`\rho`:
:math:`k(\rho, s) = \frac{2}{\pi a^2} \arccos\left(\mathrm{clip}\left(
\frac{\rho^2 + s^2 - a^2}{2 \rho s}, -1, 1\right)\right)`.

A beam of 1/e^2 radius :math:`w` has the normalised irradiance
:math:`B(\rho) = \frac{2}{\pi w^2} e^{-2\rho^2/w^2}` (mm^-2, integral 1). Convolving a
radially symmetric profile :math:`f` with it gives another radial profile,

.. math::
    (B * f)(\rho) = \int_0^\infty f(s)\, k(\rho, s)\, s\, ds,\qquad
    k(\rho, s) = \frac{4}{w^2}\, e^{-2(\rho - s)^2/w^2}\, I_0^{e}(4\rho s / w^2),

where :math:`I_0^e(x) = e^{-x} I_0(x)` is the exponentially scaled Bessel function (the
angular integral of the Gaussian, written so that it never overflows). With ``f`` linear
between the nodes of a :class:`~translucent.fitting.geometry.RadialGrid`, the convolution
is a matrix on the node values, built once per capture.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.special import i0e

from ..errors import InputError
from .geometry import RadialGrid

__all__ = ["BEAM_PROFILES", "beam_irradiance", "beam_convolution_kernel",
           "beam_convolution_matrix"]

#: The beam shapes a capture may give (``beam_profile``).
BEAM_PROFILES = ("gaussian", "top_hat")

#: Points per interval of a top-hat row's quadrature. The kernel has square-root kinks
#: where the circles touch (s = |rho - a| and rho + a): each row is integrated between the
#: grid nodes and those points, with Gauss-Legendre after a cosine map on the intervals
#: ending at a kink (which absorbs the square root), plain Gauss-Legendre elsewhere.
TOP_HAT_POINTS = 8

#: Gauss-Legendre points per sub-cell of the convolution quadrature.
QUADRATURE_ORDER = 4
#: Sub-cells per beam standard deviation (w / 2): 4-point Gauss-Legendre on cells of
#: sigma / 2 integrates the Gaussian kernel to better than 1e-8 relative.
SUBCELLS_PER_SIGMA = 2.0
#: Where the beam is narrower than this fraction of the grid's cell width the grid cannot
#: resolve it; the profile there varies on the scale of r >> w, so the convolution changes
#: it by O((w / r)^2) < 1e-3 and the row is the identity.
UNRESOLVED_FRACTION = 0.25


def _check_profile(profile: str) -> str:
    if profile not in BEAM_PROFILES:
        raise InputError(f"must be one of {', '.join(BEAM_PROFILES)}", field="beam_profile",
                         value=profile)
    return profile


def beam_irradiance(rho, beam_radius_mm, profile: str = "gaussian"):
    r"""Normalised beam irradiance :math:`B(\rho)`, mm^-2.

    Parameters
    ----------
    rho : array_like
        Distance from the beam axis, mm.
    beam_radius_mm : float
        1/e^2 radius :math:`w` (Gaussian) or disk radius :math:`a` (top hat), mm, > 0.
    profile : {"gaussian", "top_hat"}

    Returns
    -------
    ndarray
        :math:`\frac{2}{\pi w^2} e^{-2\rho^2/w^2}`, or :math:`1 / (\pi a^2)` inside the
        disk; integrates to 1 over the plane.
    """
    w = float(beam_radius_mm)
    rho = np.asarray(rho, dtype=np.float64)
    if _check_profile(profile) == "top_hat":
        return np.where(rho <= w, 1.0 / (np.pi * w * w), 0.0)
    return 2.0 / (np.pi * w * w) * np.exp(-2.0 * rho * rho / (w * w))


def beam_convolution_kernel(rho, s, beam_radius_mm, profile: str = "gaussian"):
    r"""Angularly integrated beam kernel :math:`k(\rho, s)`, mm^-2 (see the module docstring).

    Parameters
    ----------
    rho, s : array_like
        Radii, mm, >= 0; broadcast against each other.
    beam_radius_mm : float
        1/e^2 radius :math:`w` (Gaussian) or disk radius :math:`a` (top hat), mm, > 0.
    profile : {"gaussian", "top_hat"}

    Returns
    -------
    ndarray
        :math:`k` such that :math:`(B * f)(\rho) = \int f(s) k(\rho, s) s\, ds`.
    """
    w2 = float(beam_radius_mm) ** 2
    rho = np.asarray(rho, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    if _check_profile(profile) == "top_hat":
        product = 2.0 * rho * s
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            cosine = np.where(product > 0, (rho**2 + s**2 - w2) / np.where(product > 0,
                                                                          product, 1.0),
                              np.where(rho**2 + s**2 < w2, -np.inf, np.inf))
        return 2.0 / (np.pi * w2) * np.arccos(np.clip(cosine, -1.0, 1.0))
    return 4.0 / w2 * np.exp(-2.0 * (rho - s) ** 2 / w2) * i0e(4.0 * rho * s / w2)


def beam_convolution_matrix(grid: RadialGrid, beam_radius_mm: float,
                            profile: str = "gaussian") -> np.ndarray:
    """Matrix ``K`` with ``(B * f)(nodes) = K @ f(nodes)`` for ``f`` linear between nodes.

    ``f`` is taken as zero beyond the last node. Rows where the grid cannot resolve the
    beam (see :data:`UNRESOLVED_FRACTION`) are the identity; a zero radius gives the
    identity matrix.

    Parameters
    ----------
    grid : RadialGrid
    beam_radius_mm : float
        1/e^2 radius (Gaussian) or disk radius (top hat), mm, >= 0.
    profile : {"gaussian", "top_hat"}

    Returns
    -------
    ndarray, shape (grid.size, grid.size)
    """
    _check_profile(profile)
    w = float(beam_radius_mm)
    if not np.isfinite(w) or w < 0:
        raise InputError("must be >= 0", field="beam_radius_mm", value=beam_radius_mm)
    nodes = grid.nodes
    n = nodes.size
    kernel_matrix = np.eye(n)
    if w == 0.0:
        return kernel_matrix
    # the quadrature's length scale: the Gaussian's sigma; for a top hat its radius / 8
    sigma = 0.5 * w if profile == "gaussian" else w / 8.0
    widths = np.diff(nodes)
    # the local cell width at each node (the wider neighbour) decides resolvability
    local = np.maximum(np.concatenate([widths, widths[-1:]]), np.concatenate([widths[:1], widths]))
    resolved = sigma >= UNRESOLVED_FRACTION * local
    if not resolved.any():
        return kernel_matrix
    if profile == "top_hat":
        rows = np.flatnonzero(resolved)
        kernel_matrix[rows] = _top_hat_rows(nodes, rows, w)
        return kernel_matrix
    # only cells within reach of a resolved row matter
    reach = nodes[resolved].max() + 8.0 * sigma
    cells = np.flatnonzero(nodes[:-1] < reach)
    points, weights = np.polynomial.legendre.leggauss(QUADRATURE_ORDER)
    sub_counts = np.clip(np.ceil(widths[cells] * SUBCELLS_PER_SIGMA / sigma), 1, 4096)
    sub_counts = sub_counts.astype(np.int64)
    cell_of_sub = np.repeat(cells, sub_counts)
    offsets = np.arange(sub_counts.sum()) - np.repeat(np.cumsum(sub_counts) - sub_counts,
                                                        sub_counts)
    sub_width = widths[cell_of_sub] / np.repeat(sub_counts, sub_counts)
    sub_start = nodes[cell_of_sub] + offsets * sub_width
    s = (sub_start[:, None] + 0.5 * sub_width[:, None] * (points[None, :] + 1.0)).ravel()
    ds = (0.5 * sub_width[:, None] * weights[None, :]).ravel()
    cell = np.repeat(cell_of_sub, QUADRATURE_ORDER)
    t = (s - nodes[cell]) / widths[cell]
    rows = np.flatnonzero(resolved)
    block = beam_convolution_kernel(nodes[rows, None], s[None, :], w, profile) \
        * (s * ds)[None, :]
    # the hat functions of the two ends of each cell carry f's node values to the points
    hats = sparse.csr_matrix((np.concatenate([1.0 - t, t]),
                              (np.tile(np.arange(s.size), 2), np.concatenate([cell, cell + 1]))),
                             shape=(s.size, n))
    kernel_rows = np.asarray((hats.T @ block.T).T)
    kernel_matrix[rows] = kernel_rows
    return kernel_matrix


def _top_hat_rows(nodes: np.ndarray, rows: np.ndarray, radius: float) -> np.ndarray:
    """Rows of the top-hat convolution matrix, each integrated on its own breakpoints."""
    n = nodes.size
    out = np.zeros((rows.size, n))
    points, weights = np.polynomial.legendre.leggauss(TOP_HAT_POINTS)
    t = 0.5 * (points + 1.0)
    plain = (t, 0.5 * weights)
    # u = (1 - cos(pi t)) / 2 clusters the points at both ends, du = pi/2 sin(pi t) dt
    mapped = (0.5 * (1.0 - np.cos(np.pi * t)), 0.25 * np.pi * np.sin(np.pi * t) * weights)
    widths = np.diff(nodes)
    for index, row in enumerate(rows):
        rho = nodes[row]
        kinks = np.array([abs(rho - radius), rho + radius])
        low, high = max(rho - radius, 0.0), min(rho + radius, nodes[-1])
        if high <= low:
            continue
        inside = nodes[(nodes > low) & (nodes < high)]
        breaks = np.unique(np.concatenate([[low, high], inside,
                                           kinks[(kinks > low) & (kinks < high)]]))
        start, end = breaks[:-1], breaks[1:]
        at_kink = np.isclose(start[:, None], kinks[None, :], rtol=0, atol=1e-12).any(axis=1) \
            | np.isclose(end[:, None], kinks[None, :], rtol=0, atol=1e-12).any(axis=1)
        for use, (u, du) in ((~at_kink, plain), (at_kink, mapped)):
            if not use.any():
                continue
            span = (end - start)[use, None]
            s = start[use, None] + span * u[None, :]
            ds = span * du[None, :]
            s, ds = s.ravel(), ds.ravel()
            values = beam_convolution_kernel(rho, s, radius, "top_hat") * s * ds
            cell = np.clip(np.searchsorted(nodes, s, side="right") - 1, 0, n - 2)
            fraction = (s - nodes[cell]) / widths[cell]
            np.add.at(out[index], cell, values * (1.0 - fraction))
            np.add.at(out[index], cell + 1, values * fraction)
    return out
