r"""A PCA basis for the dipole profile :math:`R_d(r)`, and its analysis.

Sect. 3.1 and Fig. 4 of Wang et al. 2008: sample :math:`R_d(r, \sigma)` (Eq. 2-3) on
650 uniform distances in [0, 65] mm over a grid of :math:`(\sigma'_s, \sigma_a)`, take the
SVD of the sampled matrix, and keep the first K left singular vectors as 1D basis
functions :math:`b_k(r)` (Eq. 4). Any profile is then projected onto the basis,
:math:`s_k(\sigma) = \int R_d(r, \sigma) b_k(r)\,dr` (Sect. 3.3, step 3), so that
:math:`R_d(r, \sigma) \approx \sum_k b_k(r) s_k(\sigma)`.

Two ways of sampling the profiles are offered (:data:`PARAMETERISATIONS`):

``"paper"``
    As in the paper: raw samples at 650 uniform distances, a linear grid over
    :math:`\sigma'_s, \sigma_a \in [0, 5]` mm^-1.
``"area_normalised"``
    The same number of distances, warped as :math:`r = R (u)^2` with u uniform (dense
    near the origin, where the profiles of dense media live); each sample weighted by
    :math:`\sqrt{r\,\Delta r}` so that the Euclidean norm of a sampled profile is its L2
    norm in the area measure :math:`r\,dr` in which a profile is integrated over a
    surface (Eq. 5); every profile scaled to unit norm (the SVD then serves thin and
    dense media alike, instead of being dominated by the largest profiles, whose
    magnitude grows as :math:`\sigma_t'^2`); and a logarithmic grid over the measured
    range of Jensen et al. 2001 with slack.

:func:`compare_parameterisations` measures both on the same footing;
:func:`terms_to_match` finds how many terms of one reach the other's 12-term error.

All lengths are in mm and coefficients in mm^-1.

References
----------
Wang, Cheslack-Postava, Wang, Luebke, Chen, Hua, Peng, Bao: Real-time editing and
relighting of homogeneous translucent materials. The Visual Computer 24 (2008).
Jensen, Marschner, Levoy, Hanrahan: A practical model for subsurface light transport.
SIGGRAPH 2001 (the dipole and the measured table).
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, check_count, check_finite
from .catalogue import MEASURED_MEDIA
from .dipole import (
    dipole_depths,
    dipole_reflectance_profile,
    effective_transport_coefficient,
    reduced_albedo,
)

__all__ = [
    "PARAMETERISATIONS",
    "ProfileSampling",
    "DipolePCABasis",
    "dipole_pca_basis",
    "decompose_family",
    "truncated_diffuse_reflectance",
    "singular_value_roots",
    "leading_basis_functions",
    "approximation_error_maps",
    "area_relative_error",
    "measured_profile_errors",
    "compare_parameterisations",
    "terms_to_match",
    "write_analysis_figure",
    "write_shipped_basis",
]

#: Bumped whenever the sampling or the decomposition changes, so that cached bases miss.
BASIS_VERSION = 1

#: Number of leading singular vectors stored with a basis (more than anyone asks for:
#: Fig. 4a of Wang et al. 2008 shows 15).
STORED_TERMS = 32

#: Profiles per block of the streamed decomposition (memory ~ block x 650 x 8 bytes).
PROFILES_PER_BLOCK = 8192

#: The sampled profiles are kept in memory between the two passes of the decomposition
#: when they take at most this much (the default 256^2 grid takes 340 MB); larger grids
#: are sampled twice instead.
PROFILE_MEMORY_BYTES = 512 * 2**20

#: Default number of samples per axis of the (sigma_s', sigma_a) grid: 256^2 = 65536
#: profiles (340 MB held in memory). Measured: going to 512^2 leaves the worst 12-term
#: error over the measured media unchanged and its median within 1e-5 (both samplings).
DEFAULT_SIGMA_SAMPLES = 256


@dataclass(frozen=True)
class ProfileSampling:
    r"""How the dipole profiles are sampled into the matrix whose SVD gives the basis.

    Parameters
    ----------
    name : str
        Label (a key of :data:`PARAMETERISATIONS` for the presets).
    distance_warp : {"uniform", "sqrt"}
        ``"uniform"``: :math:`r_j = j R / (n - 1)` (the paper). ``"sqrt"``:
        :math:`r_j = R\,((j + 1/2)/n)^2`, dense near the origin.
    measure : {"samples", "area"}
        ``"samples"``: raw values :math:`R_d(r_j)` (the paper). ``"area"``: values
        weighted by :math:`\sqrt{r_j \Delta r_j}` (L2 in the area measure).
    normalise : bool
        Scale every sampled profile to unit norm before the SVD.
    sigma_spacing : {"linear", "log"}
        Spacing of the coefficient grid.
    sigma_s_prime_range, sigma_a_range : (float, float)
        Grid ranges in mm^-1 (inclusive); a log grid needs a positive lower end.
    sigma_samples : int
        Grid samples per axis (the grid has ``sigma_samples**2`` profiles).
    distance_samples : int
        Number of distances n (650 in the paper).
    radius_max : float
        Largest distance R in mm (65 in the paper); the basis is 0 beyond it.
    """

    name: str
    distance_warp: str = "uniform"
    measure: str = "samples"
    normalise: bool = False
    sigma_spacing: str = "linear"
    sigma_s_prime_range: tuple[float, float] = (0.0, 5.0)
    sigma_a_range: tuple[float, float] = (0.0, 5.0)
    sigma_samples: int = DEFAULT_SIGMA_SAMPLES
    distance_samples: int = 650
    radius_max: float = 65.0

    def __post_init__(self):
        choices = {"distance_warp": ("uniform", "sqrt"), "measure": ("samples", "area"),
                   "sigma_spacing": ("linear", "log")}
        for field_name, valid in choices.items():
            if getattr(self, field_name) not in valid:
                raise InputError(f"must be one of {', '.join(valid)}", field=field_name,
                                 value=getattr(self, field_name))
        for field_name in ("sigma_s_prime_range", "sigma_a_range"):
            lo, hi = (float(v) for v in check_finite(getattr(self, field_name), field_name))
            if not 0 <= lo < hi or (self.sigma_spacing == "log" and lo <= 0):
                raise InputError("must be (low, high) with 0 <= low < high (low > 0 for a log "
                                 "grid), mm^-1", field=field_name, value=getattr(self, field_name))
            object.__setattr__(self, field_name, (lo, hi))
        for field_name, least in (("sigma_samples", 2), ("distance_samples", 16)):
            value = getattr(self, field_name)
            object.__setattr__(self, field_name, check_count(value, field_name, least))
        radius_max = float(check_finite(self.radius_max, "radius_max"))
        if radius_max <= 0:
            raise InputError("must be > 0 mm", field="radius_max", value=self.radius_max)
        object.__setattr__(self, "radius_max", radius_max)

    def radii_and_weights(self) -> tuple[np.ndarray, np.ndarray]:
        r"""Return the distances :math:`r_j` (mm) and weights :math:`w_j` of :math:`R_d(r_j)`."""
        n, radius = self.distance_samples, self.radius_max
        if self.distance_warp == "uniform":
            radii = np.linspace(0.0, radius, n)
            spacing = np.full(n, radius / (n - 1))
        else:
            u = (np.arange(n) + 0.5) / n
            radii = radius * u * u
            spacing = 2.0 * radius * u / n
        weights = np.ones(n) if self.measure == "samples" else np.sqrt(radii * spacing)
        return radii, weights

    def sigma_grids(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the grid axes ``(sigma_s_prime, sigma_a)``, mm^-1."""
        space = np.linspace if self.sigma_spacing == "linear" else np.geomspace
        return (space(*self.sigma_s_prime_range, self.sigma_samples),
                space(*self.sigma_a_range, self.sigma_samples))

    def grid_coordinate(self, r) -> np.ndarray:
        """Fractional sample index of distances ``r`` (mm): the inverse of the warp."""
        r = np.asarray(r, dtype=np.float64)
        n, radius = self.distance_samples, self.radius_max
        if self.distance_warp == "uniform":
            return r * ((n - 1) / radius)
        return n * np.sqrt(np.maximum(r, 0.0) / radius) - 0.5


