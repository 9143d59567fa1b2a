"""volpath_mnee against a photon tracer written here: a flat slab at eta 1.3 under a point light.

Seen from straight above, annulus by annulus, the radiance must match a photon tracer in
numpy, from the light (no Mitsuba, no code shared with the integrator). The fast tier at a
few thousand pixel samples; the ``slow`` tier at enough to resolve a 2 % difference.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

mi_module = pytest.importorskip("mitsuba")

from manifold_scenes import jit_mitsuba  # noqa: E402
from translucent.reference import manifold_nee  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    return jit_mitsuba()


def _fresnel(cos_i, eta_i, eta_t):
    """Unpolarised Fresnel reflectance and the transmitted cosine (numpy)."""
    cos_i = np.abs(cos_i)
    sin2_t = (eta_i / eta_t) ** 2 * (1.0 - cos_i**2)
    cos_t = np.sqrt(np.clip(1.0 - sin2_t, 0.0, None))
    r_s = (eta_i * cos_i - eta_t * cos_t) / (eta_i * cos_i + eta_t * cos_t)
    r_p = (eta_t * cos_i - eta_i * cos_t) / (eta_t * cos_i + eta_i * cos_t)
    return np.where(sin2_t >= 1.0, 1.0, 0.5 * (r_s**2 + r_p**2)), cos_t


def photon_tracer(sigma_a, sigma_s, eta, thickness, height, edges, cone_degrees, photons,
                  rng, batches=8):
    """Radiance leaving a slab's top straight up, per annulus about the light's foot.

    A point light of unit intensity at ``height`` (mm) above the top of a laterally
    infinite slab (z in [-thickness, 0], isotropic scattering, index ``eta`` inside).
    Photons leave the light uniformly over the downward hemisphere (flux 2 pi / n each),
    are refracted in with weight 1 - F, walk with implicit absorption, and at each
    boundary leave with 1 - F and walk on with F; exits through the top within
    ``cone_degrees`` of the vertical are scored: radiance = flux / (annulus area x
    pi sin^2 cone). Returns (mean, standard error over batches) per annulus.
    """
    sigma_t = sigma_a + sigma_s
    albedo = sigma_s / sigma_t
    cos_cone = math.cos(math.radians(cone_degrees))
    projected_solid_angle = math.pi * (1.0 - cos_cone**2)
    areas = math.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    sums = np.zeros((batches, edges.size - 1))
    per_batch = photons // batches
    for batch in range(batches):
        uz = -rng.random(per_batch)
        phi = 2.0 * math.pi * rng.random(per_batch)
        sin_t = np.sqrt(1.0 - uz**2)
        ux, uy = sin_t * np.cos(phi), sin_t * np.sin(phi)
        x, y = ux * height / -uz, uy * height / -uz
        z = np.zeros(per_batch)
        reflected, cos_in = _fresnel(uz, 1.0, eta)
        weight = (1.0 - reflected) * (2.0 * math.pi / per_batch)
        ux, uy, uz = ux / eta, uy / eta, -cos_in
        floor = 1e-4 * 2.0 * math.pi / per_batch
        while weight.size:
            step = -np.log1p(-rng.random(weight.size)) / sigma_t
            up, down = uz > 0, uz < 0
            to_boundary = np.full(weight.size, np.inf)
            to_boundary[up] = -z[up] / uz[up]
            to_boundary[down] = (-thickness - z[down]) / uz[down]
            hit = step >= to_boundary
            travel = np.minimum(step, to_boundary)
            x, y, z = x + travel * ux, y + travel * uy, z + travel * uz
            reflected, cos_out = _fresnel(uz[hit], eta, 1.0)
            top = uz[hit] > 0
            leaving = weight[hit] * (1.0 - reflected)
            scored = top & (cos_out >= cos_cone)
            radius = np.hypot(x[hit][scored], y[hit][scored])
            annulus = np.searchsorted(edges, radius) - 1
            inside = (annulus >= 0) & (annulus < edges.size - 1)
            np.add.at(sums[batch], annulus[inside], leaving[scored][inside])
            weight[hit] *= reflected
            uz[hit] = -uz[hit]
            z[hit] = np.where(top, 0.0, -thickness)
            scatter = ~hit
            weight[scatter] *= albedo
            cos_new = 2.0 * rng.random(int(scatter.sum())) - 1.0
            phi = 2.0 * math.pi * rng.random(cos_new.size)
            sin_new = np.sqrt(1.0 - cos_new**2)
            ux[scatter], uy[scatter] = sin_new * np.cos(phi), sin_new * np.sin(phi)
            uz[scatter] = cos_new
            small = weight < floor
            survives = rng.random(weight.size) < 0.1  # Russian roulette: unbiased
            weight = np.where(small, np.where(survives, 10.0 * weight, 0.0), weight)
            alive = weight > 0
            x, y, z, ux, uy, uz, weight = (a[alive] for a in (x, y, z, ux, uy, uz, weight))
    radiance = sums / (areas * projected_solid_angle)
    return radiance.mean(axis=0), radiance.std(axis=0, ddof=1) / math.sqrt(batches)


SLAB = {"sigma_a": 0.1, "sigma_s": 0.9, "eta": 1.3, "thickness": 10.0, "height": 5.0}


def _slab_render(mi, size, spp, passes, half_width):
    from translucent.scenes.meshes import slab
    from translucent.scenes.raycast import to_mitsuba_mesh

    sigma_t = SLAB["sigma_a"] + SLAB["sigma_s"]
    medium = {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": [1.0] * 3},
              "albedo": {"type": "rgb", "value": [SLAB["sigma_s"] / sigma_t] * 3},
              "scale": sigma_t}
    thickness = SLAB["thickness"]
    shape = to_mitsuba_mesh(slab(60.0, 60.0, thickness, (0.0, -thickness / 2, 0.0), 8),
                            "slab", props={"bsdf": {"type": "dielectric",
                                                    "int_ior": SLAB["eta"]},
                                           "interior": medium})
    view = (mi.ScalarTransform4f().look_at(origin=[0, 50, 0], target=[0, 0, 0],
                                           up=[0, 0, -1])
            @ mi.ScalarTransform4f().scale([half_width, half_width, 1.0]))
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath_mnee", "max_depth": -1, "rr_depth": 5},
        "sensor": {"type": "orthographic", "to_world": view,
                   "film": {"type": "hdrfilm", "width": size, "height": size,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "slab": shape,
        "light": {"type": "point", "position": [0.0, SLAB["height"], 0.0],
                  "intensity": {"type": "rgb", "value": [1.0] * 3}}})
    images = np.array([np.array(mi.render(scene, spp=spp, seed=k))[..., 1]
                       for k in range(passes)], dtype=np.float64)
    return images, manifold_nee.counts(scene)


def _slab_check(mi, size, spp, passes, photons, annuli):
    half_width = 4.0
    edges = half_width * np.sqrt(np.arange(annuli + 1) / annuli)  # equal areas
    traced, traced_se = photon_tracer(SLAB["sigma_a"], SLAB["sigma_s"], SLAB["eta"],
                                      SLAB["thickness"], SLAB["height"], edges, 15.0,
                                      photons, np.random.default_rng(2))
    images, counted = _slab_render(mi, size, spp, passes, half_width)
    centres = (np.arange(size) + 0.5) / size * 2.0 * half_width - half_width
    radius = np.hypot(*np.meshgrid(centres, centres))
    annulus = np.searchsorted(edges, radius) - 1
    per_pass = np.array([[image[annulus == k].mean() for k in range(annuli)]
                         for image in images])
    rendered = per_pass.mean(axis=0)
    rendered_se = per_pass.std(axis=0, ddof=1) / math.sqrt(passes)
    z = (rendered - traced) / np.hypot(rendered_se, traced_se)
    assert counted["not_converged"] <= 1e-4 * counted["connections"], counted
    assert np.abs(z).max() < 3.5, f"rendered {rendered}, traced {traced}, z {z}"
    combined = (rendered - traced).sum() / np.sqrt((rendered_se**2 + traced_se**2).sum())
    assert abs(combined) < 3.0, f"all annuli together at z = {combined:.2f}"
    # the check can fail: a render 10 % too dark is told apart
    darker = (0.9 * rendered - traced).sum() / np.sqrt((rendered_se**2
                                                        + traced_se**2).sum())
    assert darker < -3.0, f"too noisy to tell 10 % (z = {darker:.2f})"


def test_a_slab_under_a_point_light_matches_an_independent_photon_tracer(mi):
    _slab_check(mi, 16, 32, 8, 300_000, 2)


@pytest.mark.slow
def test_a_slab_under_a_point_light_matches_an_independent_photon_tracer_converged(mi):
    _slab_check(mi, 32, 64, 16, 4_000_000, 4)
