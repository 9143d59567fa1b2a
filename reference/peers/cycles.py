"""Blender Cycles as a renderer the report scores: its subsurface modes and its volumes.

The renderer contract of :mod:`.registry`, for Cycles (``bpy``, the ``peers`` extra, in
the Python :func:`~.blender.bpy_python` finds). A homogeneous medium is given to Cycles as
a user matching it exactly would give it (:func:`~.blender.subsurface_inputs`), in each
of Cycles' ways to render it:

* ``burley``: the Principled BSDF's Christensen-Burley mode, disk probes of the radial
  profile; the suite knows its model, ``burley_cycles``, so its error splits into the
  profile's and Cycles' own;
* ``random_walk``: a volumetric random walk in the medium Cycles derives from the surface
  albedo and radius (its own albedo inversion), entered through the IOR;
* ``random_walk_skin``: the same walk with the radius rescaled by the dipole's albedo
  inversion and half the entries diffuse;
* ``volume``: Volume Scatter and Absorption inside the object's boundary (a Glass BSDF
  where eta is not 1), Cycles' volumetric path tracing: the transport check, the mode
  whose model is the reference itself.

Example
-------
``translucent report sphere bowl --methods prt --renderers cycles`` scores every mode
beside PRT (``TRANSLUCENT_BPY_PYTHON`` naming a Python with ``bpy``).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from ...image import Image
from . import blender

__all__ = ["MODES", "NAME", "applies_to", "available", "model_of", "render"]

NAME = "cycles"

MODES = {
    "burley": "Principled BSDF, Christensen-Burley (disk probes of the profile)",
    "random_walk": "Principled BSDF, Random Walk (a volumetric walk entered through the IOR)",
    "random_walk_skin": "Principled BSDF, Random Walk (Skin) (dipole-rescaled radius, "
                        "diffuse entries)",
    "volume": "Volume Scatter and Absorption in the boundary (volumetric path tracing)",
}

#: Seconds a worker may take before it is stopped.
WORKER_TIMEOUT = 3600.0


def available() -> str | None:
    """Return why Cycles cannot run here (no Python with ``bpy``), else None."""
    import os

    python = blender.bpy_python()
    if python is None:
        return blender.INSTALL_HINT
    if not (os.path.isfile(python) and os.access(python, os.X_OK)):
        return (f"{blender.BPY_PYTHON_VARIABLE} names {python}, which is not an executable "
                f"file; {blender.INSTALL_HINT}")
    return None


def applies_to(scene, mode: str) -> str | None:
    """Return why ``scene`` is beyond ``mode`` (the part Cycles is not given), else None."""
    error = blender.scene_refusal(scene, mode)
    if error is None:
        return None
    return f"{error.field}: {error.reason}" if error.field else error.reason


def model_of(mode: str) -> str | None:
    """Return the suite's profile ``mode`` renders (``burley``: ``burley_cycles``), or None."""
    return "burley_cycles" if mode == "burley" else None


def render(scene, mode: str, spp_values, seed: int = 0) -> list[dict]:
    """Render ``scene`` at each of ``spp_values``, timed after an untimed warm-up.

    The largest count is rendered as two halves of distinct seeds: their mean is its image
    and their spread its variance (what the report's brightness ratio and noise floors
    need), their seconds summed its time.

    Returns
    -------
    list of dict
        Per spp, ascending: ``spp``, ``seconds`` (Cycles' render, scene export and BVH
        included) and ``image`` (:class:`~translucent.image.Image`), or ``error``.
    """
    counts = sorted({int(spp) for spp in spp_values})
    top = counts[-1]
    halves = [top // 2, top - top // 2] if top >= 2 else [top]
    renders = counts[:-1] + halves
    with tempfile.TemporaryDirectory(prefix="translucent-cycles-") as folder:
        description = blender.describe_scene(
            scene, mode=mode, output=str(Path(folder) / "renders"), warm_up=True,
            renders=[(spp, seed * len(renders) + k) for k, spp in enumerate(renders)])
        try:
            images, timing = blender.run_worker(description, Path(folder),
                                                timeout=WORKER_TIMEOUT)
        except RuntimeError as error:
            return [{"spp": spp, "error": str(error)} for spp in counts]
    seconds = [float(s) for s in timing["seconds"]]

    def point(spp, rgb, variance, took):
        return {"spp": spp, "seconds": took,
                "image": Image(rgb, variance, {"renderer": "cycles", "mode": mode, "spp": spp,
                                               "blender": timing["blender"],
                                               "seconds": took})}

    points = [point(spp, image, None, took) for spp, image, took
              in zip(counts[:-1], images, seconds, strict=False)]
    last = images[len(counts) - 1:]
    if len(last) == 2:
        weights = np.array(halves, dtype=np.float64) / top
        mean = weights[0] * last[0] + weights[1] * last[1]
        # two estimates of the mean, weighted by their samples: the variance of the mean
        variance = weights[0] * weights[1] * (last[0] - last[1]) ** 2
        points.append(point(top, mean, variance, sum(seconds[len(counts) - 1:])))
    else:
        points.append(point(top, last[0], None, seconds[-1]))
    return points
