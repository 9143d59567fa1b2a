r"""Blender Cycles as an independent renderer of the suite's scenes.

Cycles shares no code with Mitsuba or the suite and offsets no rays at surfaces, so it
checks the references where they could share a bias (the float32 shell of
:mod:`translucent.scenes.frame` was found this way). It runs in a separate Python, the one
that has ``bpy`` (the ``peers`` extra; the ``bpy`` wheel pins numpy below 2, so it usually
lives in an environment of its own):

* :func:`describe_scene` writes what Cycles needs of a scene as JSON: the camera, each
  mesh with its material (a homogeneous medium, given in one of :data:`MODES`: Cycles'
  volume shader inside the object's boundary, or a Principled BSDF subsurface method with
  :func:`subsurface_inputs`; or a Lambertian surface) and the lights, every length in scene
  units and every coefficient per scene unit;
* :func:`run_worker` runs ``blender_worker.py`` in that Python, one Cycles render a
  (samples, seed) pair; :func:`render_cycles` returns the mean of passes with the variance
  of that mean, as the references; :mod:`.cycles` is the report's renderer built on them.

Each light is given in the power Cycles' own units need for the suite's radiometry (the
worker's docstring states the conversions, read in Cycles' source); the slow tests of
``tests/reference/test_cycles.py`` measure each on a Lambertian object against the suite's
reference (equal within noise).

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

__all__ = ["BPY_PYTHON_VARIABLE", "MODES", "SUBSURFACE_METHODS", "bpy_python", "describe_scene",
           "render_cycles", "run_worker", "scene_refusal", "subsurface_inputs",
           "write_description"]

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


#: The Principled BSDF's subsurface methods, by the suite's mode name.
SUBSURFACE_METHODS = {"burley": "BURLEY", "random_walk": "RANDOM_WALK",
                      "random_walk_skin": "RANDOM_WALK_SKIN"}

#: The description's material for a medium in each mode: "volume" or a subsurface method.
MODES = ("volume", *SUBSURFACE_METHODS)


def _check_subsurface_medium(medium: Dipole) -> np.ndarray:
    """Return sigma_t' (mm^-1), or raise where a subsurface mode cannot be given ``medium``."""
    from ...materials.profiles.random_walk import load_table

    sigma_t = np.asarray(medium.sigma_a + medium.sigma_s_prime, dtype=np.float64)
    if np.any(sigma_t <= 0):
        raise InputError("Cycles' subsurface radius 4 pi / sigma_t' is infinite for a channel "
                         "without extinction", field="sigma_s_prime",
                         value=np.asarray(medium.sigma_s_prime).tolist())
    load_table().check_eta(medium.eta)  # A is the walk table's total at this eta
    return sigma_t


def subsurface_inputs(medium: Dipole, mm_per_unit: float) -> dict:
    r"""Return the Principled BSDF's subsurface inputs that match ``medium``.

    Base Color is the medium's surface albedo A (the photon random walk's total diffuse
    reflectance at its eta, as :class:`~translucent.materials.profiles.burley.BurleyProfile`
    takes it) and the radius (Scale 1) :math:`4\pi / \sigma'_t` in scene units: Cycles
    divides it by :math:`4\pi` into its walk's reduced mean free path and its Burley ``d``
    (module docstring of ``blender_worker.py``), so the three modes see one medium, given as
    a user matching the medium exactly would give it.

    Raises
    ------
    InputError
        A channel without extinction (an infinite radius), or an eta outside the walk
        table (1.0 .. 2.0).
    """
    from ...materials.profiles.random_walk import RandomWalkProfile

    sigma_t = _check_subsurface_medium(medium)
    albedo = RandomWalkProfile(medium).total()
    return {"base_color": np.clip(albedo, 0.0, 1.0).tolist(),
            "radius": (4.0 * math.pi / (sigma_t * mm_per_unit)).tolist(),
            "anisotropy": float(medium.g), "ior": float(medium.eta)}


