r"""Stability of multiresolution splatting (:mod:`translucent.fast.splatting`).

The heterogeneous scene's mesh at 48 x 36 pixels (32^2 irradiance texels) under a
directional light from overhead to grazing (90 .. 0.5 degrees above the horizon), with a
homogeneous SubEdit profile (ln P falling by 8 over its support) whose support :math:`r_s`
runs from far below a pixel to far beyond the object (1e-4 .. 1e4 mm); and the camera
turned away from the object (empty buffers). Invariants: the frame is finite and
non-negative; with nothing in view it is black. Against brute-force Eq. 5 on the same
buffers (:meth:`~translucent.fast.splatting.SplattingState.render_ground_truth`) the
relative L1 error is compared wherever brute force itself sees the profile. A support below
the buffers' spacing is lost by both alike, since Eq. 5 samples the profile at the
buffers' points: at 0.01 mm brute force totals 6e-32 against 8 at 1 mm, and the splats 0.
Such a material should look like a surface of albedo :math:`R_d`; neither Eq. 5 nor the
paper has that local term.
"""

from __future__ import annotations

import itertools

import numpy as np

from ...materials.subedit import SubEditProfiles
from ...scenes import Camera, DirectionalLight, load_scene
from ..bench import with_size
from . import StressResult, count_nonfinite, stress_kernel

SUPPORTS_MM = (1e-4, 1e-2, 1.0, 10.0, 100.0, 1e4)
ELEVATIONS_DEG = (90.0, 30.0, 5.0, 0.5)
WIDTH, HEIGHT, IRRADIANCE = 48, 36, 32
#: Splats stop at each profile's effective range (95 % of its energy), and at 48 x 36
#: pixels the coarse levels cover few pixels: measured worst 8.6 % (support 1 mm, light
#: from overhead), 5-6 % at 10-100 mm, 0.1 % when the whole object is in range.
BOUND = 0.15
#: A frame whose brute-force total is below this share of the brightest case's has an
#: unresolved profile: compared for finiteness only.
RESOLVED = 1e-12


@stress_kernel("splatting over profile supports and light angles")
def splatting_sweep(supports=SUPPORTS_MM, elevations=ELEVATIONS_DEG) -> StressResult:
    """Splatted and brute-force frames over supports (mm) and light elevations (degrees)."""
    from ...fast import splatting

    base = with_size(load_scene("heterogeneous"), WIDTH, HEIGHT)
    result = StressResult(evaluations=0, bound=BOUND, against="brute-force Eq. 5",
                          notes="the 95 %-energy truncation plus the coarse levels at "
                                "48 x 36 pixels; unresolved supports checked for finiteness")
    frames = []
    for support, elevation in itertools.product(supports, elevations):
        material = SubEditProfiles(np.tile(np.linspace(0.0, -8.0, 9)[:, None], (1, 3)),
                                   support)
        angle = np.radians(elevation)
        scene = base.with_lights([DirectionalLight(
            direction=np.array([np.cos(angle), -np.sin(angle), 0.0]),
            irradiance=np.ones(3))])
        state = splatting.precompute(scene, irradiance_resolution=IRRADIANCE)
        image = state.render(material=material).rgb
        truth = state.render_ground_truth(material=material).rgb
        count_nonfinite(image, result)
        result.evaluations += image.size
        frames.append((support, elevation, image, truth))
    brightest = max(float(truth.sum()) for _, _, _, truth in frames)
    for support, elevation, image, truth in frames:
        total = float(truth.sum())
        case = {"support_mm": support, "elevation_deg": elevation, "truth_total": total,
                "splat_total": float(image.sum())}
        if total > RESOLVED * brightest:
            error = float(np.abs(image - truth).sum() / total)
            case["relative_error"] = error
            if error > result.worst_relative_error:
                result.worst_relative_error = error
                result.worst_at = {"support_mm": support, "elevation_deg": elevation}
        result.details.append(case)
    # the camera turned away: nothing to splat, a black frame
    camera = base.camera
    away = base.with_camera(Camera(origin=camera.origin,
                                   target=2.0 * camera.origin - camera.target, up=camera.up,
                                   fov=camera.fov, width=WIDTH, height=HEIGHT))
    empty = splatting.precompute(away, irradiance_resolution=IRRADIANCE).render().rgb
    count_nonfinite(empty, result)
    result.evaluations += empty.size
    result.negative += int(np.count_nonzero(empty))
    result.details.append({"camera": "turned away", "nonzero_pixels":
                           int(np.count_nonzero(empty))})
    return result
