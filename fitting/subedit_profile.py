r"""The SubEdit scattering profile: piecewise-linear :math:`\ln P(r)` in ``n`` segments.

Eq. 9 of Chen et al. 2012 (after Song et al. 2009):

.. math::
    \ln P(r) = (1 - w)\hat P^k + w \hat P^{k+1},\qquad k r_s < r n < (k + 1) r_s,
    \quad w = n r / r_s - k,

with :math:`\hat P^k` the value at :math:`r_k = k r_s / n` and :math:`P = 0` beyond the
maximum scattering radius :math:`r_s`. For a homogeneous material Eq. 8 of Chen et al.
gives :math:`R_d(r) = \sqrt{P(r) P(r)} = P(r)`, so the fitted ``P`` plays the role of the
dipole's :math:`R_d`.

This is the minimal evaluation the fitter needs. ``materials/subedit.py`` (the per-texel
SubEdit material) is the place for the full representation; when it offers the same
evaluation, the fitter should call it instead of this module.
"""

from __future__ import annotations

import numpy as np

__all__ = ["subedit_log_profile", "subedit_knots"]


def subedit_knots(r_s_mm: float, segments: int) -> np.ndarray:
    """Knot radii :math:`r_k = k r_s / n`, k = 0..n, mm."""
    return np.linspace(0.0, float(r_s_mm), int(segments) + 1)


def subedit_log_profile(r, knot_values, r_s_mm):
    r"""Evaluate :math:`\ln P(r)` (Eq. 9 of Chen et al. 2012); ``-inf`` for :math:`r > r_s`.

    Parameters
    ----------
    r : array_like, shape (m,)
        Radii, mm, >= 0.
    knot_values : array_like, shape (..., n + 1)
        :math:`\hat P^0 \dots \hat P^n`, ln of the profile at the knots (ln mm^-2 when P is
        absolute).
    r_s_mm : float
        Maximum scattering radius, mm, > 0.

    Returns
    -------
    ndarray, shape (..., m)
        :math:`\ln P(r)`.
    """
    r = np.asarray(r, dtype=np.float64)
    knot_values = np.asarray(knot_values, dtype=np.float64)
    segments = knot_values.shape[-1] - 1
    position = r * segments / float(r_s_mm)
    k = np.clip(np.floor(position).astype(np.int64), 0, segments - 1)
    w = position - k
    value = (1.0 - w) * knot_values[..., k] + w * knot_values[..., k + 1]
    return np.where(r <= r_s_mm, value, -np.inf)
