"""The measured-media catalogue of Jensen et al. 2001.

Reduced scattering and absorption coefficients in mm^-1 (R, G, B), as printed in Table 1
of Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport
(SIGGRAPH 2001), and as carried by pbrt-v3 and pbrt-v4. eta = 1.3 for all but Marble
(1.5); g = 0 because the coefficients are reduced ones.

Mitsuba 0.6 prints the Chicken1 and Chicken2 red absorption as 0.0015 and 0.0018; we
take those as a typo for 0.015 and 0.018 (pbrt agrees).
"""

from __future__ import annotations

from ..errors import InputError
from .homogeneous import Dipole

__all__ = ["MEASURED_MEDIA", "measured_medium", "measured_medium_names"]

#: name -> (sigma_s' RGB in mm^-1, sigma_a RGB in mm^-1, eta). Jensen et al. 2001, Table 1.
MEASURED_MEDIA: dict[str, tuple[tuple[float, float, float], tuple[float, float, float], float]] = {
    "Apple": ((2.29, 2.39, 1.97), (0.0030, 0.0034, 0.046), 1.3),
    "Chicken1": ((0.15, 0.21, 0.38), (0.015, 0.077, 0.19), 1.3),
    "Chicken2": ((0.19, 0.25, 0.32), (0.018, 0.088, 0.20), 1.3),
    "Cream": ((7.38, 5.47, 3.15), (0.0002, 0.0028, 0.0163), 1.3),
    "Ketchup": ((0.18, 0.07, 0.03), (0.061, 0.97, 1.45), 1.3),
    "Marble": ((2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071), 1.5),
    "Potato": ((0.68, 0.70, 0.55), (0.0024, 0.0090, 0.12), 1.3),
    "Skimmilk": ((0.70, 1.22, 1.90), (0.0014, 0.0025, 0.0142), 1.3),
    "Skin1": ((0.74, 0.88, 1.01), (0.032, 0.17, 0.48), 1.3),
    "Skin2": ((1.09, 1.59, 1.79), (0.013, 0.070, 0.145), 1.3),
    "Spectralon": ((11.6, 20.4, 14.9), (0.0, 0.0, 0.0), 1.3),
    "Wholemilk": ((2.55, 3.21, 3.77), (0.0011, 0.0024, 0.014), 1.3),
}


def measured_medium_names() -> list[str]:
    """Return the catalogue's names, in table order."""
    return list(MEASURED_MEDIA)


def measured_medium(name: str) -> Dipole:
    """Return the measured medium ``name`` (case-insensitive) as a :class:`Dipole`.

    Raises
    ------
    InputError
        For an unknown name; the message lists the valid ones.
    """
    lookup = {key.lower(): key for key in MEASURED_MEDIA}
    key = lookup.get(str(name).strip().lower())
    if key is None:
        raise InputError(f"unknown measured material; valid names: {', '.join(MEASURED_MEDIA)}",
                         field="material", value=name)
    sigma_s_prime, sigma_a, eta = MEASURED_MEDIA[key]
    return Dipole(sigma_a=sigma_a, sigma_s_prime=sigma_s_prime, eta=eta, g=0.0, name=key)
