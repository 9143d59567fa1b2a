"""The same physical scene in other units renders the same image (scenes/frame.py).

Before the rendering frame, Mitsuba's float32 ray offset skipped a shell of medium of a
fixed size in scene units: the Skin1 sphere below in units a hundred times smaller lost
1.5 / 5.8 / 12 % (R G B) of its light. The scenes here are rescaled by hand, not by
:class:`~translucent.scenes.frame.Frame`, so that the check does not share the code it
checks.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from translucent.materials import measured_medium
from translucent.reference import render
from translucent.scenes import Camera, Mesh, PointLight, Scene, SceneObject
from translucent.scenes.meshes import icosphere

#: Units per unit of the 1x scene.
SCALES = (0.01, 0.1, 10.0)
#: Standard errors at most between two scales' object means (per channel).
Z_LIMIT = 3.0
#: And at most this relative difference.
RELATIVE_LIMIT = 1e-3


def _sphere(scale: float, shift=(0.0, 0.0, 0.0), size: int = 12) -> Scene:
    """The Skin1 sphere of radius 10 mm under a point light, in units ``1 / scale`` of 10 mm,
    the whole scene moved by ``shift`` (those units)."""
    shift = np.asarray(shift, dtype=np.float64)
    sphere = icosphere(3, 1.0)
    mesh = Mesh(sphere.vertices * scale + shift, sphere.faces, sphere.normals)
    camera = Camera(origin=np.array([0.0, 0.0, 5.0]) * scale + shift, target=shift,
                    fov=30.0, width=size, height=size)
    # irradiance I / d^2 stays when d scales: I scales with its square
    light = PointLight(np.array([3.0, 4.0, 4.0]) * scale + shift, 100.0 * scale**2)
    material = dataclasses.replace(measured_medium("Skin1"), eta=1.0)
    return Scene([SceneObject("sphere", mesh, material)], [light], camera,
                 mm_per_unit=10.0 / scale, name="sphere")


def _object_mean(image):
    """Per channel: the image's mean and its standard error (the background is black)."""
    count = image.rgb.shape[0] * image.rgb.shape[1]
    return image.rgb.mean(axis=(0, 1)), np.sqrt(image.variance.sum(axis=(0, 1))) / count


def _check_same(first, second, what):
    (a, sa), (b, sb) = _object_mean(first), _object_mean(second)
    z = (a - b) / np.hypot(sa, sb)
    assert np.all(np.abs(z) < Z_LIMIT), (what, a / b, z)
    assert np.all(np.abs(a / b - 1.0) < RELATIVE_LIMIT), (what, a / b, z)


@pytest.mark.parametrize("integrator,profile,spp,size", [
    ("volpath", None, 32, 12), ("volpathmis", None, 32, 12),
    # the Python integrator: 17 s; its own crossing test below stays in the fast tier
    pytest.param("volpath_mnee", None, 4, 6, marks=pytest.mark.slow),
    ("bssrdf_path", "better_dipole", 16, 12)])
def test_the_unit_does_not_change_the_image(integrator, profile, spp, size):
    # in RGB: volpath_mnee would render one channel at a time, three times the cost
    options = dict(spp=spp, passes=3, cache=False, progress=False, integrator=integrator,
                   profile=profile, per_channel=False)
    base = render(_sphere(1.0, size=size), **options)
    assert _object_mean(base)[0].min() > 0
    for scale in SCALES:
        _check_same(render(_sphere(scale, size=size), **options), base, (integrator, scale))


def test_the_origin_does_not_change_the_image():
    # far from the origin, float32 has fewer digits for the sphere: the frame centres it
    options = dict(spp=32, passes=4, cache=False, progress=False)
    _check_same(render(_sphere(1.0, shift=(300.0, -200.0, 500.0)), **options),
                render(_sphere(1.0), **options), "moved")


def test_the_check_tells_the_offset_shell():
    """The offset the frame removes, put back by hand, is seen: the test can fail."""
    from translucent.reference import mitsuba_scene
    from translucent.scenes.frame import Frame

    options = dict(spp=32, passes=4, cache=False, progress=False)
    base = render(_sphere(1.0), **options)
    original = mitsuba_scene.rendering_frame
    try:
        # the 0.01x scene rendered as the suite did before: in its own units
        mitsuba_scene.rendering_frame = lambda scene: Frame((0.0, 0.0, 0.0), 1.0)
        small = render(_sphere(0.01), **options)
    finally:
        mitsuba_scene.rendering_frame = original
    ratio = _object_mean(small)[0] / _object_mean(base)[0]
    assert ratio[2] < 0.95, ratio  # blue lost about 12 %
    assert math.isfinite(ratio.sum())


@pytest.mark.slow  # 10-17 s of the fast tier; the frame's own sweeps above stay fast
def test_volpath_mnee_starts_the_medium_at_the_crossing():
    """volpath_mnee samples a medium from where the path crossed into it, not from the
    offset origin: rendered where the offset is 30 times the frame's (the sphere 30 units
    off the origin, no rendering frame), it keeps the frame's image; volpath loses blue."""
    from translucent.reference import mitsuba_scene
    from translucent.scenes.frame import Frame

    ratios = {}
    for integrator in ("volpath_mnee", "volpath"):
        options = dict(spp=512, passes=4, cache=False, progress=False, integrator=integrator,
                       per_channel=False)
        framed = render(_sphere(1.0, size=8), **options)
        original = mitsuba_scene.rendering_frame
        try:
            mitsuba_scene.rendering_frame = lambda scene: Frame((-30.0, -30.0, -30.0), 1.0)
            far = render(_sphere(1.0, size=8), **options)
        finally:
            mitsuba_scene.rendering_frame = original
        (a, sa), (b, sb) = _object_mean(far), _object_mean(framed)
        ratios[integrator] = a / b
        if integrator == "volpath_mnee":
            z = (a - b) / np.hypot(sa, sb)
            assert np.all(np.abs(z) < Z_LIMIT), (a / b, z)
            assert np.all(np.abs(a / b - 1.0) < 0.01), (a / b, z)
    assert ratios["volpath"][2] < 0.98, ratios  # the shell it skips there: about 4 % of blue