#: The two preset samplings: the paper's and the one that needs fewer terms.
PARAMETERISATIONS: dict[str, ProfileSampling] = {
    "paper": ProfileSampling("paper"),
    "area_normalised": ProfileSampling(
        "area_normalised", distance_warp="sqrt", measure="area", normalise=True,
        sigma_spacing="log", sigma_s_prime_range=(0.02, 25.0), sigma_a_range=(1e-4, 5.0)),
}


def _sampling(parameterisation) -> ProfileSampling:
    if isinstance(parameterisation, ProfileSampling):
        return parameterisation
    if parameterisation not in PARAMETERISATIONS:
        raise InputError(f"unknown parameterisation; valid: {', '.join(PARAMETERISATIONS)}",
                         field="parameterisation", value=parameterisation)
    return PARAMETERISATIONS[parameterisation]


def _check_eta(eta, field: str = "eta") -> np.ndarray:
    eta = check_finite(eta, field)
    if ((eta < 1.0) | (eta > 3.0)).any():
        raise InputError("must be in [1, 3]", field=field, value=eta.tolist())
    return eta


def _check_coefficient(value, field: str) -> np.ndarray:
    array = check_finite(value, field)
    if (array < 0).any():
        raise InputError("must be >= 0 mm^-1", field=field, value=array.tolist())
    return array