def _solid_material(scene: Scene, index: int, mode: str) -> dict:
    """Return a solid medium as Cycles is given it: its voxel grid, or its value per face.

    Volume mode: the grid itself, read nearest-voxel as the reference reads it (the
    worker's atlas lookup). Subsurface modes: each face takes the medium of the voxel its
    centroid lies in, as a texture painted on the surface would give it (Cycles evaluates
    the subsurface inputs where light enters), with A the walk table's total reflectance.
    """
    from ...materials.profiles.random_walk import load_table

    solid = scene.objects[index].material
    if mode not in SUBSURFACE_METHODS:
        return {"type": "solid_medium", "ior": float(solid.eta),
                "bounds": np.asarray(solid.bounds, dtype=np.float64).tolist(),
                "sigma_s": np.asarray(solid.sigma_s_prime * scene.mm_per_unit, np.float32),
                "sigma_a": np.asarray(solid.sigma_a * scene.mm_per_unit, np.float32)}
    mesh = scene.objects[index].mesh
    centroids = mesh.vertices[mesh.faces].mean(axis=1)
    sigma_a, sigma_s_prime = solid.coefficients_at(centroids)
    sigma_t = sigma_a + sigma_s_prime  # > 0 in every voxel (SolidMedium checks it)
    albedo = load_table().reduced_cumulative(np.inf, sigma_s_prime / sigma_t, solid.eta)
    return {"type": "subsurface", "method": SUBSURFACE_METHODS[mode],
            "face_base_color": np.clip(albedo, 0.0, 1.0).astype(np.float32),
            "face_radius": (4.0 * math.pi / (sigma_t * scene.mm_per_unit)).astype(np.float32),
            "anisotropy": 0.0, "ior": float(solid.eta)}


def _check_material(scene: Scene, index: int, mode: str) -> None:
    """Raise where Cycles cannot be given object ``index``'s material in ``mode``."""
    from ...materials.solid import SolidMedium

    material = scene.objects[index].material
    if isinstance(material, (Lambertian, SolidMedium)):
        return
    if not isinstance(material, Dipole):
        raise InputError("Cycles is given homogeneous and solid media and Lambertian surfaces "
                         "only (it has no Ward, Blinn-Phong or Cook-Torrance node; a SubEdit "
                         "material is a surface texture of profiles, not a medium)",
                         file=scene.source, field=f"objects[{index}].material",
                         value=type(material).__name__)
    if mode in SUBSURFACE_METHODS:
        _check_subsurface_medium(material)


def scene_refusal(scene: Scene, mode: str) -> InputError | None:
    """Return why Cycles cannot be given ``scene`` in ``mode`` (the error naming the part).

    The checks :func:`describe_scene` makes, without building the description: the
    planning of a report asks this of every scene and mode.
    """
    try:
        if mode not in MODES:
            raise InputError(f"unknown Cycles mode; valid: {', '.join(MODES)}", field="mode",
                             value=mode)
        for index in range(len(scene.objects)):
            _check_material(scene, index, mode)
        for index in range(len(scene.lights)):
            _light(scene, index)
    except InputError as error:
        return error
    return None


def _material(scene: Scene, index: int, mode: str) -> dict:
    from ...materials.solid import SolidMedium

    material = scene.objects[index].material
    if isinstance(material, Lambertian):
        return {"type": "diffuse", "albedo": np.broadcast_to(
            np.asarray(material.albedo, dtype=np.float64), (3,)).tolist()}
    if isinstance(material, SolidMedium):
        return _solid_material(scene, index, mode)
    if mode in SUBSURFACE_METHODS:
        return {"type": "subsurface", "method": SUBSURFACE_METHODS[mode],
                **subsurface_inputs(material, scene.mm_per_unit)}
    sigma_s = material.sigma_s_prime / (1.0 - material.g)
    return {"type": "medium", "g": float(material.g), "ior": float(material.eta),
            "sigma_s": (sigma_s * scene.mm_per_unit).tolist(),
            "sigma_a": (material.sigma_a * scene.mm_per_unit).tolist()}


