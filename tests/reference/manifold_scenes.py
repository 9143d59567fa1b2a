"""What the volpath_mnee test modules share: the JIT Mitsuba they run on, a medium, a sphere.

The tests run with ``--import-mode=importlib``; ``conftest.py`` puts this folder on
``sys.path`` so that the modules import this one by name.
"""

from __future__ import annotations

import pytest
from translucent.backend import mitsuba
from translucent.reference import manifold_nee


def jit_mitsuba():
    """Return Mitsuba in a JIT variant with volpath_mnee registered, or skip the test."""
    module = mitsuba()
    if not module.variant().startswith(("llvm_", "cuda_")):
        pytest.skip("volpath_mnee needs a JIT variant")
    manifold_nee.register()
    return module


#: The point light the sphere scenes are lit by.
POINT = {"type": "point", "position": [3.0, 4.0, 4.0],
         "intensity": {"type": "rgb", "value": [100.0, 100.0, 100.0]}}


def medium(sigma_t=(1.0, 1.0, 1.0)):
    """Return a homogeneous medium of albedo (0.9, 0.8, 0.7), extinction ``3 sigma_t``."""
    return {"type": "homogeneous", "sigma_t": {"type": "rgb", "value": list(sigma_t)},
            "albedo": {"type": "rgb", "value": [0.9, 0.8, 0.7]}, "scale": 3.0}


def sphere_scene(mi, integrator, boundary, light, size, sigma_t=(1.0, 1.0, 1.0),
                 **integrator_props):
    """Return a unit sphere of :func:`medium` behind ``boundary``, seen from 5 units."""
    from translucent.scenes.meshes import icosphere
    from translucent.scenes.raycast import to_mitsuba_mesh

    shape = to_mitsuba_mesh(icosphere(4, 1.0), "sphere",
                            props={"bsdf": boundary, "interior": medium(sigma_t)})
    camera = mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0])
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": integrator, "max_depth": -1, "rr_depth": 5,
                       **integrator_props},
        "sensor": {"type": "perspective", "fov": 30, "to_world": camera,
                   "film": {"type": "hdrfilm", "width": size, "height": size,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "sphere": shape, "light": light})