@dataclass(frozen=True, eq=False)
class DipolePCABasis:
    r"""The first K PCA basis functions :math:`b_k(r)` of the dipole profile (Eq. 4).

    Build it with :func:`dipole_pca_basis`. The stored singular vectors :math:`U` are
    orthonormal in the weighted sampling; the basis functions are
    :math:`b_k(r_j) = U_{jk} / w_j`, linear in between, 0 beyond ``radius_max``.

    Attributes
    ----------
    sampling : ProfileSampling
    eta : float
        Index of refraction the sampled profiles used.
    radii, weights : ndarray, shape (n,)
        Sample distances (mm) and weights (see :meth:`ProfileSampling.radii_and_weights`).
    vectors : ndarray, shape (n, STORED_TERMS)
        Orthonormal left singular vectors, in order.
    singular_values : ndarray
        All singular values of the sampled matrix, decreasing.
    terms : int
        K, the number of basis functions used by :meth:`evaluate` and :meth:`project`.
    """

    sampling: ProfileSampling
    eta: float
    radii: np.ndarray
    weights: np.ndarray
    vectors: np.ndarray
    singular_values: np.ndarray
    terms: int = 12

    def __post_init__(self):
        if int(self.terms) != self.terms or not 1 <= self.terms <= self.vectors.shape[1]:
            raise InputError(f"must be an integer in [1, {self.vectors.shape[1]}]",
                             field="terms", value=self.terms)
        object.__setattr__(self, "terms", int(self.terms))
        functions = self.vectors[:, : self.terms] / self.weights[:, None]
        # the table carries a zero row past the last distance: b_k(r) = 0 beyond radius_max
        table = np.vstack([functions, np.zeros((1, self.terms))])
        projector = (self.vectors[:, : self.terms] * self.weights[:, None]).T.copy()
        for name, value in (("table", table), ("projector", projector)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)

    @property
    def name(self) -> str:
        """The sampling's name (``"paper"`` or ``"area_normalised"`` for the presets)."""
        return self.sampling.name

    def truncated(self, terms: int) -> DipolePCABasis:
        """Return the same basis with ``terms`` functions (up to :data:`STORED_TERMS`)."""
        return DipolePCABasis(self.sampling, self.eta, self.radii, self.weights, self.vectors,
                              self.singular_values, terms)

    def evaluate(self, r) -> np.ndarray:
        r"""Basis functions :math:`b_k(r)`, shape ``r.shape + (K,)``.

        Linear interpolation between the sampled distances; 0 beyond ``radius_max`` mm (the
        transfer beyond 65 mm is dropped, as in Sect. 3.1 of Wang et al. 2008).

        Parameters
        ----------
        r : array_like
            Distances in mm, >= 0.
        """
        coordinate = self.sampling.grid_coordinate(r)
        last = self.radii.size - 1
        coordinate = np.where(np.asarray(r) > self.sampling.radius_max, last + 1.0,
                              np.clip(coordinate, 0.0, last))
        index = np.minimum(coordinate.astype(np.int64), last)
        fraction = (coordinate - index)[..., None]
        return self.table[index] * (1.0 - fraction) + self.table[index + 1] * fraction

    def project(self, sigma_a, sigma_s_prime, eta=None) -> np.ndarray:
        r"""Coefficients :math:`s_k(\sigma)` of the dipole profile (Sect. 3.3, step 3).

        :math:`s_k = \sum_j w_j U_{jk} R_d(r_j, \sigma)`, the discrete form of
        :math:`\int R_d(r, \sigma) b_k(r)\,dr` in the sampling's measure. Broadcasts: RGB
        coefficients of shape (3,) give (3, K). Takes tens of microseconds.

        Parameters
        ----------
        sigma_a, sigma_s_prime : array_like
            Absorption and reduced scattering coefficients, mm^-1, finite and >= 0.
        eta : array_like, optional
            Relative index of refraction in [1, 3]; the basis's own by default (any other
            value is projected just the same, with the basis built for ``self.eta``).

        Returns
        -------
        ndarray, shape ``broadcast(sigma_a, sigma_s_prime, eta).shape + (K,)``, float64

        Raises
        ------
        InputError
            NaN/Inf or negative coefficients, eta outside [1, 3].
        """
        return self.project_with_residual(sigma_a, sigma_s_prime, eta)[0]

    def project_with_residual(self, sigma_a, sigma_s_prime, eta=None):
        r"""Coefficients :math:`s_k(\sigma)` and the fraction of the profile the basis misses.

        The projection is orthogonal in the sampling's weighted norm, so the residual is
        :math:`\lVert w R_d - U s\rVert / \lVert w R_d\rVert =
        (1 - \lVert s\rVert^2 / \lVert w R_d\rVert^2)^{1/2}` at no extra cost: near 0 for
        profiles the basis represents, near 1 for those it cannot (a profile much narrower
        than the sampled distances resolve: the opaque limit).

        Returns
        -------
        coefficients : ndarray, shape ``broadcast shape + (K,)``
            As :meth:`project`.
        residual : ndarray, broadcast shape
            Dimensionless, in [0, 1]; 0 for a zero profile.
        """
        sigma_a = _check_coefficient(sigma_a, "sigma_a")
        sigma_s_prime = _check_coefficient(sigma_s_prime, "sigma_s_prime")
        eta = _check_eta(self.eta if eta is None else eta)
        profile = dipole_reflectance_profile(self.radii, sigma_a[..., None],
                                             sigma_s_prime[..., None], eta[..., None])
        coefficients = profile @ self.projector.T
        sampled = (profile * self.weights) ** 2
        norm = sampled.sum(axis=-1)
        missed = np.clip(norm - (coefficients**2).sum(axis=-1), 0.0, None)
        residual = np.sqrt(np.divide(missed, norm, out=np.zeros_like(norm), where=norm > 0))
        return coefficients, np.minimum(residual, 1.0)

    @functools.cached_property
    def area_moments(self) -> np.ndarray:
        r"""Return :math:`m_k = 2\pi\int_0^R b_k(r)\,r\,dr`, shape (K,).

        :math:`\sum_k s_k m_k` is the total diffuse reflectance of the K-term profile.
        """
        radii, measure = _fine_radii(self.sampling.radius_max)
        return 2.0 * np.pi * (self.evaluate(radii) * measure[:, None]).sum(axis=0)

    def project_with_energy(self, sigma_a, sigma_s_prime, eta=None):
        r"""Coefficients, residual, and the energy of the K-term and of the exact profile.

        The energy of a profile is :math:`2\pi\int_0^R R(r)\,r\,dr` over the basis's
        distances (R = ``radius_max``): :math:`\sum_k s_k m_k` with the per-basis energies
        :attr:`area_moments` (precomputed once) for the K-term profile (Eq. 4 of Wang et al.
        2008), :func:`truncated_diffuse_reflectance` in closed form for the exact one. The
        residual on the samples says nothing of a profile narrower than the sample spacing;
        its energy, on a quadrature that resolves it, does. Costs what :meth:`project` does.

        Parameters
        ----------
        sigma_a, sigma_s_prime, eta
            As :meth:`project`.

        Returns
        -------
        coefficients, residual : ndarray
            As :meth:`project_with_residual`.
        energy, exact_energy : ndarray, broadcast shape
            Dimensionless (total diffuse reflectance over [0, R]).
        """
        coefficients, residual = self.project_with_residual(sigma_a, sigma_s_prime, eta)
        eta = self.eta if eta is None else eta
        exact_energy = truncated_diffuse_reflectance(sigma_a, sigma_s_prime, eta,
                                                     self.sampling.radius_max)
        return coefficients, residual, coefficients @ self.area_moments, exact_energy

    def project_profile(self, profile) -> np.ndarray:
        r"""Coefficients :math:`s_k` of any profile (mm^-2) given at :attr:`radii` or as a callable.

        Parameters
        ----------
        profile : callable or array_like, shape (..., n)
            ``profile(r)`` for distances in mm, or its values at :attr:`radii`.

        Returns
        -------
        ndarray, shape (..., K)
        """
        values = profile(self.radii) if callable(profile) else profile
        values = check_finite(values, "profile")
        if values.shape[-1:] != self.radii.shape:
            raise InputError(f"must hold the profile at the basis's {self.radii.size} distances",
                             field="profile", value=values.shape)
        return values @ self.projector.T

    def reconstruct(self, r, coefficients) -> np.ndarray:
        r""":math:`\sum_k b_k(r) s_k`, mm^-2, shape ``r.shape + coefficients.shape[:-1]``."""
        coefficients = np.asarray(coefficients, dtype=np.float64)
        functions = self.evaluate(np.asarray(r, dtype=np.float64).reshape(-1))
        values = np.tensordot(functions, coefficients, axes=([1], [-1]))
        return values.reshape(np.shape(r) + coefficients.shape[:-1])

    def cache_key(self) -> dict:
        """Return what identifies this basis in content hashes."""
        return {"sampling": asdict(self.sampling), "eta": self.eta, "terms": self.terms,
                "version": BASIS_VERSION}


