r"""A measured beam: the beam's own image on a white diffuse target, as the forward model's kernel.

A lab beam is rarely an exact Gaussian or top hat. A capture may give an image of the beam
itself (``beam_profile = "measured"``, ``beam_image``: the same camera and pixel size, the
beam on a white diffuse target such as Spectralon or matte paper, whose own blur is far
below a pixel). :func:`measure_beam` turns it into a radially symmetric irradiance
:math:`B(\rho)`: the background (the median of the image's one-pixel border) removed, the
centre found as the fitter finds the incident point (the thresholded centroid), and the
mean over rings a quarter of a pixel wide, normalised to integrate to 1, out to where the rings fall
below :data:`BEAM_FLOOR` of the peak.

The kernel. :math:`B` is constant on each ring :math:`[a_{k-1}, a_k]`, so it is a sum of
uniform disks,

.. math:: B = \sum_k w_k\, U_{a_k}, \qquad w_k = \pi a_k^2 (b_k - b_{k+1}), \qquad
          \sum_k w_k = 1,

with :math:`U_a` the normalised top hat of radius :math:`a`, whose exact convolution
matrix :func:`~translucent.fitting.beam.beam_convolution_matrix` already builds; the
measured beam's matrix is the same sum of theirs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .beam import beam_convolution_matrix
from .geometry import RadialGrid

__all__ = ["BEAM_FLOOR", "MeasuredBeam", "measure_beam"]

#: Width of the rings the beam is averaged over, pixels of its image: narrower than a
#: pixel, since pixel centres fall at all radii (a top hat's edge is then placed to a
#: fraction of a pixel, not smeared over a whole one).
RING_WIDTH_PX = 0.25
#: Rings below this fraction of the peak ring are taken as no light (the noise floor).
BEAM_FLOOR = 1e-3


@dataclass(frozen=True)
class MeasuredBeam:
    """A radially symmetric beam irradiance, piecewise constant on rings.

    Attributes
    ----------
    edges_mm : ndarray, shape (K + 1,)
        Ring edges from 0, mm.
    irradiance : ndarray, shape (K,)
        :math:`B` on each ring, mm^-2 (integral 1).
    centre_px : (float, float)
        Where the beam's centre lies in its image.
    """

    edges_mm: np.ndarray
    irradiance: np.ndarray
    centre_px: tuple[float, float]

    @property
    def disk_weights(self) -> np.ndarray:
        """Weights :math:`w_k` of the uniform disks of radii ``edges_mm[1:]`` (sum 1)."""
        outer = self.edges_mm[1:]
        following = np.concatenate([self.irradiance[1:], [0.0]])
        return np.pi * outer ** 2 * (self.irradiance - following)

    @property
    def radius_mm(self) -> float:
        """Radius holding 99 % of the beam's power, mm."""
        power = np.cumsum(self.irradiance * np.pi * np.diff(self.edges_mm ** 2))
        return float(self.edges_mm[1:][np.searchsorted(power, 0.99 * power[-1])])

    def convolution_matrix(self, grid: RadialGrid) -> np.ndarray:
        """Matrix ``K`` with ``(B * f)(nodes) = K @ f(nodes)`` (the sum of the disks' matrices)."""
        matrix = np.zeros((grid.size, grid.size))
        for radius, weight in zip(self.edges_mm[1:], self.disk_weights, strict=True):
            if weight != 0.0:
                matrix += weight * beam_convolution_matrix(grid, float(radius), "top_hat")
        return matrix


def measure_beam(image, pixel_size_mm: float, *, path=None) -> MeasuredBeam:
    """Radial irradiance of a beam image (see the module docstring).

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Linear values (the channels are summed).
    pixel_size_mm : float
        The capture's pixel size.
    path : path, optional
        The image's file, for messages.

    Returns
    -------
    MeasuredBeam

    Raises
    ------
    InputError
        An image with no light above its border, or a beam that reaches the image border.
    """
    from .incident_point import refine_incident_point

    values = np.asarray(image, dtype=np.float64)
    if values.ndim == 3:
        values = values.sum(axis=2)
    values = np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)
    border = np.concatenate([values[0], values[-1], values[1:-1, 0], values[1:-1, -1]])
    signal = values - float(np.median(border))
    height, width = signal.shape
    if not signal.max() > 0:
        raise InputError("the beam image holds no light above its border", file=path,
                         field="beam_image")
    iy, ix = np.unravel_index(int(np.argmax(signal)), signal.shape)
    centre = refine_incident_point(signal, (ix + 0.5, iy + 0.5),
                                   search_radius_px=max(height, width))
    ys, xs = np.mgrid[0:height, 0:width]
    radius = np.hypot(xs + 0.5 - centre[0], ys + 0.5 - centre[1])
    reach = min(centre[0], width - centre[0], centre[1], height - centre[1])
    rings = int(np.floor(reach / RING_WIDTH_PX))
    if rings < 8:
        raise InputError("the beam's centre lies on the image border", file=path,
                         field="beam_image", value=list(centre))
    index = np.floor(radius / RING_WIDTH_PX).astype(np.int64)
    inside = index < rings
    sums = np.bincount(index[inside], signal[inside], minlength=rings)
    counts = np.bincount(index[inside], minlength=rings)
    # a ring no pixel centre falls in (near the centre) takes its neighbours' values
    filled = counts > 0
    middle = (np.arange(rings) + 0.5) * RING_WIDTH_PX
    ring_mean = np.interp(middle, middle[filled], sums[filled] / counts[filled])
    # the beam ends at the first ring below the floor
    low = np.flatnonzero(ring_mean < BEAM_FLOOR * ring_mean.max())
    end = int(low[0]) if low.size else rings
    if end >= rings and ring_mean[-1] > 10 * BEAM_FLOOR * ring_mean.max():
        raise InputError("the beam reaches the image border: its image must hold all of it",
                         file=path, field="beam_image", value=[width, height])
    edges = np.arange(end + 1, dtype=np.float64) * RING_WIDTH_PX * pixel_size_mm
    ring_mean = np.clip(ring_mean[:end], 0.0, None)
    power = np.sum(ring_mean * np.pi * np.diff(edges ** 2))
    return MeasuredBeam(edges_mm=edges, irradiance=ring_mean / power,
                        centre_px=(float(centre[0]), float(centre[1])))