def _pointing(position, direction, up_hint=None) -> list:
    """Return a 4 x 4 object matrix (rows) at ``position`` whose local -z is ``direction``."""
    forward = np.asarray(direction, dtype=np.float64)
    forward = forward / np.linalg.norm(forward)
    hint = np.array([0.0, 0.0, 1.0]) if up_hint is None else np.asarray(up_hint, float)
    if abs(float(forward @ hint)) > 0.99:
        hint = np.array([1.0, 0.0, 0.0])
    right = np.cross(forward, hint)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2] = right, up, -forward
    matrix[:3, 3] = np.asarray(position, dtype=np.float64)
    return matrix.tolist()


def _light(scene: Scene, index: int) -> dict:  # noqa: C901 - one case a light type
    from ...scenes import (
        ConstantEnvironment,
        DirectionalLight,
        RectangularAreaLight,
        SphereAreaLight,
        SpotLight,
    )

    light = scene.lights[index]
    if isinstance(light, PointLight):
        return {"type": "point", "position": light.position.tolist(),
                "energy": (4.0 * math.pi * light.intensity).tolist()}
    if isinstance(light, SphereAreaLight):
        return {"type": "point", "position": light.center.tolist(), "radius": light.radius,
                "energy": (4.0 * math.pi ** 2 * light.radius ** 2 * light.radiance).tolist()}
    if isinstance(light, SpotLight):
        return {"type": "spot", "matrix": _pointing(light.position, light.direction),
                "energy": (4.0 * math.pi * light.intensity).tolist(),
                "cutoff": math.radians(light.cutoff_angle),
                "beam_width": math.radians(light.beam_width)}
    if isinstance(light, RectangularAreaLight):
        u, v = light.u_axis, light.v_axis
        if abs(float(u @ v)) > 1e-9 * float(np.linalg.norm(u) * np.linalg.norm(v)):
            raise InputError("Cycles' area light is a rectangle: u_axis and v_axis must be "
                             "orthogonal", file=scene.source, field=f"lights[{index}].v_axis",
                             value=v.tolist())
        matrix = np.eye(4)
        # x along u, y along -v: the local -z (where Cycles emits) is cross(u, v)
        matrix[:3, 0] = u / np.linalg.norm(u)
        matrix[:3, 1] = -v / np.linalg.norm(v)
        matrix[:3, 2] = -light.normal
        matrix[:3, 3] = light.center
        return {"type": "area", "matrix": matrix.tolist(),
                "size_x": 2.0 * float(np.linalg.norm(u)),
                "size_y": 2.0 * float(np.linalg.norm(v)),
                "energy": (math.pi * light.area * light.radiance).tolist()}
    if isinstance(light, DirectionalLight):
        return {"type": "sun", "matrix": _pointing([0.0, 0.0, 0.0], light.direction),
                "strength": light.irradiance.tolist()}
    if isinstance(light, ConstantEnvironment):
        return {"type": "environment",
                "radiance": np.broadcast_to(light.radiance, (3,)).tolist()}
    raise InputError("Cycles is given point, sphere, spot, rectangle and directional lights "
                     "and a constant environment", file=scene.source,
                     field=f"lights[{index}]", value=type(light).__name__)


def describe_scene(scene: Scene, *, renders: list[tuple[int, int]], output: str,
                   mode: str = "volume", threads: int | None = None,
                   save_blend: str | None = None, warm_up: bool = False) -> dict:
    """Return the JSON description ``blender_worker.py`` renders (module docstring).

    Parameters
    ----------
    scene : Scene
    renders : list of (int, int)
        Samples per pixel and Cycles seed of each render.
    output : str
        The folder the worker writes the renders into.
    mode : str
        One of :data:`MODES`: how a homogeneous medium is given to Cycles (its volume
        shader inside the boundary, or a Principled BSDF subsurface method).
    threads : int, optional
        Cycles' threads (default: every core).
    save_blend : str, optional
        Also save the built scene as this ``.blend`` file.
    warm_up : bool
        Render once at 1 spp, untimed, before the renders (as the path-tracing ladder
        compiles its kernels before it times).

    Raises
    ------
    InputError
        A part Cycles is not given: a material other than a homogeneous medium or a
        Lambertian surface, a light other than those :func:`_light` converts, a
        non-rectangular area light, an unknown mode.
    """
    refusal = scene_refusal(scene, mode)
    if refusal is not None:
        raise refusal
    objects = [{"name": obj.name, "vertices": obj.mesh.vertices.tolist(),
                "faces": obj.mesh.faces.tolist(), "material": _material(scene, index, mode)}
               for index, obj in enumerate(scene.objects)]
    lights = [_light(scene, index) for index in range(len(scene.lights))]
    camera = scene.camera
    return {"camera": {"origin": camera.origin.tolist(), "target": camera.target.tolist(),
                       "up": camera.up.tolist(), "fov_x_degrees": camera.fov,
                       "width": camera.width, "height": camera.height},
            "objects": objects, "lights": lights,
            "renders": [{"samples": int(spp), "seed": int(seed)} for spp, seed in renders],
            "output": str(output),
            **({"threads": int(threads)} if threads else {}),
            **({"warm_up": True} if warm_up else {}),
            **({"save_blend": str(save_blend)} if save_blend else {})}


