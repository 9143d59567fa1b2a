"""Irradiance at the illumination samples, and the environment transfer.

Eq. 6 of Wang et al. 2008 from point, spot, directional, area and environment lights.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...materials.fresnel import fresnel_transmittance, transmitted_cosine
from ...scenes.lighting import (
    ENVIRONMENT_LIGHTS,
    SAMPLED_LIGHTS,
    direct_irradiance,
    environment_radiance,
)
from ..sparse_transport import (
    QuantisedRows,
    SparseRows,
    nonlinear_approximation,
)
from ..wavelets import (
    haar2d_forward,
    haar2d_support_weights,
)
from .knobs import FRESNEL_RANK
from .transfer import IlluminationSamples

# ------------------------------------------------------------------- lighting


def _far_distance(samples: IlluminationSamples) -> float:
    """Return a distance past the samples' extent (scene units), for rays to infinity."""
    return 10.0 * max(1.0, float(np.ptp(samples.positions, axis=0).max()))


def sample_irradiance(scene, samples: IlluminationSamples, lights, eta: float, *,
                      area_light_samples: int = 16, environment=None,
                      seed: int = 0) -> np.ndarray:
    r"""Irradiance :math:`E(x_i)` at the illumination samples (Eq. 6 of Wang et al. 2008).

    :math:`E = \int L\,F_t(\eta, \omega_i)\,(n \cdot \omega_i)\,d\omega_i` with shadows from
    ``scenes`` ray queries. Point, spot, directional, rectangle and sphere lights are
    sampled by :func:`translucent.scenes.lighting.light_samples` (``area_light_samples``
    per area light, drawn from one generator seeded with ``seed``); environment lights
    go through ``environment`` (an :class:`EnvironmentTransfer`).

    Parameters
    ----------
    scene : Scene
        For the ray queries (every object occludes).
    samples : IlluminationSamples
    lights : sequence of lights
    eta : float
        Index of refraction in :math:`F_t`.

    Returns
    -------
    ndarray, (N, 3), float64
        W per scene unit squared (the lights' units).
    """
    from ...scenes.raycast import visible

    far = _far_distance(samples)

    def occluded(rows, sample):
        if sample.target is None:
            ends = samples.positions[rows] + far * sample.direction[rows]
        else:
            ends = sample.target if np.ndim(sample.target) == 1 else sample.target[rows]
        return ~visible(scene, samples.positions[rows], ends, normals_a=samples.normals[rows],
                        normals_b=sample.target_normal)

    rng = np.random.default_rng(seed)
    irradiance = np.zeros((len(samples), 3))
    for light_index, light in enumerate(lights):
        if isinstance(light, ENVIRONMENT_LIGHTS):
            if environment is None:
                raise InputError("environment lighting needs the precomputed visibility",
                                 field="environment", value=None)
            irradiance += environment.irradiance(light, eta)
        elif isinstance(light, SAMPLED_LIGHTS):
            irradiance += direct_irradiance(
                [light], samples.positions, samples.normals, occluded=occluded,
                count=area_light_samples, rng=rng,
                response=lambda cosine: transmitted_cosine(eta, cosine))
        else:
            raise InputError(f"unknown light type {type(light).__name__}",
                             field=f"lights[{light_index}]", value=type(light).__name__)
    return irradiance


@functools.lru_cache(maxsize=4)
def fresnel_cosine_factors(rank: int = FRESNEL_RANK, *, resolution: int = 256):
    r"""Return a separable form :math:`F_t(\eta, \mu)\,\mu \approx \sum_j a_j(\eta)\,c_j(\mu)`.

    By SVD over :math:`\eta \in [1, 3]` and :math:`\mu \in [0, 1]`: environment visibility
    (which must not depend on the material) is precomputed with each :math:`c_j`, and the
    :math:`a_j(\eta)` of the current material combine them at run time.

    Returns
    -------
    mu : ndarray, (resolution,)
    factors : ndarray, (rank, resolution)
        :math:`c_j` on ``mu``.
    weights : callable
        ``weights(eta) -> (rank,)``: the :math:`a_j`.
    error : float
        Largest absolute error of the approximation on the grid (the function peaks at ~1).
    """
    mu = np.linspace(0.0, 1.0, resolution)
    etas = np.linspace(1.0, 3.0, resolution)
    values = fresnel_transmittance(etas[:, None], mu[None, :]) * mu[None, :]
    _, _, right = np.linalg.svd(values, full_matrices=False)
    factors = right[:rank]

    def weights(eta):
        row = fresnel_transmittance(float(eta), mu) * mu
        return factors @ row

    error = float(np.abs(values - (values @ factors.T) @ factors).max())
    return mu, factors, weights, error


