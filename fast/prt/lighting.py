"""Irradiance at the illumination samples, and the environment transfer.

Eq. 6 of Wang et al. 2008 from point, spot, directional, area and environment lights.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ...materials.fresnel import fresnel_transmittance
from ...scenes.lighting import environment_radiance
from ...scenes.scene import (
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    SphereAreaLight,
    SpotLight,
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


def _transmitted_cosine(eta, cosine):
    r""":math:`F_t(\eta, n \cdot \omega_i)\,(n \cdot \omega_i)` of Eq. 6, 0 from below."""
    return np.where(cosine > 0, fresnel_transmittance(eta, np.clip(cosine, 0, 1)) * cosine, 0.0)


def _far_distance(samples: IlluminationSamples) -> float:
    """Return a distance past the samples' extent (scene units), for rays to infinity."""
    return 10.0 * max(1.0, float(np.ptp(samples.positions, axis=0).max()))


def _point_irradiance(samples, position, eta, falloff=None):
    offset = position - samples.positions
    squared = np.maximum(np.einsum("nd,nd->n", offset, offset), 1e-300)
    direction = offset / np.sqrt(squared)[:, None]
    cosine = np.einsum("nd,nd->n", samples.normals, direction)
    weight = _transmitted_cosine(eta, cosine) / squared
    if falloff is not None:
        weight = weight * falloff(-direction)
    return weight, direction


def _stratified_unit_square(count: int, seed: int) -> np.ndarray:
    side = int(math.ceil(math.sqrt(count)))
    rng = np.random.default_rng(seed)
    cells = np.stack(np.meshgrid(np.arange(side), np.arange(side), indexing="ij"), -1)
    cells = cells.reshape(-1, 2)[:count]
    return (cells + rng.random(cells.shape)) / side


def _rectangle_points(light: RectangularAreaLight, count: int, seed: int):
    """Stratified points on a rectangle emitter, its normal, and the area each stands for."""
    uv = _stratified_unit_square(count, seed)
    points = light.center + (2 * uv[:, :1] - 1) * light.u_axis + \
        (2 * uv[:, 1:] - 1) * light.v_axis
    return points, light.normal, light.area / len(points)


def _sphere_light_directions(light: SphereAreaLight, samples: IlluminationSamples,
                             count: int, seed: int):
    r"""Stratified directions in the cone each sample sees the sphere in, and their hit points.

    Solid-angle sampling of a sphere emitter: every direction stands for
    :math:`2\pi(1 - \cos\alpha)/n` sr, where :math:`\sin\alpha = \rho / d`.
    Yields ``(directions (N, 3), points (N, 3), solid angle (N,))`` per stratum; samples
    inside the sphere get a zero solid angle.
    """
    uv = _stratified_unit_square(count, seed)
    offset = light.center - samples.positions
    distance = np.linalg.norm(offset, axis=1)
    axis = offset / np.maximum(distance, 1e-300)[:, None]
    outside = distance > light.radius
    sin_alpha = np.where(outside, light.radius / np.maximum(distance, 1e-300), 1.0)
    cos_alpha = np.sqrt(np.clip(1.0 - sin_alpha**2, 0.0, 1.0))
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangent = np.cross(axis, helper)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(axis, tangent)
    solid_angle = np.where(outside, 2.0 * np.pi * (1.0 - cos_alpha) / len(uv), 0.0)
    for u, v in uv:
        cos_theta = 1.0 - u * (1.0 - cos_alpha)
        sin_theta = np.sqrt(np.clip(1.0 - cos_theta**2, 0.0, 1.0))
        phi = 2.0 * np.pi * v
        direction = (cos_theta[:, None] * axis + (sin_theta * np.cos(phi))[:, None] * tangent
                     + (sin_theta * np.sin(phi))[:, None] * bitangent)
        along = distance * cos_theta
        reach = along - np.sqrt(np.clip(light.radius**2 - (distance * sin_theta) ** 2, 0.0,
                                        None))
        yield direction, samples.positions + reach[:, None] * direction, solid_angle


def _shadow(scene, samples: IlluminationSamples, weight, targets, target_normal) -> None:
    """Zero ``weight`` where a sample with ``weight > 0`` does not see its target point."""
    from ...scenes.raycast import visible

    lit = np.flatnonzero(weight > 0)
    if not len(lit):
        return
    targets = np.asarray(targets, dtype=np.float64)
    ends = targets[lit] if targets.ndim == 2 else targets
    seen = visible(scene, samples.positions[lit], ends, normals_a=samples.normals[lit],
                   normals_b=target_normal)
    weight[lit[~seen]] = 0.0


def sample_irradiance(scene, samples: IlluminationSamples, lights, eta: float, *,
                      area_light_samples: int = 16, environment=None,
                      seed: int = 0) -> np.ndarray:
    r"""Irradiance :math:`E(x_i)` at the illumination samples (Eq. 6 of Wang et al. 2008).

    :math:`E = \int L\,F_t(\eta, \omega_i)\,(n \cdot \omega_i)\,d\omega_i` with shadows from
    ``scenes`` ray queries: point and spot lights (Mitsuba's linear-in-angle spot profile),
    directional lights, rectangle emitters (``area_light_samples`` stratified points on the
    rectangle) and sphere emitters (as many stratified directions in the cone each sample
    sees the sphere in), and environment lights through ``environment`` (an
    :class:`EnvironmentTransfer`).

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
    irradiance = np.zeros((len(samples), 3))
    for light_index, light in enumerate(lights):
        if isinstance(light, (PointLight, SpotLight)):
            falloff = light.falloff if isinstance(light, SpotLight) else None
            weight, _ = _point_irradiance(samples, light.position, eta, falloff)
            _shadow(scene, samples, weight, light.position, None)
            irradiance += weight[:, None] * light.intensity
        elif isinstance(light, DirectionalLight):
            cosine = samples.normals @ -light.direction
            weight = _transmitted_cosine(eta, cosine)
            far = _far_distance(samples)
            _shadow(scene, samples, weight, samples.positions - far * light.direction, None)
            irradiance += weight[:, None] * light.irradiance
        elif isinstance(light, RectangularAreaLight):
            points, normal, patch = _rectangle_points(light, area_light_samples,
                                                      seed + light_index)
            for point in points:
                weight, direction = _point_irradiance(samples, point, eta)
                weight *= np.clip(-(direction @ normal), 0.0, None) * patch
                _shadow(scene, samples, weight, point, normal)
                irradiance += weight[:, None] * light.radiance
        elif isinstance(light, SphereAreaLight):
            for direction, points, solid_angle in _sphere_light_directions(
                    light, samples, area_light_samples, seed + light_index):
                cosine = np.einsum("nd,nd->n", samples.normals, direction)
                weight = _transmitted_cosine(eta, cosine) * solid_angle
                _shadow(scene, samples, weight, points, None)
                irradiance += weight[:, None] * light.radiance
        elif isinstance(light, (ConstantEnvironment, ImageEnvironment)):
            if environment is None:
                raise InputError("environment lighting needs the precomputed visibility",
                                 field="environment", value=None)
            irradiance += environment.irradiance(light, eta)
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
