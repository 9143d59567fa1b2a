r"""The parametric two-exponential profile of Sheng et al. 2014 (rose petals).

References
----------
Sheng, Shi, Wang, Narasimhan: Translucent radiosity. IEEE TVCG 20(7), 2014, Sect. 6.1.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ..homogeneous import rgb_field
from .base import RadialProfile, rgb_broadcast

__all__ = ["TwoExponentialProfile"]


class TwoExponentialProfile(RadialProfile):
    r"""The parametric profile :math:`s(r) = a_1 e^{-b_1 r} + a_2 e^{-b_2 r}` per channel.

    Sheng et al. 2014, Sect. 6.1 (the rose petals): reflection and, optionally,
    transmission each a sum of two exponentials. Total:
    :math:`2\pi(a_1/b_1^2 + a_2/b_2^2)`.

    Parameters
    ----------
    a1, a2 : float or RGB
        Amplitudes, mm^-2, >= 0.
    b1, b2 : float or RGB
        Decay rates, mm^-1, > 0.
    transmission : tuple (a1, b1, a2, b2), optional
        The transmission profile's parameters, same units.
    name : str, optional
    """

    model = "two_exponential"
    summary = "two exponentials a1 exp(-b1 r) + a2 exp(-b2 r) (Sheng et al. 2014, Sect. 6.1)"

    def __init__(self, a1, b1, a2=0.0, b2=1.0, *, transmission=None, name: str = ""):
        self.reflection_parameters = self._check((a1, b1, a2, b2), "reflection")
        self.transmission_parameters = None
        if transmission is not None:
            if len(transmission) != 4:
                raise InputError("must be (a1, b1, a2, b2)", field="transmission",
                                 value=transmission)
            self.transmission_parameters = self._check(transmission, "transmission")
        self.has_transmission = transmission is not None
        self.name = name or "two-exponential"

    @staticmethod
    def _check(parameters, kind):
        a1, b1, a2, b2 = parameters
        return (rgb_field(a1, f"{kind}.a1"), rgb_field(b1, f"{kind}.b1", strict=True),
                rgb_field(a2, f"{kind}.a2"), rgb_field(b2, f"{kind}.b2", strict=True))

    @staticmethod
    def _value(r, parameters):
        a1, b1, a2, b2 = parameters
        r = rgb_broadcast(r, a1)
        return a1 * np.exp(-b1 * r) + a2 * np.exp(-b2 * r)

    def reflection(self, r) -> np.ndarray:
        """:math:`a_1 e^{-b_1 r} + a_2 e^{-b_2 r}`, mm^-2."""
        return self._value(r, self.reflection_parameters)

    def transmission(self, r) -> np.ndarray:
        """Evaluate the transmission exponentials (0 when none were given)."""
        if self.transmission_parameters is None:
            return super().transmission(r)
        return self._value(r, self.transmission_parameters)

    def total(self, kind: str = "reflection", max_radius: float | None = None) -> np.ndarray:
        r"""Return the closed form :math:`2\pi(a_1/b_1^2 + a_2/b_2^2)` (integral to infinity)."""
        parameters = self.reflection_parameters if kind == "reflection" \
            else self.transmission_parameters
        if max_radius is None and parameters is not None:
            a1, b1, a2, b2 = parameters
            return 2.0 * np.pi * (a1 / b1**2 + a2 / b2**2)
        return super().total(kind, max_radius)

    def length_scale(self) -> np.ndarray:
        """Return the slower decay length 1/min(b1, b2) per channel, mm."""
        _, b1, a2, b2 = self.reflection_parameters
        return 1.0 / np.where(a2 > 0, np.minimum(b1, b2), b1)

    def cache_key(self) -> dict:
        """Return what identifies this profile in content hashes."""
        def listed(parameters):
            return None if parameters is None else [p.tolist() for p in parameters]
        return {"type": "two_exponential", "reflection": listed(self.reflection_parameters),
                "transmission": listed(self.transmission_parameters)}
