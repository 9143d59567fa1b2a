r"""The measured media, found by name: Jensen et al. 2001 and Narasimhan et al. 2006.

Two published tables of homogeneous media, per RGB channel, coefficients in mm^-1:

* :data:`MEASURED_MEDIA`, the 12 media of Jensen et al. 2001, Table 1: reduced scattering
  and absorption coefficients as printed there and as pbrt-v3 and pbrt-v4 carry them.
  eta = 1.3 for all but Marble (1.5); g = 0 because the coefficients are reduced ones.
  Mitsuba 0.6 prints the Chicken1 and Chicken2 red absorption as 0.0015 and 0.0018; we take
  those as a typo for 0.015 and 0.018 (pbrt agrees).
* :data:`NARASIMHAN_MEDIA`, the 35 media of Narasimhan et al. 2006, Table 1 (liquids and
  powders measured by dilution: scattering, absorption and the Henyey-Greenstein mean
  cosine g per channel), at natural concentration, as pbrt-v4 (``src/pbrt/media.cpp``,
  ``GetMediumScatteringProperties``) and Mitsuba 0.6 (``src/medium/materials.h``) carry
  them. pbrt-v4 stores the reduced coefficient :math:`\sigma'_s = \sigma_s (1 - g)` and
  :math:`\sigma_a` to five significant digits; Mitsuba 0.6 stores :math:`\sigma_s`,
  :math:`\sigma_a` to five decimals (two or three significant digits for the clear drinks)
  and g to three decimals, with eta = 1.33 for all. We keep pbrt-v4's :math:`\sigma'_s` and
  :math:`\sigma_a`, Mitsuba 0.6's g and eta; :math:`\sigma_s = \sigma'_s / (1 - g)` then
  agrees with Mitsuba 0.6's to the two sources' roundings (``tests/materials``). The names
  are pbrt-v4's; Mitsuba 0.6 spells two of them "Budweiser Beder" and "Orange Juice
  Powder", which :data:`MEDIUM_ALIASES` accepts.

:func:`measured_medium` finds a name in either table (case-insensitive; spaces, ``_`` and
``-`` ignored, ``&`` read as "and": ``"lowfat_milk"``, ``"LowfatMilk"``) and returns the
:class:`~translucent.materials.homogeneous.Dipole`; :func:`measured_medium_entry` returns
the published row with its per-channel g. No name of one table folds onto a name of the
other.

A :class:`Dipole` keeps one g. For a medium whose g varies by channel it keeps the
published :math:`\sigma'_s` per channel exactly (all the diffusion profiles see) and the
one g of :func:`effective_g`, so that the path-traced reference's
:math:`\sigma_s = \sigma'_s / (1 - g)` keeps the channels' summed :math:`\sigma_s`.

References
----------
.. [1] H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan, "A practical model for
   subsurface light transport", SIGGRAPH 2001, Table 1.
.. [2] S. G. Narasimhan, M. Gupta, C. Donner, R. Ramamoorthi, S. K. Nayar, H. W. Jensen,
   "Acquiring scattering properties of participating media by dilution", ACM Trans.
   Graph. 25(3) (SIGGRAPH 2006), Table 1.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .homogeneous import Dipole, rgb_field

__all__ = [
    "MEASURED_MEDIA",
    "MEDIUM_ALIASES",
    "MEDIUM_TABLES",
    "NARASIMHAN_ETA",
    "NARASIMHAN_MEDIA",
    "MeasuredEntry",
    "canonical_medium_name",
    "effective_g",
    "measured_medium",
    "measured_medium_entry",
    "measured_medium_names",
]

RGB = tuple[float, float, float]

#: name -> (sigma_s' RGB in mm^-1, sigma_a RGB in mm^-1, eta). Jensen et al. 2001, Table 1.
MEASURED_MEDIA: dict[str, tuple[RGB, RGB, float]] = {
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

#: Relative index of refraction of every medium of :data:`NARASIMHAN_MEDIA` (water's, as
#: Mitsuba 0.6 gives it).
NARASIMHAN_ETA = 1.33

#: name -> (sigma_s' RGB in mm^-1, sigma_a RGB in mm^-1, g RGB). Narasimhan et al. 2006,
#: Table 1, at natural concentration: sigma_s' = sigma_s (1 - g) and sigma_a as pbrt-v4's
#: media.cpp prints them, g as Mitsuba 0.6's materials.h does (0 where nothing scatters).
NARASIMHAN_MEDIA: dict[str, tuple[RGB, RGB, RGB]] = {
    "Lowfat Milk": ((0.89187, 1.5136, 2.532), (0.002875, 0.00575, 0.0115),
                    (0.932, 0.902, 0.859)),
    "Reduced Milk": ((2.4858, 3.1669, 4.5214), (0.0025556, 0.0051111, 0.012778),
                     (0.819, 0.797, 0.746)),
    "Regular Milk": ((4.5513, 5.8294, 7.136), (0.0015333, 0.0046, 0.019933),
                     (0.75, 0.714, 0.681)),
    "Espresso": ((0.72378, 0.84557, 1.0247), (4.7984, 6.5751, 8.8493),
                 (0.907, 0.896, 0.88)),
    "Mint Mocha Coffee": ((0.31602, 0.38538, 0.48131), (3.772, 5.8228, 7.82),
                          (0.91, 0.907, 0.914)),
    "Lowfat Soy Milk": ((0.30576, 0.34233, 0.61664), (0.0014375, 0.0071875, 0.035937),
                        (0.85, 0.853, 0.842)),
    "Regular Soy Milk": ((0.59223, 0.73866, 1.4693), (0.0019167, 0.0095833, 0.065167),
                         (0.873, 0.858, 0.832)),
    "Lowfat Chocolate Milk": ((0.64925, 0.83916, 1.1057), (0.0115, 0.0368, 0.1564),
                              (0.934, 0.927, 0.916)),
    "Regular Chocolate Milk": ((1.4585, 2.1289, 2.9527), (0.010063, 0.043125, 0.14375),
                               (0.862, 0.838, 0.806)),
    "Coke": ((8.9053e-05, 8.372e-05, 0), (0.10014, 0.16503, 0.2468),
             (0.965, 0.972, 0.0)),
    "Pepsi": ((6.1697e-05, 4.2564e-05, 0), (0.091641, 0.14158, 0.20729),
              (0.926, 0.979, 0.0)),
    "Sprite": ((6.0306e-06, 6.4139e-06, 6.5504e-06), (0.001886, 0.0018308, 0.0020025),
               (0.943, 0.953, 0.952)),
    "Gatorade": ((0.0024574, 0.003007, 0.0037325), (0.024794, 0.019289, 0.008878),
                 (0.933, 0.933, 0.935)),
    "Chardonnay": ((1.7982e-05, 1.3758e-05, 1.2023e-05), (0.010782, 0.011855, 0.023997),
                   (0.914, 0.958, 0.975)),
    "White Zinfandel": ((1.7501e-05, 1.9069e-05, 1.288e-05), (0.012072, 0.016184, 0.019843),
                        (0.919, 0.943, 0.972)),
    "Merlot": ((2.1129e-05, 0, 0), (0.11632, 0.25191, 0.29434),
               (0.974, 0.0, 0.0)),
    "Budweiser Beer": ((2.4356e-05, 2.4079e-05, 1.0564e-05), (0.011492, 0.024911, 0.057786),
                       (0.917, 0.956, 0.982)),
    "Coors Light Beer": ((5.0922e-05, 4.301e-05, 0), (0.006164, 0.013984, 0.034983),
                         (0.918, 0.966, 0.0)),
    "Clorox": ((0.0024035, 0.0031373, 0.003991), (0.0033542, 0.014892, 0.026297),
               (0.912, 0.905, 0.892)),
    "Apple Juice": ((0.00013612, 0.00015836, 0.000227), (0.012957, 0.023741, 0.052184),
                    (0.947, 0.949, 0.945)),
    "Cranberry Juice": ((0.00010402, 0.00011646, 7.8139e-05), (0.039437, 0.094223, 0.12426),
                        (0.947, 0.951, 0.974)),
    "Grape Juice": ((5.382e-05, 0, 0), (0.10404, 0.23958, 0.29325),
                    (0.961, 0.0, 0.0)),
    "Ruby Grapefruit Juice": ((0.011002, 0.010927, 0.011036), (0.085867, 0.18314, 0.25262),
                              (0.929, 0.929, 0.931)),
    "White Grapefruit Juice": ((0.22826, 0.23998, 0.32748), (0.0138, 0.018831, 0.056781),
                               (0.548, 0.545, 0.565)),
    "Shampoo": ((0.0007176, 0.0008303, 0.0009016), (0.014107, 0.045693, 0.061717),
                (0.91, 0.905, 0.92)),
    "Strawberry Shampoo": ((0.00015671, 0.00015947, 1.518e-05), (0.01449, 0.05796, 0.075823),
                           (0.927, 0.935, 0.994)),
    "Head & Shoulders Shampoo": ((0.023805, 0.028804, 0.034306), (0.084621, 0.15688, 0.20365),
                                 (0.911, 0.896, 0.884)),
    "Lemon Tea Powder": ((0.040224, 0.045264, 0.051081), (2.4288, 4.5757, 7.2127),
                         (0.946, 0.946, 0.949)),
    "Orange Powder": ((0.00015617, 0.00017482, 0.0001762), (0.001449, 0.003441, 0.007863),
                      (0.919, 0.918, 0.922)),
    "Pink Lemonade Powder": ((0.00012103, 0.00013073, 0.00012528), (0.001165, 0.002366, 0.003195),
                             (0.902, 0.902, 0.904)),
    "Cappuccino Powder": ((1.8436, 2.5851, 2.1662), (35.844, 49.547, 61.084),
                          (0.849, 0.843, 0.926)),
    "Salt Powder": ((0.027333, 0.032451, 0.031979), (0.28415, 0.3257, 0.34148),
                    (0.802, 0.793, 0.821)),
    "Sugar Powder": ((0.00022272, 0.00025513, 0.000271), (0.012638, 0.031051, 0.050124),
                     (0.921, 0.919, 0.931)),
    "Suisse Mocha Powder": ((2.7979, 3.5452, 4.3365), (17.502, 27.004, 35.433),
                            (0.907, 0.894, 0.888)),
    "Pacific Ocean Surface Water": ((0.0001764, 0.00032095, 0.00019617),
                                    (0.031845, 0.031324, 0.030147), (0.902, 0.825, 0.914)),
}

#: Other spellings -> name in :data:`NARASIMHAN_MEDIA`: Mitsuba 0.6's names for two media.
MEDIUM_ALIASES: dict[str, str] = {
    "Budweiser Beder": "Budweiser Beer",
    "Orange Juice Powder": "Orange Powder",
}

#: The values :func:`measured_medium_names` takes.
MEDIUM_TABLES = ("jensen2001", "narasimhan2006", "all")


def _folded(name) -> str:
    """Return ``name`` as the lookup compares it: lower case, "&" as "and", no " ", "_", "-"."""
    return re.sub(r"[\s_-]+", "", str(name).strip().lower().replace("&", "and"))


_LOOKUP: dict[str, str] = {_folded(name): name for name in (*MEASURED_MEDIA, *NARASIMHAN_MEDIA)}
_LOOKUP.update({_folded(alias): name for alias, name in MEDIUM_ALIASES.items()})


def effective_g(sigma_s_prime, g) -> float:
    r"""Return the one mean cosine that stands for a per-channel g.

    .. math:: \bar g = \frac{\sum_c \sigma_{s,c}\, g_c}{\sum_c \sigma_{s,c}},
              \qquad \sigma_{s,c} = \frac{\sigma'_{s,c}}{1 - g_c},

    the g for which :math:`\sum_c \sigma'_{s,c} / (1 - \bar g) = \sum_c \sigma_{s,c}`:
    keeping every channel's :math:`\sigma'_s` and this g keeps the channels' summed
    :math:`\sigma_s`. A channel that does not scatter has no say.

    Parameters
    ----------
    sigma_s_prime : (3,) array_like
        Reduced scattering coefficient per channel, mm^-1, >= 0.
    g : (3,) array_like
        Mean cosine per channel, in (-1, 1).

    Returns
    -------
    float
        :math:`\bar g`, in the range of ``g``; 0 when no channel scatters.
    """
    sigma_s_prime = np.asarray(sigma_s_prime, dtype=np.float64)
    g = np.asarray(g, dtype=np.float64)
    sigma_s = sigma_s_prime / (1.0 - g)
    total = float(sigma_s.sum())
    return float((sigma_s * g).sum() / total) if total > 0 else 0.0


@dataclass(frozen=True, eq=False)
class MeasuredEntry:
    r"""One row of a measured-media table, per RGB channel, as published.

    Parameters
    ----------
    name : str
        The table's name of the medium ("Marble", "Lowfat Milk").
    table : str
        ``"jensen2001"`` or ``"narasimhan2006"``.
    sigma_s_prime : (3,) array_like
        Reduced scattering coefficient :math:`\sigma'_s = \sigma_s (1 - g)`, mm^-1.
    sigma_a : (3,) array_like
        Absorption coefficient, mm^-1.
    g : (3,) array_like
        Henyey-Greenstein mean cosine per channel, in [0, 1) (0 for Jensen et al. 2001,
        whose coefficients are reduced ones).
    eta : float
        Relative index of refraction of the boundary.
    """

    name: str
    table: str
    sigma_s_prime: np.ndarray
    sigma_a: np.ndarray
    g: np.ndarray
    eta: float

    def __post_init__(self):
        for field in ("sigma_s_prime", "sigma_a", "g"):
            object.__setattr__(self, field, rgb_field(getattr(self, field), field))

    @property
    def sigma_s(self) -> np.ndarray:
        r"""Scattering coefficient per channel, :math:`\sigma'_s / (1 - g)`, mm^-1."""
        return self.sigma_s_prime / (1.0 - self.g)

    def dipole(self) -> Dipole:
        """Return the medium as a :class:`Dipole` (its one g from :func:`effective_g`)."""
        return Dipole(sigma_a=self.sigma_a, sigma_s_prime=self.sigma_s_prime, eta=self.eta,
                      g=effective_g(self.sigma_s_prime, self.g), name=self.name)


def measured_medium_names(table: str = "jensen2001") -> list[str]:
    """Return the names of a measured-media table, in table order.

    Parameters
    ----------
    table : {"jensen2001", "narasimhan2006", "all"}
        Jensen et al. 2001's 12 media (the default, the set the benchmarks and the fitting
        validation run over), Narasimhan et al. 2006's 35, or both (Jensen's first).

    Returns
    -------
    list of str

    Raises
    ------
    InputError
        An unknown ``table``; the message lists the valid ones.
    """
    if table == "jensen2001":
        return list(MEASURED_MEDIA)
    if table == "narasimhan2006":
        return list(NARASIMHAN_MEDIA)
    if table == "all":
        return [*MEASURED_MEDIA, *NARASIMHAN_MEDIA]
    raise InputError(f"unknown table of measured media; valid: {', '.join(MEDIUM_TABLES)}",
                     field="table", value=table)


def canonical_medium_name(name) -> str | None:
    """Return the table's spelling of a measured medium's name, or None when there is none.

    Case, spaces, ``_`` and ``-`` do not matter, ``&`` reads as "and", and the spellings of
    :data:`MEDIUM_ALIASES` are accepted: ``"lowfat_milk"`` gives ``"Lowfat Milk"``.
    """
    return _LOOKUP.get(_folded(name))


def measured_medium_entry(name: str) -> MeasuredEntry:
    """Return the published row of the measured medium ``name``, per channel.

    Parameters
    ----------
    name : str
        A name of either table, matched as :func:`canonical_medium_name` does.

    Returns
    -------
    MeasuredEntry

    Raises
    ------
    InputError
        For an unknown name; the message lists the valid ones.
    """
    key = canonical_medium_name(name)
    if key is None:
        raise InputError("unknown measured material; valid names: "
                         f"{', '.join(measured_medium_names('all'))}", field="material",
                         value=name)
    if key in MEASURED_MEDIA:
        sigma_s_prime, sigma_a, eta = MEASURED_MEDIA[key]
        return MeasuredEntry(key, "jensen2001", sigma_s_prime, sigma_a, 0.0, eta)
    sigma_s_prime, sigma_a, g = NARASIMHAN_MEDIA[key]
    return MeasuredEntry(key, "narasimhan2006", sigma_s_prime, sigma_a, g, NARASIMHAN_ETA)


def measured_medium(name: str) -> Dipole:
    """Return the measured medium ``name`` as a :class:`Dipole`.

    Parameters
    ----------
    name : str
        A name of Jensen et al. 2001's or Narasimhan et al. 2006's table ("Marble",
        "Lowfat Milk"), matched as :func:`canonical_medium_name` does.

    Returns
    -------
    Dipole
        Coefficients in mm^-1 and the table's eta. Jensen et al. 2001's media have g = 0;
        Narasimhan et al. 2006's keep their reduced coefficients and the g of
        :func:`effective_g`.

    Raises
    ------
    InputError
        For an unknown name; the message lists the valid ones.
    """
    return measured_medium_entry(name).dipole()
