"""The independent expectations ``bssrdf_path`` is checked against (numpy, no integrator code).

* :func:`slab_radiance`: radiance seen straight down on a flat half-space lit by a spot
  beam, the profile's ``reflection`` convolved with the beam's Fresnel-weighted irradiance
  (a polar quadrature about each point), times the exit term at normal exit.
* :func:`sphere_radiance`: radiance of a translucent mesh under a point light by dense
  quadrature over its triangles (centroids of a barycentric subdivision), shadows from the
  faces' own planes (the mesh is convex), camera rays through Mitsuba as an intersection
  engine (:func:`translucent.scenes.raycast.trace`), supersampled over each pixel.

Fresnel terms are this module's own, and the exit normalisation its own quadrature.
"""

from __future__ import annotations

import math

import numpy as np

#: Radius, in element spacings, of the disk about an exit point integrated in polar form.
NEAR_FIELD = 4.0

#: Directions of the near field's polar quadrature of a heterogeneous BSSRDF.
NEAR_ANGLES = 16

#: Cosine nodes of the exit normalisation's quadrature (midpoint rule; the integrand is
#: smooth in the cosine: 1e-9 against 4x the nodes).
NORMALISATION_NODES = 200_000


def fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance from outside (index 1) into ``eta`` at ``cos_i``."""
    cos_i = np.clip(np.abs(cos_i), 0.0, 1.0)
    sin2_t = (1.0 - cos_i**2) / eta**2
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    r_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    r_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (r_s**2 + r_p**2)


def exit_normalisation(eta) -> float:
    r"""Return :math:`\int F_t\cos\theta\,d\omega = 2\pi\int_0^1 (1 - F_r(\mu))\mu\,d\mu`."""
    mu = (np.arange(NORMALISATION_NODES) + 0.5) / NORMALISATION_NODES
    return float(2.0 * math.pi * np.mean((1.0 - fresnel(mu, eta)) * mu))


def exit_term(cos_o, eta):
    r""":math:`S_\omega = F_t(\cos\theta_o) / \int F_t\cos\,d\omega` (sr^-1)."""
    return (1.0 - fresnel(cos_o, eta)) / exit_normalisation(eta)


def spot_irradiance(points, spot, eta):
    """Irradiance entering a horizontal surface (y = 0) from a ``SpotLight``, W mm^-2.

    ``points``: (..., 2) (x, z) positions. Times the Fresnel transmittance of its incidence.
    """
    position = np.asarray(spot.position)
    offset = np.stack([points[..., 0] - position[0], np.full(points.shape[:-1], -position[1]),
                       points[..., 1] - position[2]], axis=-1)
    distance = np.linalg.norm(offset, axis=-1)
    direction = offset / distance[..., None]
    cosine = position[1] / distance
    intensity = float(np.mean(spot.intensity))
    return intensity * spot.falloff(direction) * cosine / distance**2 \
        * (1.0 - fresnel(cosine, eta))


def slab_exitance(radii, profile, spot, eta, reach, radial_nodes: int = 400,
                  arc_nodes: int = 128):
    r"""Exitance :math:`M(\rho)` at distances ``radii`` (mm) from the beam's foot, (N, 3).

    :math:`M(x) = \int\!\!\int R(s)\,E_t(x + s\,e^{i\psi})\,s\,ds\,d\psi` in polar
    coordinates about x, over the arcs of each circle that lie inside the beam's cone (Gauss-
    Legendre in the angle, trapezoidal in s: geometric from 0 where x is inside the beam).
    """
    beam = spot.position[1] * math.tan(math.radians(spot.cutoff_angle))
    nodes, weights = np.polynomial.legendre.leggauss(arc_nodes)
    out = np.zeros((len(radii), 3))
    for i, rho in enumerate(radii):
        low, high = max(0.0, rho - beam), min(rho + beam, reach)
        if low == 0.0:
            s = np.concatenate([[0.0], np.geomspace(1e-6 * high, high, radial_nodes)])
        else:
            s = low + (high - low) * 0.5 * (1.0 - np.cos(np.linspace(0, np.pi, radial_nodes)))
        with np.errstate(divide="ignore", invalid="ignore"):
            cosine = (rho**2 + s**2 - beam**2) / (2.0 * rho * s)
        half = np.where(np.isfinite(cosine), np.arccos(np.clip(cosine, -1.0, 1.0)), np.pi)
        psi = half[:, None] * nodes[None, :]
        points = np.stack([rho - s[:, None] * np.cos(psi), s[:, None] * np.sin(psi)], axis=-1)
        arc = half * (spot_irradiance(points, spot, eta) * weights).sum(axis=1)
        out[i] = np.trapezoid(profile.reflection(s) * (s * arc)[:, None], s, axis=0)
    return out


def sphere_radiance(scene, obj_index, profile_values, eta, light, subdivide, supersample,
                    cut, pair_values=None):
    """Per-pixel radiance of a convex translucent mesh under a point light, and coverage.

    Returns the radiance (H, W, 3) and the fraction of each pixel's rays that see the
    object (H, W).

    ``profile_values(r)`` gives R (mm^-2, shape ``r.shape + (3,)``) at r mm; nothing beyond
    ``cut`` mm. A heterogeneous BSSRDF gives ``pair_values(xo, xi, r)`` instead (exit points
    (K, 3) and entry points (P, 3) in scene units, their distances (K, P) in mm: R of shape
    (K, P, 3)); its near field is then integrated over :data:`NEAR_ANGLES` directions of
    the exit point's tangent disk (the rule may change across it). Every face is split into
    ``subdivide``^2 triangles whose centroids carry
    their area; a centroid is lit where the light lies outside its face's plane and in
    front of its interpolated normal. Near the exit point, where a profile that goes as
    1/r defeats the centroid rule, R is split by a smooth step w(r) rising from 0 at half
    of :data:`NEAR_FIELD` element spacings to 1 at them: w R is summed over the elements,
    (1 - w) R integrated in polar form over a flat disk times the entering power density at
    the exit point.
    """
    from translucent.scenes.gbuffer import camera_frame
    from translucent.scenes.raycast import trace

    mesh = scene.objects[obj_index].mesh
    mpu = scene.mm_per_unit
    vertices, faces, normals = mesh.vertices, mesh.faces, mesh.normals
    n = subdivide
    # barycentric centroids of the n^2 sub-triangles
    bary = []
    for i in range(n):
        for j in range(n - i):
            bary.append(((i + 1 / 3) / n, (j + 1 / 3) / n))
            if i + j < n - 1:
                bary.append(((i + 2 / 3) / n, (j + 2 / 3) / n))
    bary = np.array(bary)
    weights = np.stack([bary[:, 0], bary[:, 1], 1.0 - bary.sum(axis=1)], axis=1)
    corners = vertices[faces]  # (F, 3, 3)
    points = np.einsum("kc,fcd->fkd", weights, corners).reshape(-1, 3)
    shading = np.einsum("kc,fcd->fkd", weights, normals[faces]).reshape(-1, 3)
    shading /= np.linalg.norm(shading, axis=-1, keepdims=True)
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    geometric = np.repeat(cross / np.linalg.norm(cross, axis=-1, keepdims=True), len(bary), 0)
    area = np.repeat(0.5 * np.linalg.norm(cross, axis=-1) / len(bary), len(bary))
    to_light = np.asarray(light.position) - points
    distance = np.linalg.norm(to_light, axis=-1)
    to_light /= distance[:, None]
    cos_i = np.sum(to_light * shading, axis=-1)
    lit = (np.sum(to_light * geometric, axis=-1) > 0) & (cos_i > 0)
    intensity = np.asarray(light.intensity, dtype=np.float64)
    # power entering each element per unit intensity: lengths in scene units, as Mitsuba
    # renders them (radiance per unit^2), the profile's mm^-2 times mpu^2 below
    entering = np.where(lit, (1.0 - fresnel(cos_i, eta)) * cos_i / distance**2 * area, 0.0)
    keep = entering > 0
    points, entering = points[keep], entering[keep]
    near = NEAR_FIELD * math.sqrt(area.mean()) * mpu  # mm

    def step(r):  # 0 below near / 2, 1 beyond near, C1 in between
        t = np.clip(2.0 * r / near - 1.0, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)

    s = np.concatenate([[0.0], np.geomspace(1e-7 * near, near, 4000)])  # mm

    def near_energy(values):  # the energy of (1 - w) R about the exit point
        return np.trapezoid(2.0 * math.pi * s[:, None] * (1.0 - step(s))[:, None] * np.where(
            (s <= cut)[:, None], values(s), 0.0), s, axis=0)

    inner = None if pair_values is not None else near_energy(profile_values)

    camera = scene.camera
    forward, left, up = camera_frame(camera)
    tan_x = math.tan(math.radians(camera.fov) / 2.0)
    tan_y = tan_x * camera.height / camera.width
    offsets = (np.arange(supersample) + 0.5) / supersample
    sx = (np.arange(camera.width)[:, None] + offsets[None, :]).ravel() / camera.width
    sy = (np.arange(camera.height)[:, None] + offsets[None, :]).ravel() / camera.height
    x = tan_x * (1.0 - 2.0 * sx)
    y = tan_y * (1.0 - 2.0 * sy)
    directions = forward + x[None, :, None] * left + y[:, None, None] * up
    directions = directions.reshape(-1, 3)
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    hits = trace(scene, camera.origin, directions)
    radiance = np.zeros((len(directions), 3))
    seen = np.flatnonzero(hits.hit & (hits.object_id == obj_index))
    cos_o = np.sum(-directions[seen] * hits.shading_normal[seen], axis=-1)
    outside = np.sum(-directions[seen] * hits.geometric_normal[seen], axis=-1) > 0
    # the entering power density (per unit area and intensity) at each exit point
    xo_all = hits.position[seen]
    towards = np.asarray(light.position) - xo_all
    gap = np.linalg.norm(towards, axis=-1)
    towards /= gap[:, None]
    cos_x = np.sum(towards * hits.shading_normal[seen], axis=-1)
    lit_x = (np.sum(towards * hits.geometric_normal[seen], axis=-1) > 0) & (cos_x > 0)
    density = np.where(lit_x, (1.0 - fresnel(cos_x, eta)) * cos_x / gap**2, 0.0)
    for start in range(0, len(seen), 64):
        chunk = slice(start, start + 64)
        xo = xo_all[chunk]
        r = np.linalg.norm(xo[:, None, :] - points[None, :, :], axis=-1) * mpu
        at = profile_values(r) if pair_values is None else pair_values(xo, points, r)
        values = np.where((r <= cut)[..., None], at, 0.0) * (step(r) * mpu**2)[..., None]
        exitance = np.einsum("kp,kpc->kc", np.broadcast_to(entering, r.shape), values)
        near_field = inner[None, :] if pair_values is None else _near_disk(
            xo, hits.shading_normal[seen][chunk], pair_values, s[s <= near][::10], step,
            cut, mpu)
        exitance += density[chunk, None] * near_field
        radiance[seen[chunk]] = exitance * intensity * (
            exit_term(cos_o[chunk], eta) * outside[chunk])[:, None]
    image = radiance.reshape(camera.height, supersample, camera.width, supersample, 3)
    seen_here = np.zeros(len(directions))
    seen_here[seen] = 1.0
    coverage = seen_here.reshape(camera.height, supersample, camera.width, supersample)
    return image.mean(axis=(1, 3)), coverage.mean(axis=(1, 3))


def _near_disk(xo, normals, pair_values, radii, step, cut, mpu):
    """The energy of (1 - w) R over each exit point's tangent disk, (K, 3), by polar quadrature.

    ``radii`` in mm (from 0); :data:`NEAR_ANGLES` midpoint directions about the normal.
    """
    out = np.zeros((len(xo), 3))
    angles = (np.arange(NEAR_ANGLES) + 0.5) / NEAR_ANGLES * 2.0 * math.pi
    for k in range(len(xo)):
        n = normals[k]
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t1 = np.cross(n, helper)
        t1 /= np.linalg.norm(t1)
        t2 = np.cross(n, t1)
        directions = np.cos(angles)[:, None] * t1 + np.sin(angles)[:, None] * t2
        points = xo[k] + (radii[:, None, None] / mpu) * directions[None]  # (S, A, 3)
        r = np.repeat(radii, NEAR_ANGLES)[None, :]
        values = pair_values(xo[k:k + 1], points.reshape(-1, 3), r)[0]
        mean = values.reshape(len(radii), NEAR_ANGLES, 3).mean(axis=1)
        mean = np.where((radii <= cut)[:, None], mean, 0.0)
        out[k] = np.trapezoid(2.0 * math.pi * radii[:, None] * (1.0 - step(radii))[:, None]
                              * mean, radii, axis=0)
    return out


def assert_images_match_quadrature(images, expected, coverage, *, global_z: float = 4.0):
    """Assert that a tracer's passes agree with a quadrature's image, within their noise.

    ``images``: the passes (P, H, W, 3); ``expected`` and ``coverage`` from
    :func:`sphere_radiance`. Over the pixels the object covers whole (the silhouette's
    partial coverage is the camera's business, not the BSSRDF's): a per-pixel z-test, the
    summed difference of the lit pixels within ``global_z`` standard errors per channel, and
    a 5 % drift of the expectation outside them (the check can tell it). Returns the masked
    ``(mean, expected, variance)``.
    """
    from translucent.image import Image
    from translucent.reports.metrics.statistics import z_test_known_variance

    passes = len(images)
    inside = coverage == 1.0
    assert inside.sum() >= 16
    mean = np.where(inside[..., None], images.mean(axis=0), 0.0)
    variance = np.where(inside[..., None], images.var(axis=0, ddof=1) / passes, 0.0)
    expected = np.where(inside[..., None], expected, 0.0)
    result = z_test_known_variance(Image(mean, variance), Image(expected, np.zeros_like(mean)),
                                   passes=(passes, None))
    assert result.passed, result.summary()
    lit = inside & (expected[..., 1] > 1e-3 * expected[..., 1].max())
    spread = np.sqrt(variance[lit].sum(axis=0))
    z = (mean[lit] - expected[lit]).sum(axis=0) / spread
    assert np.abs(z).max() < global_z, (z, mean[lit].sum(axis=0) / expected[lit].sum(axis=0))
    drifted = (mean[lit] - 1.05 * expected[lit]).sum(axis=0) / spread
    assert np.abs(drifted).min() > global_z, drifted
    return mean, expected, variance
