r"""Blender Cycles as an independent renderer of the suite's scenes.

Cycles shares no code with Mitsuba or the suite and offsets no rays at surfaces, so it
checks the references where they could share a bias (the float32 shell of
:mod:`translucent.scenes.frame` was found this way). It runs in a separate Python, the one
that has ``bpy`` (the ``peers`` extra; the ``bpy`` wheel pins numpy below 2, so it usually
lives in an environment of its own):

* :func:`describe_scene` writes what Cycles needs of a scene as JSON: the camera, each
  mesh with its material (an index-matched homogeneous medium, or a Lambertian surface)
  and the point lights, every length in scene units and every coefficient per scene unit;
* :func:`render_cycles` runs ``blender_worker.py`` in that Python, one Cycles render a pass,
  and returns the mean of the passes with the variance of that mean, as the references.

Cycles' point light of ``energy`` P watts is not the suite's intensity I = P / (4 pi):
Blender's light units carry their own factor. :func:`render_cycles` writes P = 4 pi I and
the caller calibrates the factor on a Lambertian object under the same light (the factor is
a property of the light, not of the material), as ``tests/reference/test_cycles.py`` does.

Set-up (not in the default install)::

    python3.11 -m venv peers && peers/bin/pip install bpy
    export TRANSLUCENT_BPY_PYTHON=$PWD/peers/bin/python
"""

from __future__ import annotations

import importlib.util
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...image import Image
from ...materials import Dipole, Lambertian
from ...scenes import PointLight, Scene

__all__ = ["BPY_PYTHON_VARIABLE", "bpy_python", "describe_scene", "render_cycles"]

#: The environment variable that names a Python with ``bpy``.
BPY_PYTHON_VARIABLE = "TRANSLUCENT_BPY_PYTHON"

#: Where the worker script lives (run by the ``bpy`` Python, not imported here).
WORKER = Path(__file__).resolve().parent / "blender_worker.py"

INSTALL_HINT = (f"Blender Cycles needs a Python 3.11 with bpy: python3.11 -m venv peers && "
                f"peers/bin/pip install bpy, then {BPY_PYTHON_VARIABLE}=peers/bin/python")


def bpy_python() -> str | None:
    """Return the Python that has ``bpy``: :data:`BPY_PYTHON_VARIABLE`, or this one, or None."""
    named = os.environ.get(BPY_PYTHON_VARIABLE)
    if named:
        return named
    if importlib.util.find_spec("bpy") is not None:
        return sys.executable
    return None


def describe_scene(scene: Scene, *, samples: int, seeds: list[int], output: str,
                   threads: int | None = None) -> dict:
    """Return the JSON description ``blender_worker.py`` renders (module docstring).

    Raises
    ------
    InputError
        A part Cycles is not given here: a dielectric boundary (eta != 1), a material other
        than a homogeneous medium or a Lambertian surface, a light other than a point light.
    """
    objects = []
    for index, obj in enumerate(scene.objects):
        material = obj.material
        field = f"objects[{index}].material"
        if isinstance(material, Dipole):
            if material.eta != 1.0:
                raise InputError("Cycles is given index-matched media only (eta = 1)",
                                 file=scene.source, field=f"{field}.eta", value=material.eta)
            sigma_s = material.sigma_s_prime / (1.0 - material.g)
            spec = {"type": "medium", "g": float(material.g),
                    "sigma_s": (sigma_s * scene.mm_per_unit).tolist(),
                    "sigma_a": (material.sigma_a * scene.mm_per_unit).tolist()}
        elif isinstance(material, Lambertian):
            spec = {"type": "diffuse", "albedo": np.asarray(material.albedo).tolist()}
        else:
            raise InputError("Cycles is given homogeneous media and Lambertian surfaces only",
                             file=scene.source, field=field, value=type(material).__name__)
        objects.append({"name": obj.name, "vertices": obj.mesh.vertices.tolist(),
                        "faces": obj.mesh.faces.tolist(), "material": spec})
    lights = []
    for index, light in enumerate(scene.lights):
        if not isinstance(light, PointLight):
            raise InputError("Cycles is given point lights only", file=scene.source,
                             field=f"lights[{index}]", value=type(light).__name__)
        lights.append({"position": light.position.tolist(),
                       "energy": (4.0 * math.pi * light.intensity).tolist()})
    camera = scene.camera
    return {"camera": {"origin": camera.origin.tolist(), "target": camera.target.tolist(),
                       "up": camera.up.tolist(), "fov_x_degrees": camera.fov,
                       "width": camera.width, "height": camera.height},
            "objects": objects, "lights": lights, "samples": int(samples),
            "seeds": [int(s) for s in seeds], "output": str(output),
            **({"threads": int(threads)} if threads else {})}


def render_cycles(scene: Scene, *, spp: int = 64, passes: int = 4, seed: int = 0,
                  python: str | None = None, timeout: float | None = None) -> Image:
    """Render ``scene`` with Cycles: the mean of ``passes`` renders and its variance.

    Parameters
    ----------
    scene : Scene
        Within :func:`describe_scene`'s reach.
    spp, passes : int
        Samples per pixel of a pass (a Cycles seed each), and passes (>= 2).
    seed : int
        Pass ``k`` uses the Cycles seed ``seed * passes + k``.
    python : str, optional
        The Python with ``bpy`` (default :func:`bpy_python`).
    timeout : float, optional
        Seconds before the worker is stopped.

    Returns
    -------
    Image
        Radiance under Cycles' light units (calibrate them: module docstring); the metadata
        holds the Blender version and each pass's seconds.
    """
    python = python or bpy_python()
    if python is None:
        raise InputError(INSTALL_HINT, field=BPY_PYTHON_VARIABLE, value=None)
    if passes < 2:
        raise InputError("must be >= 2 (the passes' spread gives the variance)",
                         field="passes", value=passes)
    with tempfile.TemporaryDirectory(prefix="translucent-cycles-") as folder:
        out = Path(folder) / "passes"
        description = describe_scene(scene, samples=spp, output=str(out),
                                     seeds=[seed * passes + k for k in range(passes)])
        path = Path(folder) / "scene.json"
        path.write_text(json.dumps(description))
        # isolated (-I): the worker's folder must not shadow Blender's own modules
        done = subprocess.run([python, "-I", str(WORKER), str(path)], capture_output=True,
                              text=True, timeout=timeout, check=False)
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
            raise RuntimeError(f"Cycles worker failed ({done.returncode}): {' | '.join(tail)}")
        images = np.array([np.load(out / f"pass_{k}.npy") for k in range(passes)],
                          dtype=np.float64)
        timing = json.loads((out / "timing.json").read_text())
    mean = images.mean(axis=0)
    variance = images.var(axis=0, ddof=1) / passes
    return Image(mean, variance, {"renderer": "cycles", "blender": timing["blender"],
                                  "spp": spp, "passes": passes,
                                  "seconds": float(sum(timing["seconds"]))})
