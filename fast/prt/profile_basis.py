r"""The PCA basis of Wang et al. 2008 over another radial profile than the dipole.

Sect. 3.1 of the paper samples the dipole :math:`R_d(r; \sigma'_s, \sigma_a)` on 650
distances over a grid of coefficients and keeps the first K left singular vectors as the
basis :math:`b_k(r)` of Eq. 4 (:mod:`translucent.materials.dipole_pca`). With the knob
``profile`` another registered radial profile (:mod:`translucent.materials.profiles`) is
sampled instead, on the same distances and the same grid
(:func:`~translucent.materials.dipole_pca.decompose_family`), and a material is projected
by sampling its own profile (Sect. 3.3, step 3). The basis is built once per profile,
sampling and eta, and kept in the cache (namespace ``prt``).

Every grid point is a medium, made three at a time (one RGB medium per profile object):
the cost of a basis is the cost of making and evaluating ``sigma_samples**2 / 3`` profile
objects, which differs greatly from one profile to another; the measured
build times, and the profiles PRT refuses for theirs, are in docs/prt.md.

References
----------
Wang, Cheslack-Postava, Wang, Luebke, Chen, Hua, Peng, Bao: Real-time editing and
relighting of homogeneous translucent materials. The Visual Computer 24 (2008), Sect. 3.
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np

from ...errors import InputError
from ...materials.catalogue import MEASURED_MEDIA
from ...materials.dipole_pca import (
    BASIS_VERSION,
    PARAMETERISATIONS,
    DipolePCABasis,
    ProfileSampling,
    decompose_family,
)
from ...materials.homogeneous import Dipole
from ..knobs import RADIAL_AVERAGE, radial_profile

#: Bump when the sampled family changes meaning, so that cached bases miss.
FAMILY_VERSION = 1

#: Distances of the area-measure error (:func:`area_errors`), dense near 0 as in
#: :func:`~translucent.materials.dipole_pca.area_relative_error`.
ERROR_RADII = 4001


class ProfileFamily:
    r"""The registered radial profile ``name`` over media: :math:`R(r; \sigma_a, \sigma'_s, \eta)`.

    Called as ``family(radii, sigma_a, sigma_s_prime, eta)`` it samples the profiles of the
    m media (shape (m,) coefficients, mm^-1) at the distances (mm), shape (m, n), mm^-2:
    what :func:`~translucent.materials.dipole_pca.decompose_family` decomposes. Per unit
    power entering, as the dipole's :math:`R_d` (Eq. 6 of Wang et al. 2008 puts
    :math:`F_t` in the irradiance).

    A medium the profile refuses (an :class:`~translucent.errors.InputError`: no
    absorption for ``burley_dmfp``, eta beyond a table) or whose values are not finite is
    a zero row, counted in :attr:`refused`.

    Parameters
    ----------
    name : str
        A value of the ``profile`` knob.
    progress : tqdm bar, optional
        Advanced by the media sampled.
    """

    def __init__(self, name: str, progress=None):
        from ...materials.profiles.registry import PROFILES

        radial_profile(name, Dipole(0.01, 1.0, 1.3))  # an unknown or directional name fails
        base = name.removesuffix(RADIAL_AVERAGE)
        entry = PROFILES[base]
        # the registry's own maker, without its per-call argument checks (a basis makes
        # tens of thousands of profiles)
        self._make = (lambda medium: entry.make(medium).radial_average()) \
            if entry.directional else entry.make
        self.name = name
        self.progress = progress
        self.refused = 0

    def profile(self, medium: Dipole):
        """Return the radial profile of ``medium`` (a RadialProfile)."""
        return self._make(medium)

    def _rows(self, radii, sigma_a, sigma_s_prime, eta) -> np.ndarray | None:
        """Up to three media as one RGB medium: (count, n), None when refused."""
        count = len(sigma_a)
        pick = np.minimum(np.arange(3), count - 1)  # pad with the last medium
        try:
            values = self._make(Dipole(sigma_a[pick], sigma_s_prime[pick], eta)).reflection(radii)
        except InputError:
            return None
        values = values.T[:count]
        return values if np.all(np.isfinite(values)) else None

    def __call__(self, radii, sigma_a, sigma_s_prime, eta) -> np.ndarray:
        """Sample the profiles of the media at ``radii``: shape (m, n), mm^-2."""
        radii = np.asarray(radii, dtype=np.float64)
        sigma_a = np.ravel(np.asarray(sigma_a, dtype=np.float64))
        sigma_s_prime = np.ravel(np.asarray(sigma_s_prime, dtype=np.float64))
        out = np.zeros((sigma_a.size, radii.size))
        for start in range(0, sigma_a.size, 3):
            chosen = slice(start, min(start + 3, sigma_a.size))
            rows = self._rows(radii, sigma_a[chosen], sigma_s_prime[chosen], eta)
            if rows is None:  # one by one: one refused medium leaves the others
                rows = np.zeros((chosen.stop - start, radii.size))
                for i in range(start, chosen.stop):
                    row = self._rows(radii, sigma_a[i:i + 1], sigma_s_prime[i:i + 1], eta)
                    self.refused += row is None
                    rows[i - start] = 0.0 if row is None else row[0]
            out[chosen] = rows
        if self.progress is not None:
            self.progress.update(sigma_a.size)
        return out

    def cache_key(self) -> dict:
        """Return what identifies the family in content hashes."""
        return {"profile": self.name, "version": FAMILY_VERSION}


def basis_sampling(parameterisation: str, sigma_samples: int) -> ProfileSampling:
    """Return the preset sampling ``parameterisation`` at ``sigma_samples`` per axis."""
    return ProfileSampling(**{**asdict(PARAMETERISATIONS[parameterisation]),
                              "sigma_samples": sigma_samples})


#: Decompositions read or built in this process, by cache key (a few hundred kB each).
_DECOMPOSITIONS: dict = {}

#: The most decompositions :data:`_DECOMPOSITIONS` keeps, the oldest dropped first.
KEPT_DECOMPOSITIONS = 8


def family_basis(profile: str, parameterisation: str, eta: float, sigma_samples: int,
                 terms: int) -> tuple[DipolePCABasis, dict]:
    """Return the K-term basis of Sect. 3.1 over ``profile``'s family, and how it was had.

    Built by :func:`~translucent.materials.dipole_pca.decompose_family` with the preset
    sampling ``parameterisation`` at ``sigma_samples`` per axis and ``eta``, or read from
    the cache (namespace ``prt``, under the entry's lock) or from this process's memory.

    Returns
    -------
    basis : DipolePCABasis
    facts : dict
        ``cache`` ("hit" or "miss"), and ``build_seconds`` and ``refused_media`` when built.
    """
    from ...cache import Cache, content_hash
    from ...progress import progress_bar

    sampling = basis_sampling(parameterisation, sigma_samples)
    key = content_hash("prt-profile-basis", BASIS_VERSION, asdict(sampling), eta,
                       ProfileFamily(profile).cache_key())
    if key in _DECOMPOSITIONS:
        return DipolePCABasis(sampling, eta, *_DECOMPOSITIONS[key], terms), {"cache": "hit"}
    facts: dict = {}

    def build():
        started = time.perf_counter()
        with progress_bar(total=sampling.sigma_samples ** 2, unit="profile",
                          description=f"PCA basis of {profile}") as bar:
            family = ProfileFamily(profile, bar)
            decomposition = decompose_family(sampling, eta, family)
        facts.update(build_seconds=time.perf_counter() - started,
                     refused_media=family.refused)
        return decomposition

    stored, made = Cache("prt").load_or_make(
        key, build, what=f"the PCA basis of profile {profile!r}",
        valid=lambda value: isinstance(value, tuple) and len(value) == 4)
    facts["cache"] = "miss" if made else "hit"
    stored = tuple(np.asarray(array) for array in stored)
    for array in stored:
        array.flags.writeable = False
    if len(_DECOMPOSITIONS) >= KEPT_DECOMPOSITIONS:
        _DECOMPOSITIONS.pop(next(iter(_DECOMPOSITIONS)))
    _DECOMPOSITIONS[key] = stored
    return DipolePCABasis(sampling, eta, *stored, terms), facts


def project_profile_with_energy(basis: DipolePCABasis, profile):
    r"""Coefficients, residual and energies of a profile's projection (Sect. 3.3, step 3).

    :meth:`~translucent.materials.dipole_pca.DipolePCABasis.project_with_energy` for any
    radial profile: :math:`s_k = \sum_j w_j U_{jk} R(r_j)`, the residual
    :math:`(1 - \lVert s\rVert^2/\lVert wR\rVert^2)^{1/2}`, the K-term energy
    :math:`\sum_k s_k m_k` and the profile's own :math:`2\pi\int_0^{65} R\,r\,dr`
    (its :meth:`~translucent.materials.profiles.RadialProfile.total` to ``radius_max``).

    Parameters
    ----------
    basis : DipolePCABasis
    profile : RadialProfile
        RGB.

    Returns
    -------
    coefficients : ndarray, shape (3, K)
    residual, energy, exact_energy : ndarray, shape (3,)
    """
    values = profile.reflection(basis.radii).T  # (3, n)
    coefficients = basis.project_profile(values)
    norm = ((values * basis.weights) ** 2).sum(axis=-1)
    missed = np.clip(norm - (coefficients**2).sum(axis=-1), 0.0, None)
    residual = np.sqrt(np.divide(missed, norm, out=np.zeros_like(norm), where=norm > 0))
    exact_energy = profile.total(max_radius=basis.sampling.radius_max)
    return coefficients, np.minimum(residual, 1.0), coefficients @ basis.area_moments, \
        exact_energy


def area_errors(basis: DipolePCABasis, profile) -> tuple[np.ndarray, np.ndarray]:
    r"""Relative errors of the K-term projection of ``profile``, per channel, shape (3,) each.

    In the area measure on distances dense near 0 (as
    :func:`~translucent.materials.dipole_pca.area_relative_error` measures the dipole's):

    * L2, :math:`(\int_0^R(\tilde R - R)^2 r\,dr / \int_0^R R^2 r\,dr)^{1/2}`: dominated by
      the peak at r = 0, which it does not bound for a profile that diverges there
      (Burley's, the random walk's: :math:`R \sim 1/r`, so :math:`\int R^2 r\,dr` grows as
      the log of the smallest distance);
    * energy-weighted L1, :math:`\int_0^R|\tilde R - R|\,r\,dr / \int_0^R R\,r\,dr`: the
      fraction of the profile's energy misplaced, finite for every profile (what the
      transfer of Eq. 5 integrates).
    """
    t = np.linspace(0.0, 1.0, ERROR_RADII)
    radii = basis.sampling.radius_max * t * t
    measure = radii * np.gradient(radii)
    coefficients = basis.project_profile(profile.reflection(basis.radii).T)
    difference = basis.evaluate(radii) @ coefficients.T - profile.reflection(radii)  # (N, 3)
    exact = profile.reflection(radii)

    def relative(numerator, denominator):
        return np.divide(numerator, denominator, out=np.zeros_like(numerator),
                         where=denominator > 0)

    l2 = relative(np.sqrt((difference ** 2 * measure[:, None]).sum(axis=0)),
                  np.sqrt((exact ** 2 * measure[:, None]).sum(axis=0)))
    l1 = relative((np.abs(difference) * measure[:, None]).sum(axis=0),
                  (exact * measure[:, None]).sum(axis=0))
    return l2, l1


def basis_error_notes(basis: DipolePCABasis, profile: str, materials: dict) -> dict:
    """Return the basis's relative errors for the log: on measured media and the scene's.

    :func:`area_errors` over the 12 measured media of Jensen et al. 2001 x 3 channels
    (worst and median; those the profile refuses are named), each at its own eta, and per
    object of the scene (R, G, B).

    Parameters
    ----------
    basis : DipolePCABasis
    profile : str
        The knob's value.
    materials : dict
        Object name -> Dipole.
    """
    family = ProfileFamily(profile)
    measured, refused = [], []
    for medium, (sigma_s_prime, sigma_a, eta) in MEASURED_MEDIA.items():
        try:
            made = family.profile(Dipole(sigma_a, sigma_s_prime, eta))
        except InputError:  # burley_dmfp takes no medium without absorption (Spectralon)
            refused.append(medium)
            continue
        measured.append(area_errors(basis, made))
    measured = np.array(measured)
    objects = {name: area_errors(basis, family.profile(m)) for name, m in materials.items()}
    notes = {"profile": profile, "terms": basis.terms,
             "sigma_samples": basis.sampling.sigma_samples}
    if refused:
        notes["measured media the profile refuses"] = refused
    for index, measure in enumerate(("area relative L2", "energy relative L1")):
        values = measured[:, index]
        notes[f"measured media {measure}"] = {"worst": float(values.max()),
                                              "median": float(np.median(values))}
        notes[f"objects {measure}"] = {name: [float(v) for v in errors[index]]
                                       for name, errors in objects.items()}
    return notes