def truncated_diffuse_reflectance(sigma_a, sigma_s_prime, eta, radius) -> np.ndarray:
    r"""Energy of the dipole profile within ``radius``: :math:`2\pi\int_0^\rho R_d(r)\,r\,dr`.

    With :math:`d = (r^2 + z^2)^{1/2}`, :math:`r\,dr = d\,dd`, each source of the profile
    (Eq. 4 of Jensen et al. 2001, :func:`~translucent.materials.dipole.dipole_reflectance_profile`)
    integrates in closed form, :math:`z\int_z^D (1 + \sigma_{tr} d) e^{-\sigma_{tr} d} d^{-2}\,dd
    = e^{-\sigma_{tr} z} - z e^{-\sigma_{tr} D} / D` with :math:`D = (\rho^2 + z^2)^{1/2}`:

    .. math::
        R_d(\rho) = \frac{\alpha'}{2}\sum_{z \in \{z_r, z_v\}}
        \Big(e^{-\sigma_{tr} z} - \frac{z\,e^{-\sigma_{tr} D}}{D}\Big)

    which tends to the total diffuse reflectance (Eq. 5 of Jensen et al. 2001) as
    :math:`\rho \to \infty`.

    Parameters
    ----------
    sigma_a, sigma_s_prime : array_like
        mm^-1, >= 0; broadcast together.
    eta : array_like
        Relative index of refraction in [1, 3].
    radius : array_like
        mm, >= 0.

    Returns
    -------
    ndarray
        Dimensionless, the broadcast shape.
    """
    sigma_a = _check_coefficient(sigma_a, "sigma_a")
    sigma_s_prime = _check_coefficient(sigma_s_prime, "sigma_s_prime")
    eta = _check_eta(eta)
    radius = check_finite(radius, "radius")
    if (radius < 0).any():
        raise InputError("must be >= 0 mm", field="radius", value=radius.tolist())
    sigma_tr = effective_transport_coefficient(sigma_a, sigma_s_prime)
    total = 0.0
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for depth in dipole_depths(sigma_a, sigma_s_prime, eta):
            outer = np.sqrt(radius * radius + depth * depth)
            total = total + np.exp(-sigma_tr * depth) - depth * np.exp(-sigma_tr * outer) / outer
    albedo = reduced_albedo(sigma_a, sigma_s_prime)
    # alpha' = 0 (no scattering) leaves infinite depths and NaN above: no energy
    return np.where(albedo > 0, 0.5 * albedo * total, 0.0)


