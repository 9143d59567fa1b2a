"""What the lights give, evaluated once for every method: the environment as Mitsuba sees it.

The fast methods and the reference must see the same light. Mitsuba's ``envmap`` looks a
direction up in the latitude-longitude map bilinearly between texel centres; a method that
took the nearest texel instead would be scored against light it was not given (measured on
a random 8 x 16 map: up to 0.70 of a texel's radiance off, 0.14 on average).
:func:`environment_radiance` is that lookup, tested against Mitsuba's own emitter
evaluation.
"""

from __future__ import annotations

import numpy as np

from .scene import ConstantEnvironment, ImageEnvironment

__all__ = ["ENVIRONMENT_LIGHTS", "environment_radiance"]

#: The environment lights (infinitely far, seen wherever a ray escapes).
ENVIRONMENT_LIGHTS = (ConstantEnvironment, ImageEnvironment)


def environment_radiance(light, directions) -> np.ndarray:
    r"""Radiance an environment light sends back along ``directions``, as Mitsuba evaluates it.

    Mitsuba's ``envmap`` maps a direction :math:`d` (pointing away from the scene) to
    :math:`u = \operatorname{atan2}(d_x, -d_z) / 2\pi \bmod 1`,
    :math:`v = \arccos(d_y) / \pi`, and interpolates bilinearly between texel centres at
    :math:`u = (j + 1/2) / W` (wrapping around in :math:`u`) and :math:`v = i / (H - 1)`
    (rows on the poles, clamped).

    Parameters
    ----------
    light : ConstantEnvironment or ImageEnvironment
    directions : array_like, shape (N, 3)
        Unit directions away from the scene.

    Returns
    -------
    ndarray, shape (N, 3), float64
        Radiance, W sr^-1 m^-2 (scene units), the image's ``scale`` applied.

    Examples
    --------
    >>> from translucent.scenes import ConstantEnvironment
    >>> environment_radiance(ConstantEnvironment([1.0, 0.5, 0.25]), [[0.0, 1.0, 0.0]])
    array([[1.  , 0.5 , 0.25]])
    """
    directions = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    if isinstance(light, ConstantEnvironment):
        return np.broadcast_to(np.asarray(light.radiance, dtype=np.float64),
                               directions.shape).copy()
    image = light.radiance.astype(np.float64) * light.scale
    height, width = image.shape[:2]
    u = (np.arctan2(directions[:, 0], -directions[:, 2]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(directions[:, 1], -1.0, 1.0)) / np.pi
    x = u * width - 0.5
    y = v * (height - 1)
    x0 = np.floor(x).astype(int)
    y0 = np.clip(np.floor(y).astype(int), 0, height - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    y1 = np.clip(y0 + 1, 0, height - 1)
    x0w, x1w = x0 % width, (x0 + 1) % width
    return ((1 - fy) * ((1 - fx) * image[y0, x0w] + fx * image[y0, x1w])
            + fy * ((1 - fx) * image[y1, x0w] + fx * image[y1, x1w]))