def write_description(description: dict, folder) -> Path:
    """Write ``description`` as ``folder/scene.json``, each array beside it in a ``.npy``.

    An array-valued field of an object's material becomes the name of its file, relative
    to the JSON's folder (the worker reads it there). Returns the JSON's path.
    """
    folder = Path(folder)
    written = dict(description)
    written["objects"] = []
    for index, item in enumerate(description["objects"]):
        material = dict(item["material"])
        for key, value in item["material"].items():
            if isinstance(value, np.ndarray):
                name = f"object_{index}.{key}.npy"
                np.save(folder / name, value)
                material[key] = {"npy": name}
        written["objects"].append({**item, "material": material})
    path = folder / "scene.json"
    path.write_text(json.dumps(written))
    return path


def run_worker(description: dict, folder: Path, *, python: str | None = None,
               timeout: float | None = None) -> tuple[list[np.ndarray], dict]:
    """Run ``blender_worker.py`` on ``description`` in ``folder``; its images and timing.

    Raises
    ------
    InputError
        No Python with ``bpy`` (:data:`INSTALL_HINT`).
    RuntimeError
        The worker failed (the last lines of its output).
    """
    python = python or bpy_python()
    if python is None:
        raise InputError(INSTALL_HINT, field=BPY_PYTHON_VARIABLE, value=None)
    path = write_description(description, folder)
    # isolated (-I): the worker's folder must not shadow Blender's own modules
    done = subprocess.run([python, "-I", str(WORKER), str(path)], capture_output=True,
                          text=True, timeout=timeout, check=False)
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        raise RuntimeError(f"Cycles worker failed ({done.returncode}): {' | '.join(tail)}")
    out = Path(description["output"])
    images = [np.load(out / f"render_{k}.npy").astype(np.float64)
              for k in range(len(description["renders"]))]
    return images, json.loads((out / "timing.json").read_text())


def render_cycles(scene: Scene, *, spp: int = 64, passes: int = 4, seed: int = 0,
                  mode: str = "volume", python: str | None = None,
                  timeout: float | None = None) -> Image:
    """Render ``scene`` with Cycles: the mean of ``passes`` renders and its variance.

    Parameters
    ----------
    scene : Scene
        Within :func:`describe_scene`'s reach.
    spp, passes : int
        Samples per pixel of a pass (a Cycles seed each), and passes (>= 2).
    seed : int
        Pass ``k`` uses the Cycles seed ``seed * passes + k``.
    mode : str
        How media are given (:func:`describe_scene`).
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
    if passes < 2:
        raise InputError("must be >= 2 (the passes' spread gives the variance)",
                         field="passes", value=passes)
    with tempfile.TemporaryDirectory(prefix="translucent-cycles-") as folder:
        description = describe_scene(scene, mode=mode, output=str(Path(folder) / "renders"),
                                     renders=[(spp, seed * passes + k) for k in range(passes)])
        images, timing = run_worker(description, Path(folder), python=python,
                                    timeout=timeout)
    images = np.array(images)
    mean = images.mean(axis=0)
    variance = images.var(axis=0, ddof=1) / passes
    return Image(mean, variance, {"renderer": "cycles", "blender": timing["blender"],
                                  "spp": spp, "passes": passes,
                                  "seconds": float(sum(timing["seconds"]))})