def _sampled_profiles(sampling: ProfileSampling, eta: float, sigma_s_prime, sigma_a,
                      radii, weights, family=None) -> np.ndarray:
    """Rows of weighted (and, if asked, unit-norm) sampled profiles for a block of the grid."""
    if family is None:
        profiles = dipole_reflectance_profile(radii, sigma_a[:, None], sigma_s_prime[:, None],
                                              eta) * weights
    else:
        profiles = family(radii, sigma_a, sigma_s_prime, eta) * weights
    if sampling.normalise:
        norms = np.linalg.norm(profiles, axis=1, keepdims=True)
        profiles = np.divide(profiles, norms, out=np.zeros_like(profiles), where=norms > 0)
    return profiles


def _profile_blocks(sampling: ProfileSampling, eta: float, radii, weights, family=None):
    """Yield the sampled matrix's rows (profiles), block by block over the grid."""
    sigma_s_prime_axis, sigma_a_axis = sampling.sigma_grids()
    rows_per_block = max(1, PROFILES_PER_BLOCK // sigma_a_axis.size)
    for start in range(0, sigma_s_prime_axis.size, rows_per_block):
        block_s = sigma_s_prime_axis[start:start + rows_per_block]
        grid_s, grid_a = np.meshgrid(block_s, sigma_a_axis, indexing="ij")
        yield _sampled_profiles(sampling, eta, grid_s.ravel(), grid_a.ravel(), radii, weights,
                                family)


def decompose_family(sampling: ProfileSampling, eta: float, family):
    r"""Sect. 3.1 of Wang et al. 2008 over another family of profiles than the dipole.

    The same sampling (distances, weights, coefficient grid) and decomposition as
    :func:`dipole_pca_basis`; only the sampled profiles differ.

    Parameters
    ----------
    sampling : ProfileSampling
    eta : float
        Relative index of refraction of the sampled profiles, in [1, 3].
    family : callable
        ``family(radii, sigma_a, sigma_s_prime, eta) -> (m, n)``: the profiles (mm^-2) of
        the m media (coefficients in mm^-1, shape (m,)) at the n distances (mm).

    Returns
    -------
    radii, weights, vectors, singular_values : ndarray
        As the arguments of :class:`DipolePCABasis`.
    """
    from threadpoolctl import threadpool_limits

    # one BLAS thread, as materials.brdf_pca's SVD: threaded LAPACK on 650 x 650 gains
    # little and stalls on a loaded machine
    with threadpool_limits(limits=1, user_api="blas"):
        return _decompose(_sampling(sampling), float(_check_eta(eta)), family)


def _decompose(sampling: ProfileSampling, eta: float, family=None):
    """Left singular vectors and singular values of the sampled matrix (distances x profiles).

    The matrix (650 x sigma_samples^2) is streamed in blocks. Its Gram matrix gives the
    singular vectors quickly, but only to an absolute precision of ~1e-16 of the largest
    eigenvalue, which loses the trailing ones (the 15th singular value of the paper's
    sampling is ~1e-6 of the first). A second pass computes the Gram matrix of the data
    rotated into those vectors: its entries carry errors ~1e-16 sqrt(lambda_i lambda_j),
    small for the small directions too, and its eigenvectors correct the first ones
    (checked against a direct SVD in the tests).
    """
    radii, weights = sampling.radii_and_weights()
    total = sampling.sigma_samples ** 2 * radii.size * 8
    kept = list(_profile_blocks(sampling, eta, radii, weights, family)) \
        if total <= PROFILE_MEMORY_BYTES else None

    def blocks():
        return iter(kept) if kept is not None else _profile_blocks(sampling, eta, radii,
                                                                   weights, family)

    gram = sum(block.T @ block for block in blocks())
    _, rotation = np.linalg.eigh(gram)
    rotation = rotation[:, ::-1]
    rotated_gram = sum((block @ rotation).T @ (block @ rotation) for block in blocks())
    eigenvalues, correction = np.linalg.eigh(rotated_gram)
    order = np.argsort(eigenvalues)[::-1]
    singular_values = np.sqrt(np.clip(eigenvalues[order], 0.0, None))
    vectors = (rotation @ correction[:, order[:STORED_TERMS]]).copy()
    # a deterministic sign: the largest entry of every vector is positive
    largest = vectors[np.abs(vectors).argmax(axis=0), np.arange(vectors.shape[1])]
    vectors *= np.where(largest < 0, -1.0, 1.0)
    return radii, weights, vectors, singular_values


#: Folder of the bases shipped with the suite (the two presets at their default density and
#: eta = 1.3), so that nobody waits for the SVD of the default basis; regenerate them with
#: :func:`write_shipped_basis` whenever :data:`BASIS_VERSION` or a preset changes.
SHIPPED_FOLDER = Path(__file__).with_name("data")


def _decomposition_key(sampling: ProfileSampling, eta: float) -> str:
    from ..cache import content_hash

    return content_hash("dipole_pca", BASIS_VERSION, asdict(sampling), eta)


def _shipped_path(sampling: ProfileSampling, eta: float) -> Path:
    key = _decomposition_key(sampling, eta)[:16]
    return SHIPPED_FOLDER / f"dipole_pca_{sampling.name}_{key}.npz"


def _read_shipped(path: Path):
    with np.load(path) as stored:
        return tuple(np.array(stored[name]) for name in ("radii", "weights", "vectors",
                                                         "singular_values"))


@functools.lru_cache(maxsize=16)
def _cached_decomposition(sampling: ProfileSampling, eta: float):
    from ..cache import Cache

    shipped = _shipped_path(sampling, eta)
    if shipped.is_file():
        stored = _read_shipped(shipped)
    else:
        cache = Cache("dipole_pca")
        key = _decomposition_key(sampling, eta)
        stored = cache.load_object(key)
        if stored is None:
            stored = _decompose(sampling, eta)
            cache.store_object(key, stored)
    for array in stored:
        array.flags.writeable = False
    return stored


def write_shipped_basis(parameterisation, eta: float = 1.3) -> Path:
    """Compute a preset basis and write it atomically where :func:`dipole_pca_basis` looks first.

    The file name carries the hash of the sampling, ``eta`` and :data:`BASIS_VERSION`, so a
    stale file is simply never found.

    Returns
    -------
    pathlib.Path
    """
    from ..atomic import atomic_path

    sampling = _sampling(parameterisation)
    eta = float(_check_eta(eta))
    radii, weights, vectors, singular_values = _decompose(sampling, eta)
    path = _shipped_path(sampling, eta)
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(handle, radii=radii, weights=weights, vectors=vectors,
                            singular_values=singular_values)
    return path


def dipole_pca_basis(parameterisation="paper", *, eta: float = 1.3, terms: int = 12,
                     sigma_samples: int | None = None) -> DipolePCABasis:
    r"""Return the PCA basis of :math:`R_d(r)` (Sect. 3.1 of Wang et al. 2008), cached.

    The two presets at their default density and eta = 1.3 ship with the suite
    (:data:`SHIPPED_FOLDER`). Any other sampling is computed on first use (tens of seconds
    for a 256 x 256 grid) and stored under the ``dipole_pca`` namespace of
    :class:`translucent.cache.Cache`, keyed by the sampling, ``eta`` and the version.

    Parameters
    ----------
    parameterisation : str or ProfileSampling
        ``"paper"`` (default), ``"area_normalised"`` or a custom :class:`ProfileSampling`.
    eta : float
        Relative index of refraction of the sampled profiles, in [1, 3].
    terms : int
        K, the number of basis functions used (12 in the paper), 1 to 32.
    sigma_samples : int, optional
        Grid samples per axis, overriding the sampling's.

    Returns
    -------
    DipolePCABasis

    Raises
    ------
    InputError
        Unknown parameterisation, eta outside [1, 3], terms outside [1, 32].
    """
    sampling = _sampling(parameterisation)
    if sigma_samples is not None:
        sampling = ProfileSampling(**{**asdict(sampling), "sigma_samples": sigma_samples})
    eta = float(_check_eta(eta))
    radii, weights, vectors, singular_values = _cached_decomposition(sampling, eta)
    return DipolePCABasis(sampling, eta, radii, weights, vectors, singular_values, terms)


# --- the analysis of Fig. 4 -----------------------------------------------------------------


def singular_value_roots(basis: DipolePCABasis, count: int = 15) -> np.ndarray:
    """Square roots of the first ``count`` singular values (Fig. 4a of Wang et al. 2008)."""
    return np.sqrt(basis.singular_values[:count])


def leading_basis_functions(basis: DipolePCABasis, count: int = 4, radius: float = 5.0,
                            samples: int = 501) -> tuple[np.ndarray, np.ndarray]:
    r"""Return the first ``count`` basis functions on [0, ``radius``] mm (Fig. 4b, Wang 2008).

    Returns
    -------
    radii : ndarray, shape (samples,)
        mm.
    functions : ndarray, shape (count, samples)
        :math:`b_k(r)`, in the units that make :math:`\sum_k b_k s_k` a profile in mm^-2.
    """
    radii = np.linspace(0.0, radius, samples)
    return radii, basis.truncated(count).evaluate(radii).T


def _fine_radii(radius_max: float, samples: int = 4001) -> tuple[np.ndarray, np.ndarray]:
    """Distances dense near 0 and trapezoid weights of the area measure r dr on them."""
    t = np.linspace(0.0, 1.0, samples)
    radii = radius_max * t * t
    widths = np.gradient(radii)
    return radii, radii * widths


def area_relative_error(basis: DipolePCABasis, sigma_a, sigma_s_prime, eta=None) -> np.ndarray:
    r"""Relative L2 error of the K-term profile in the area measure, over [0, 65] mm.

    .. math::
        \epsilon = \Big(\int_0^R (\tilde R_d - R_d)^2\,r\,dr \Big/
        \int_0^R R_d^2\,r\,dr\Big)^{1/2}

    with :math:`\tilde R_d = \sum_k b_k s_k` (Eq. 4 of Wang et al. 2008), evaluated on
    4001 distances dense near 0, independent of the basis's own sampling. This is the
    error that matters for Eq. 5, where profiles are integrated over a surface.

    Parameters
    ----------
    basis : DipolePCABasis
    sigma_a, sigma_s_prime : array_like
        mm^-1; broadcast together (and with ``eta``).
    eta : array_like, optional
        Defaults to the basis's.

    Returns
    -------
    ndarray
        Dimensionless, the broadcast shape of the coefficients.
    """
    eta = basis.eta if eta is None else eta
    sigma_a, sigma_s_prime, eta = np.broadcast_arrays(np.asarray(sigma_a, np.float64),
                                                      np.asarray(sigma_s_prime, np.float64),
                                                      np.asarray(eta, np.float64))
    radii, measure = _fine_radii(basis.sampling.radius_max)
    coefficients = basis.project(sigma_a, sigma_s_prime, eta)
    approximation = basis.evaluate(radii) @ coefficients.reshape(-1, basis.terms).T
    exact = dipole_reflectance_profile(radii[:, None], sigma_a.reshape(-1),
                                       sigma_s_prime.reshape(-1), eta.reshape(-1))
    error = np.sqrt(((approximation - exact) ** 2 * measure[:, None]).sum(axis=0))
    norm = np.sqrt((exact ** 2 * measure[:, None]).sum(axis=0))
    relative = np.divide(error, norm, out=np.zeros_like(error), where=norm > 0)
    return relative.reshape(sigma_a.shape)


def approximation_error_maps(basis: DipolePCABasis, *, resolution: int = 64,
                             sigma_range: tuple[float, float] = (1e-6, 5.0)) -> dict:
    r"""Return the error maps of Fig. 4c-d of Wang et al. 2008, and the area-measure error.

    Over a log-spaced grid of :math:`\sigma'_s` (rows) and :math:`\sigma_a` (columns) in
    ``sigma_range`` mm^-1, with the basis's K terms. Errors are taken on the paper's 650
    uniform distances in [0, 65] mm (whatever the basis's own sampling).

    Returns
    -------
    dict
        ``sigma_s_prime`` (rows, mm^-1), ``sigma_a`` (columns, mm^-1), ``l2`` (absolute L2
        error :math:`(\int (\tilde R_d - R_d)^2 dr)^{1/2}`, mm^-2 mm^1/2),
        ``log10_relative_linf`` (:math:`\log_{10}(\max|\tilde R_d - R_d| / \max R_d)`, the
        digits of accuracy, Fig. 4d), ``area_relative_l2`` (see :func:`area_relative_error`),
        ``terms``.
    """
    lo, hi = sigma_range
    if not 0 < lo < hi:
        raise InputError("must be (low, high) with 0 < low < high, mm^-1", field="sigma_range",
                         value=sigma_range)
    sigma_s_prime = np.geomspace(lo, hi, resolution)
    sigma_a = np.geomspace(lo, hi, resolution)
    grid_s, grid_a = np.meshgrid(sigma_s_prime, sigma_a, indexing="ij")
    radii = np.linspace(0.0, basis.sampling.radius_max, 650)
    spacing = radii[1] - radii[0]
    exact = dipole_reflectance_profile(radii, grid_a[..., None], grid_s[..., None], basis.eta)
    coefficients = basis.project(grid_a, grid_s)
    approximation = coefficients @ basis.evaluate(radii).T
    difference = approximation - exact
    l2 = np.sqrt((difference ** 2).sum(axis=-1) * spacing)
    peak = exact.max(axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative_linf = np.abs(difference).max(axis=-1) / peak
        log10_relative_linf = np.log10(np.where(peak > 0, relative_linf, np.nan))
    return {"sigma_s_prime": sigma_s_prime, "sigma_a": sigma_a, "l2": l2,
            "log10_relative_linf": log10_relative_linf,
            "area_relative_l2": area_relative_error(basis, grid_a, grid_s),
            "terms": basis.terms}


def measured_profile_errors(basis: DipolePCABasis) -> dict[str, np.ndarray]:
    """:func:`area_relative_error` of every measured medium (Jensen et al. 2001), per RGB channel.

    Each medium is projected with its own eta (1.5 for Marble), onto a basis built for
    ``basis.eta``.
    """
    return {name: area_relative_error(basis, sigma_a, sigma_s_prime, eta)
            for name, (sigma_s_prime, sigma_a, eta) in MEASURED_MEDIA.items()}


def compare_parameterisations(bases: dict[str, DipolePCABasis],
                              terms=tuple(range(1, 17))) -> dict[str, dict[str, np.ndarray]]:
    """Error against the number of terms for several bases, on the 36 measured profiles.

    Parameters
    ----------
    bases : dict
        label -> basis (its own ``terms`` is ignored).
    terms : sequence of int
        The K to evaluate.

    Returns
    -------
    dict
        label -> ``{"terms", "worst", "median"}``: the worst and the median
        :func:`area_relative_error` over the 12 measured media x 3 channels.
    """
    terms = np.asarray(terms, dtype=int)
    results = {}
    for label, basis in bases.items():
        worst, median = [], []
        for count in terms:
            errors = np.concatenate(list(measured_profile_errors(basis.truncated(int(count)))
                                         .values()))
            worst.append(errors.max())
            median.append(np.median(errors))
        results[label] = {"terms": terms, "worst": np.array(worst), "median": np.array(median)}
    return results


def terms_to_match(reference: DipolePCABasis, candidate: DipolePCABasis,
                   reference_terms: int = 12, statistic: str = "worst") -> int | None:
    """Fewest terms of ``candidate`` whose measured-media error is at most ``reference``'s.

    Parameters
    ----------
    reference, candidate : DipolePCABasis
    reference_terms : int
        K of the reference (12, the paper's choice).
    statistic : {"worst", "median"}
        Over the 36 measured profiles (see :func:`compare_parameterisations`).

    Returns
    -------
    int or None
        None when even :data:`STORED_TERMS` terms do not reach it.
    """
    if statistic not in ("worst", "median"):
        raise InputError("must be 'worst' or 'median'", field="statistic", value=statistic)
    target = compare_parameterisations({"r": reference}, [reference_terms])["r"][statistic][0]
    for count in range(1, candidate.vectors.shape[1] + 1):
        error = compare_parameterisations({"c": candidate}, [count])["c"][statistic][0]
        if error <= target:
            return count
    return None


def write_analysis_figure(path, bases: dict[str, DipolePCABasis], *, resolution: int = 48):
    """Write the Fig. 4 analysis of Wang et al. 2008 for each basis as one PNG, atomically.

    One row per basis: square roots of the first 15 singular values (normalised by the
    first), the first four basis functions on [0, 5] mm, the L2 error map, the
    log10 relative L-infinity error map (both with the basis's K terms, over
    [1e-6, 5] mm^-1), and a last row with the measured-media error against K for all bases.

    Returns
    -------
    pathlib.Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..atomic import atomic_save_figure

    rows = len(bases) + 1
    figure, axes = plt.subplots(rows, 4, figsize=(16, 3.6 * rows), squeeze=False)
    for row, (label, basis) in enumerate(bases.items()):
        roots = singular_value_roots(basis)
        axes[row, 0].semilogy(np.arange(1, roots.size + 1), roots / roots[0], "o-")
        axes[row, 0].set(title=f"{label}: sqrt(singular values)", xlabel="k")
        radii, functions = leading_basis_functions(basis)
        for k, function in enumerate(functions):
            axes[row, 1].plot(radii, function, label=f"b{k + 1}")
        axes[row, 1].set(title=f"{label}: first four b_k(r)", xlabel="r (mm)")
        axes[row, 1].legend()
        maps = approximation_error_maps(basis, resolution=resolution)
        extent = np.log10([maps["sigma_a"][0], maps["sigma_a"][-1],
                           maps["sigma_s_prime"][0], maps["sigma_s_prime"][-1]])
        for column, key, title in ((2, "l2", "L2 error"),
                                   (3, "log10_relative_linf", "log10 relative Linf error")):
            shown = axes[row, column].imshow(maps[key], origin="lower", extent=extent,
                                             aspect="auto", cmap="viridis")
            figure.colorbar(shown, ax=axes[row, column])
            axes[row, column].set(title=f"{label}: {title}, K={basis.terms}",
                                  xlabel="log10 sigma_a", ylabel="log10 sigma_s'")
    comparison = compare_parameterisations(bases)
    for label, result in comparison.items():
        axes[-1, 0].semilogy(result["terms"], result["worst"], "o-", label=f"{label} worst")
        axes[-1, 0].semilogy(result["terms"], result["median"], "s--", label=f"{label} median")
    axes[-1, 0].set(title="measured media: area-measure relative L2", xlabel="K")
    axes[-1, 0].legend()
    for axis in axes[-1, 1:]:
        axis.axis("off")
    figure.tight_layout()
    return atomic_save_figure(path, figure)