def _environment_directions(resolution: int):
    """Cell-centre directions (Mitsuba's lat-long convention) of a res x 2 res grid, two squares."""
    theta = math.pi * (np.arange(resolution) + 0.5) / resolution
    phi = 2.0 * math.pi * (np.arange(2 * resolution) + 0.5) / (2 * resolution)
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    directions = np.stack([np.sin(phi) * np.sin(theta), np.cos(theta),
                           -np.cos(phi) * np.sin(theta)], axis=-1)
    solid_angle = (math.pi / resolution) ** 2 * np.sin(theta)
    # two squares: phi in [0, pi) then [pi, 2 pi); each row-major
    squares = np.concatenate([directions[:, :resolution], directions[:, resolution:]], axis=0)
    angles = np.concatenate([solid_angle[:, :resolution], solid_angle[:, resolution:]], axis=0)
    return squares.reshape(-1, 3), angles.reshape(-1)


@dataclass(frozen=True, eq=False)
class EnvironmentTransfer:
    r"""Precomputed wavelet-compressed visibility of the environment at every sample.

    Rows ``j * N + i``: Haar coefficients (over the two squares of the direction grid) of
    :math:`V_i(\omega)\,c_j(n_i \cdot \omega)\,d\omega`, where :math:`c_j` are the
    :func:`fresnel_cosine_factors`; Sect. 3.3 of Wang et al. 2008, "Environment lighting".
    """

    resolution: int
    transport: QuantisedRows
    samples: int

    def irradiance(self, light, eta: float) -> np.ndarray:
        """E at the samples for one environment light and index ``eta``, (N, 3)."""
        directions, _ = _environment_directions(self.resolution)
        radiance = environment_radiance(light, directions)
        images = radiance.T.reshape(3, 2, self.resolution, self.resolution)
        radiance_w = haar2d_forward(images.astype(np.float32)).reshape(3, -1).T
        products = self.transport.product(radiance_w).reshape(FRESNEL_RANK, self.samples, 3)
        _, _, weights, _ = fresnel_cosine_factors()
        return np.einsum("j,jnc->nc", weights(eta), products.astype(np.float64))


def precompute_environment(scene, samples: IlluminationSamples, resolution: int,
                           terms: int) -> EnvironmentTransfer:
    """Visibility of ``resolution x 2 resolution`` directions from every sample, compressed.

    Rays from every sample towards every direction of its upper hemisphere
    (:func:`translucent.scenes.visible`); each row, weighted by the solid angle and one
    Fresnel-cosine factor, is Haar-transformed over the two squares of the direction grid
    and cut to its ``terms`` largest coefficients.
    """
    from ...scenes.raycast import visible

    directions, solid_angle = _environment_directions(resolution)
    mu_grid, factors, _, _ = fresnel_cosine_factors()
    far = _far_distance(samples)
    block = max(1, (1 << 20) // len(directions))
    # ranked by support: the lighting is smooth where visibility has sharp horizons, so the
    # coarse coefficients matter more than their size says (measured on a constant
    # environment, 64 of 512 terms: 2.6 % worst-sample error by magnitude)
    ranking = haar2d_support_weights(2, resolution)
    pieces: list[list[SparseRows]] = [[] for _ in range(FRESNEL_RANK)]
    for start in range(0, len(samples), block):
        stop = min(start + block, len(samples))
        cosine = samples.normals[start:stop] @ directions.T
        where = np.nonzero(cosine > 0)
        seen = np.zeros(cosine.shape, dtype=bool)
        if len(where[0]):
            origins = samples.positions[start:stop][where[0]]
            seen[where] = visible(scene, origins, origins + far * directions[where[1]],
                                  normals_a=samples.normals[start:stop][where[0]])
        for j in range(FRESNEL_RANK):
            factor = np.interp(np.clip(cosine, 0.0, 1.0), mu_grid, factors[j])
            rows = np.where(seen, factor * solid_angle, 0.0).astype(np.float32)
            images = haar2d_forward(rows.reshape(-1, 2, resolution, resolution))
            pieces[j].append(nonlinear_approximation(images.reshape(stop - start, -1), 1.0,
                                                     terms, weights=ranking))
    stacked = SparseRows.concatenate([piece for rows in pieces for piece in rows])
    return EnvironmentTransfer(resolution, stacked.quantised(), len(samples))
