r"""PCA linearisation of an analytic BRDF's edited term (Sect. 4 of Nguyen et al. 2010).

The edited term :math:`f_E(\gamma, \delta)` of a model (Table 4) is sampled on an even grid
of :math:`k'` editing parameters :math:`\gamma_i \in [\gamma_{min}, \gamma_{max}]` and
:math:`h` values of :math:`\delta` (the half angle in :math:`[0, \pi/2]`; for Lafortune the
normalised lobe cosine in :math:`[\epsilon, 1 - \epsilon]`), one column
:math:`\mathbf{p}_i` per :math:`\gamma_i` (Eq. 11). The mean :math:`\mathbf{b}_0` is
subtracted and the SVD of the centred matrix gives the basis
:math:`\mathbf{B}' = [\mathbf{b}_1 \dots \mathbf{b}_K]` (Eqs. 12-14), so that

.. math:: f_E(\gamma, \delta) \approx b_0(\delta) + \sum_{j=1}^K c_j(\gamma)\, b_j(\delta)
          \qquad \text{(Eq. 10)}

and a new :math:`\gamma` costs one evaluation of :math:`\mathbf{p}(\gamma)` and one
:math:`K \times h` matrix-vector product with the projection matrix
:math:`\mathbf{H} = (\mathbf{B}'^T\mathbf{B}')^{-1}\mathbf{B}'^T` (Eq. 15).

Between grid values of :math:`\delta` the basis functions are interpolated linearly.

References
----------
C. H. Nguyen, M.-H. Kyung, J.-H. Lee, S.-W. Nam: A PCA decomposition for real-time BRDF
editing and relighting with global illumination. Computer Graphics Forum 29(4), 2010.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .brdfs import (
    GAMMA_RANGES,
    canonical_model,
    check_gamma,
    edited_term,
    pca_variable_range,
    uses_half_angle,
)

__all__ = [
    "PCA_MODEL_PREFIX",
    "pca_model_name",
    "pca_model_basis",
    "pca_model_gather",
    "GATHER_TRANSPORTS",
    "GLOSSY_GATHER",
    "LAMBERTIAN_GATHER",
    "DEFAULT_BASIS_SIZE",
    "DEFAULT_DELTA_SAMPLES",
    "DEFAULT_GAMMA_SAMPLES",
    "PCABasis",
    "PCAAnalysis",
    "build_pca_basis",
    "pca_analysis",
]

#: K, the number of basis functions kept: 6 in every scene of Nguyen et al. 2010 (Table 5).
DEFAULT_BASIS_SIZE = 6

#: k', the number of gamma samples. The paper does not give it; with 1000 samples the RMS
#: error between grid values of gamma matches the one at grid values within 3 % for every
#: model (measured at K = 6): the basis generalises over the whole range.
DEFAULT_GAMMA_SAMPLES = 1000

#: h, the number of delta samples: the narrowest lobes (Blinn-Phong gamma = 300, width
#: ~0.08 rad; Ward gamma = 0.05, width ~0.05 rad) get 30 to 50 samples across.
DEFAULT_DELTA_SAMPLES = 1024


#: The name of the K-term PCA BRDF as a model the reference renders: ``brdf_pca_k6``.
PCA_MODEL_PREFIX = "brdf_pca_k"

#: After a PCA BRDF model's name, ``+lambertian_gatherN``: the transport of Nguyen et al.
#: 2010, Sect. 5.2, that the method converges to: the first surface seen reflects with its
#: (PCA) BRDF, the next ``N + 1`` diffusely (Lambertian gather samples, ``N`` bounces of
#: Eq. 17 among them).
LAMBERTIAN_GATHER = "lambertian_gather"

#: ``+glossy_gatherN``: as :data:`LAMBERTIAN_GATHER`, but the second surface (a gather
#: sample) reflects the light that reaches it directly by its whole BRDF (the method's
#: ``gather_reflection="brdf"``); its light from other surfaces stays diffuse.
GLOSSY_GATHER = "glossy_gather"

#: The gather transports a model name may carry, and the surfaces along a path (from the
#: eye) that reflect the direct light by their whole BRDF.
GATHER_TRANSPORTS = {LAMBERTIAN_GATHER: 1, GLOSSY_GATHER: 2}


def pca_model_name(n_basis: int, gather_bounces: int | None = None,
                   transport: str = LAMBERTIAN_GATHER) -> str:
    """Return the model name of the K-term PCA BRDF, carried by a gather transport if asked.

    Examples
    --------
    >>> pca_model_name(6), pca_model_name(6, 2)
    ('brdf_pca_k6', 'brdf_pca_k6+lambertian_gather2')
    >>> pca_model_name(6, 2, GLOSSY_GATHER)
    'brdf_pca_k6+glossy_gather2'
    """
    name = f"{PCA_MODEL_PREFIX}{int(n_basis)}"
    if gather_bounces is None:
        return name
    if transport not in GATHER_TRANSPORTS:
        raise InputError(f"must be one of {', '.join(GATHER_TRANSPORTS)}", field="transport",
                         value=transport)
    return f"{name}+{transport}{int(gather_bounces)}"


def _ascii_digits(text: str) -> bool:
    return bool(text) and text.isascii() and text.isdigit()


def _pca_model_parts(name) -> tuple[int, str | None, int | None] | None:
    if not isinstance(name, str) or not name.startswith(PCA_MODEL_PREFIX):
        return None
    digits, plus, transport = name[len(PCA_MODEL_PREFIX):].partition("+")
    kind = next((k for k in GATHER_TRANSPORTS if transport.startswith(k)), None)
    bounces = transport[len(kind):] if kind else ""
    if not _ascii_digits(digits) or not 1 <= int(digits) <= 64 or (plus and not (
            kind and _ascii_digits(bounces) and int(bounces) <= 64)):
        raise InputError(f"a PCA BRDF model is {PCA_MODEL_PREFIX}K with K in [1, 64], "
                         f"optionally +TRANSPORTN with TRANSPORT one of "
                         f"{', '.join(GATHER_TRANSPORTS)} and N in [0, 64]",
                         field="profile", value=name)
    return int(digits), kind, (int(bounces) if kind else None)


def pca_model_basis(name) -> int | None:
    """Return K of a PCA BRDF model name, or None when ``name`` is not one.

    Examples
    --------
    >>> pca_model_basis("brdf_pca_k6"), pca_model_basis("dipole"), pca_model_basis(None)
    (6, None, None)
    >>> pca_model_basis("brdf_pca_k6+lambertian_gather2")
    6
    """
    parts = _pca_model_parts(name)
    return None if parts is None else parts[0]


def pca_model_gather(name) -> tuple[str, int] | None:
    """Return the gather transport and bounces N of ``brdf_pca_kK+TRANSPORTN`` (None: exact).

    Examples
    --------
    >>> pca_model_gather("brdf_pca_k6+lambertian_gather2"), pca_model_gather("brdf_pca_k6")
    (('lambertian_gather', 2), None)
    """
    parts = _pca_model_parts(name)
    return None if parts is None or parts[1] is None else (parts[1], parts[2])


def _check_count(value, field_name: str, minimum: int, maximum: int) -> int:
    if int(value) != value or not minimum <= int(value) <= maximum:
        raise InputError(f"must be an integer in [{minimum}, {maximum}]", field=field_name,
                         value=value)
    return int(value)


@dataclass(frozen=True, eq=False)
class PCABasis:
    r"""Basis functions of a model's edited term and the projection of Eq. 15.

    Parameters
    ----------
    model : str
    gamma_range : (float, float)
        The range the basis was fitted over (the model's editing range).
    delta : ndarray, shape (h,)
        The delta grid (radians, or Lafortune's lobe cosine).
    mean : ndarray, shape (h,)
        :math:`\mathbf{b}_0`, sr^-1.
    components : ndarray, shape (K, h)
        :math:`\mathbf{b}_1 \dots \mathbf{b}_K` (orthonormal rows), sr^-1.
    projection : ndarray, shape (K, h)
        :math:`\mathbf{H}` of Eq. 15.
    singular_values : ndarray
        Every singular value of the centred sample matrix (descending); their squares
        over :math:`k'` are the eigenvalues of the covariance.
    """

    model: str
    gamma_range: tuple
    delta: np.ndarray
    mean: np.ndarray
    components: np.ndarray
    projection: np.ndarray
    singular_values: np.ndarray
    gamma_samples: int = DEFAULT_GAMMA_SAMPLES
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def size(self) -> int:
        """K, the number of basis functions besides the mean."""
        return len(self.components)

    @property
    def eigenvalues(self) -> np.ndarray:
        """Eigenvalues of the sample covariance for the K kept components."""
        return self.singular_values[: self.size] ** 2 / self.gamma_samples

    def samples(self, gamma) -> np.ndarray:
        r"""Return :math:`\mathbf{p}(\gamma)`, the edited term on the delta grid (Eq. 11)."""
        gamma = np.asarray(gamma, dtype=np.float64)
        return edited_term(self.model, gamma[..., None], self.delta)

    def coefficients(self, gamma) -> np.ndarray:
        r"""Return :math:`\mathbf{c}(\gamma) = [1, c_1, \dots, c_K]` (Eqs. 13 and 15).

        Raises
        ------
        InputError
            ``gamma`` outside the model's range (the basis was fitted there only).
        """
        check_gamma(self.model, gamma)
        low, high = self.gamma_range
        if not low <= float(gamma) <= high:
            raise InputError(f"must be in the basis' range [{low:g}, {high:g}]",
                             field="gamma", value=gamma)
        projected = self.projection @ (self.samples(float(gamma)) - self.mean)
        return np.concatenate([[1.0], projected])

    def reconstruct(self, gamma) -> np.ndarray:
        r"""Return the linearised edited term on the delta grid, :math:`\mathbf{Bc}(\gamma)`."""
        return self.basis_matrix() @ self.coefficients(gamma)

    def basis_matrix(self) -> np.ndarray:
        r"""Return :math:`\mathbf{B} = [\mathbf{b}_0 \dots \mathbf{b}_K]`, shape (h, K + 1)."""
        if "matrix" not in self._cache:
            self._cache["matrix"] = np.column_stack([self.mean, self.components.T])
        return self._cache["matrix"]

    def delta_of(self, variable) -> np.ndarray:
        """Return delta of a :func:`~translucent.materials.brdfs.pca_variable` (arccos: angles)."""
        variable = np.asarray(variable, dtype=np.float64)
        if uses_half_angle(self.model):
            return np.arccos(np.clip(variable, 0.0, 1.0))
        return variable

    def basis_values(self, variable) -> np.ndarray:
        r"""Interpolate :math:`b_0 \dots b_K` at values of the PCA variable.

        Parameters
        ----------
        variable : array_like
            :math:`\cos\delta` (half-angle models) or Lafortune's lobe cosine, as
            :func:`~translucent.materials.brdfs.pca_variable` returns it.

        Returns
        -------
        ndarray, shape ``variable.shape + (K + 1,)``
            Linear interpolation on the delta grid, sr^-1; zero where the edited term is
            zero for every gamma (a Lafortune lobe cosine <= 0).
        """
        delta = self.delta_of(variable)
        grid = self.delta
        position = (delta - grid[0]) / (grid[1] - grid[0])
        position = np.clip(position, 0.0, len(grid) - 1.0)
        index = np.minimum(position.astype(np.int64), len(grid) - 2)
        fraction = (position - index)[..., None]
        matrix = self.basis_matrix()
        values = matrix[index] * (1.0 - fraction) + matrix[index + 1] * fraction
        if not uses_half_angle(self.model):
            values = np.where((delta > 0)[..., None], values, 0.0)
        return values

    def rms_error(self, gammas) -> np.ndarray:
        """Return the RMS over delta of linearised minus exact edited term, per gamma (sr^-1)."""
        gammas = np.atleast_1d(np.asarray(gammas, dtype=np.float64))
        exact = self.samples(gammas)                                    # (n, h)
        projected = (exact - self.mean) @ self.projection.T             # (n, K)
        approx = self.mean + projected @ self.components
        return np.sqrt(np.mean((approx - exact) ** 2, axis=-1))

    def cache_key(self) -> dict:
        """Return what identifies this basis in content hashes."""
        return {"model": self.model, "gamma_range": list(self.gamma_range),
                "delta": self.delta, "mean": self.mean, "components": self.components}


def _sample_matrix(model, gamma_range, gamma_samples, delta_samples):
    low, high = gamma_range
    gammas = np.linspace(low, high, gamma_samples)
    d_low, d_high = pca_variable_range(model)
    delta = np.linspace(d_low, d_high, delta_samples)
    columns = edited_term(model, gammas[:, None], delta[None, :]).T       # (h, k'), Eq. 11
    return delta, columns


#: Left singular vectors stored per decomposition (the analysis uses up to 64).
STORED_COMPONENTS = 64


@functools.lru_cache(maxsize=32)
def _decomposition(model, gamma_range, gamma_samples, delta_samples):
    """SVD of the centred sample matrix; kept in memory and in the ``brdf_pca_basis`` cache.

    The SVD runs with one BLAS thread: threaded LAPACK on a matrix this small gains little
    and, on a loaded machine, stalls in synchronisation (measured: 1.4 s with one thread,
    9-35 s with two on a shared 2-core machine).
    """
    from threadpoolctl import threadpool_limits

    from ..cache import Cache, content_hash

    key = content_hash("pca_basis", 1, model, list(gamma_range), gamma_samples, delta_samples)
    cache = Cache("brdf_pca_basis")
    stored = cache.load_object(key)
    if stored is not None:
        return stored
    delta, columns = _sample_matrix(model, gamma_range, gamma_samples, delta_samples)
    mean = columns.mean(axis=1)                                          # b_0, Eq. 13
    with threadpool_limits(limits=1, user_api="blas"):
        left, singular, _ = np.linalg.svd(columns - mean[:, None], full_matrices=False)
    result = (delta, mean, np.ascontiguousarray(left[:, :STORED_COMPONENTS]), singular)
    cache.store_object(key, result)
    return result


def build_pca_basis(model: str, n_basis: int = DEFAULT_BASIS_SIZE, *,
                    gamma_range=None, gamma_samples: int = DEFAULT_GAMMA_SAMPLES,
                    delta_samples: int = DEFAULT_DELTA_SAMPLES) -> PCABasis:
    """Fit the PCA basis of a model's edited term (Sect. 4 of Nguyen et al. 2010).

    Parameters
    ----------
    model : str
        A model of :data:`~translucent.materials.brdfs.MODELS`.
    n_basis : int
        K, basis functions kept besides the mean, in [1, 64] (and < k').
    gamma_range : (float, float), optional
        A sub-range of the model's editing range (default: all of it).
    gamma_samples : int
        k', evenly spaced gamma samples, in [K + 1, 100000].
    delta_samples : int
        h, evenly spaced delta samples, in [16, 65536].

    Returns
    -------
    PCABasis

    Raises
    ------
    InputError
        Unknown model, a range outside the model's, counts out of range.
    """
    model = canonical_model(model)
    n_basis = _check_count(n_basis, "n_basis", 1, 64)
    gamma_samples = _check_count(gamma_samples, "gamma_samples", n_basis + 1, 100_000)
    delta_samples = _check_count(delta_samples, "delta_samples", 16, 65_536)
    full = GAMMA_RANGES[model]
    if gamma_range is None:
        gamma_range = full
    low, high = (float(v) for v in gamma_range)
    if not full[0] <= low < high <= full[1]:
        raise InputError(f"must be a sub-interval of [{full[0]:g}, {full[1]:g}] for the {model} "
                         "model", field="gamma_range", value=gamma_range)
    delta, mean, left, singular = _decomposition(model, (low, high), gamma_samples,
                                                 delta_samples)
    components = left[:, :n_basis].T.copy()
    basis = components.T                                                 # B', (h, K)
    projection = np.linalg.solve(basis.T @ basis, basis.T)               # H, Eq. 15
    for array in (delta, mean, components, projection):
        array.flags.writeable = False
    return PCABasis(model, (low, high), delta, mean, components, projection, singular.copy(),
                    gamma_samples)


@dataclass(frozen=True)
class PCAAnalysis:
    r"""The analysis of Fig. 5 of Nguyen et al. 2010 for one model.

    Attributes
    ----------
    model : str
    basis_sizes : ndarray of int
        K values of panel (a).
    rms_max, rms_mean : ndarray
        Largest and mean RMS error over test gammas for each K (panel a), sr^-1.
    relative_rms_max : ndarray
        Largest RMS error relative to the RMS of the exact edited term, for each K.
    delta : ndarray
        The delta grid.
    first_basis : ndarray, shape (7, h)
        :math:`b_1 \dots b_7` (panel b).
    gammas : ndarray
        Test gammas (between the grid values), panel (c).
    rms_along_gamma : ndarray
        RMS error at each test gamma with K = ``along_gamma_k`` (panel c), sr^-1.
    along_gamma_k : int
    peak : float
        Largest value of the edited term over the range (sets the scale of the errors).
    """

    model: str
    basis_sizes: np.ndarray
    rms_max: np.ndarray
    rms_mean: np.ndarray
    relative_rms_max: np.ndarray
    delta: np.ndarray
    first_basis: np.ndarray
    gammas: np.ndarray
    rms_along_gamma: np.ndarray
    along_gamma_k: int
    peak: float

    def smallest_k_reaching(self, rms: float) -> int | None:
        """Return the smallest K whose largest RMS error is <= ``rms`` (None if none does)."""
        reached = np.flatnonzero(self.rms_max <= rms)
        return int(self.basis_sizes[reached[0]]) if len(reached) else None

    def to_dict(self) -> dict:
        """Return the numbers as JSON-able lists (the basis vectors left out)."""
        return {"model": self.model, "basis_sizes": self.basis_sizes.tolist(),
                "rms_max": self.rms_max.tolist(), "rms_mean": self.rms_mean.tolist(),
                "relative_rms_max": self.relative_rms_max.tolist(),
                "along_gamma_k": self.along_gamma_k,
                "rms_along_gamma_max": float(self.rms_along_gamma.max()),
                "rms_along_gamma_mean": float(self.rms_along_gamma.mean()),
                "peak": self.peak, "k_for_1e-5": self.smallest_k_reaching(1e-5)}


def pca_analysis(model: str, *, max_basis: int = 24, along_gamma_k: int = DEFAULT_BASIS_SIZE,
                 test_gammas: int = 997, gamma_samples: int = DEFAULT_GAMMA_SAMPLES,
                 delta_samples: int = DEFAULT_DELTA_SAMPLES) -> PCAAnalysis:
    """Measure the accuracy of the linearisation as in Fig. 5 of Nguyen et al. 2010.

    The errors are measured at ``test_gammas`` values evenly spaced over the range, a
    count prime to the fitting grid's so that they fall between the fitted gammas.

    Returns
    -------
    PCAAnalysis
    """
    model = canonical_model(model)
    max_basis = _check_count(max_basis, "max_basis", 1, 64)
    low, high = GAMMA_RANGES[model]
    gammas = np.linspace(low, high, _check_count(test_gammas, "test_gammas", 2, 100_000))
    sizes = np.unique(np.concatenate([np.arange(1, min(max_basis, 12) + 1),
                                      np.arange(12, max_basis + 1, 4), [max_basis]]))
    largest = build_pca_basis(model, max_basis, gamma_samples=gamma_samples,
                              delta_samples=delta_samples)
    exact_rms = np.sqrt(np.mean(largest.samples(gammas) ** 2, axis=-1))
    rms_max, rms_mean, relative = [], [], []
    along = None
    for k in sizes:
        basis = build_pca_basis(model, int(k), gamma_samples=gamma_samples,
                                delta_samples=delta_samples)
        errors = basis.rms_error(gammas)
        rms_max.append(errors.max())
        rms_mean.append(errors.mean())
        relative.append((errors / exact_rms).max())
        if k == along_gamma_k:
            along = errors
    if along is None:
        along = build_pca_basis(model, along_gamma_k, gamma_samples=gamma_samples,
                                delta_samples=delta_samples).rms_error(gammas)
    return PCAAnalysis(model, sizes, np.array(rms_max), np.array(rms_mean), np.array(relative),
                       largest.delta, largest.components[:7].copy(), gammas, along,
                       along_gamma_k, float(largest.samples(gammas).max()))
