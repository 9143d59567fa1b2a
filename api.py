"""The suite from Python, one function per command: ``import translucent``.

======================  =====================================  ==========================
function                what it does                           command
======================  =====================================  ==========================
:func:`load_scene`      a built-in scene or a scene file       ``translucent scenes``
:func:`render`          a Mitsuba 3 reference (mean, variance) ``translucent render``
:func:`compare`         every metric beside its noise floor    ``translucent compare``
:func:`approx`          a fast method's image                  ``translucent approx``
:func:`method`          a fast method's module (precompute)    ``translucent approx``
:func:`fit`             profiles fitted to a slab capture      ``translucent fit``
======================  =====================================  ==========================

Each takes a scene name, a path or the object itself where the command takes a name or a
path, checks its input as the command does (:class:`~translucent.errors.InputError` names
the file, field and value) and returns what the command prints, as objects.
"""

from __future__ import annotations

import os

from .errors import InputError
from .image import Image

__all__ = ["load_scene", "render", "compare", "approx", "method", "fit"]


def load_scene(name_or_path):
    """Load a built-in scene by name, or a scene file (TOML) by path.

    Parameters
    ----------
    name_or_path : str or os.PathLike
        ``"sphere"`` (``translucent scenes`` lists the names) or a scene file
        (docs/scene-format.md).

    Returns
    -------
    Scene

    Examples
    --------
    >>> import translucent
    >>> scene = translucent.load_scene("sphere")
    >>> scene.name, [item.name for item in scene.objects], scene.camera.width
    ('sphere', ['sphere'], 96)
    """
    from .scenes import load_scene as load

    return load(name_or_path)


def _scene(scene):
    """Return ``scene`` loaded where it is a name or a path."""
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene)
    return scene


def _image(image, field: str) -> Image:
    """Return ``image`` read where it is the path of an EXR."""
    if isinstance(image, Image):
        return image
    if isinstance(image, (str, os.PathLike)):
        return Image.read(image)
    raise InputError("must be an Image or the path of an OpenEXR file", field=field,
                     value=type(image).__name__)


def render(scene, *, spp: int = 64, passes: int = 4, target_rse: float | None = None,
           budget_seconds: float | None = None, seed: int = 0, progress: bool = False,
           cache: bool = True, **options) -> Image:
    """Render a reference of ``scene`` with Mitsuba 3: the mean and its variance.

    Parameters
    ----------
    scene : Scene, str or os.PathLike
        The scene, a built-in scene's name or a scene file.
    spp : int
        Samples per pixel of each pass.
    passes : int
        Independent passes (their spread gives the variance of the mean). Ignored with
        ``target_rse``.
    target_rse : float, optional
        Render progressively instead: passes are added until the median relative standard
        error over the lit pixels is at most this (in (0, 1)), or ``budget_seconds`` is
        spent (:func:`translucent.reference.render.render_to_target`).
    budget_seconds : float, optional
        With ``target_rse``: rendering time at most, seconds.
    seed : int
        Picks the passes' seeds.
    progress : bool
        Show a progress bar.
    cache : bool
        Look the render up in, and store it into, the cache (``TRANSLUCENT_CACHE``).
    **options
        ``integrator``, ``per_channel``, ``max_depth``, ``rr_depth``, as
        :func:`translucent.reference.render` takes them.

    Returns
    -------
    Image
        ``rgb`` (H x W x 3, linear radiance), ``variance`` (of the mean) and the provenance
        in ``metadata`` (scene hash, spp, passes, seconds, integrator, variant).

    Examples
    --------
    A Lambertian sphere of albedo 0.5 in a white furnace renders 0.5 wherever it is seen:

    >>> import translucent
    >>> image = translucent.render("furnace_sphere", spp=16, passes=2, cache=False)
    >>> centre = image.rgb[image.shape[0] // 2, image.shape[1] // 2]
    >>> bool(abs(centre.mean() - 0.5) < 0.05), image.metadata["passes"]
    (True, 2)
    """
    from .reference import render as render_passes
    from .reference.render import check_noise_target, render_to_target

    scene = _scene(scene)
    if target_rse is None:
        if budget_seconds is not None:
            raise InputError("goes with target_rse", field="budget_seconds",
                             value=budget_seconds)
        return render_passes(scene, spp=spp, passes=passes, seed=seed, progress=progress,
                             cache=cache, **options)
    check_noise_target(target_rse, None, budget_seconds)
    return render_to_target(scene, target_rse=target_rse, budget_seconds=budget_seconds,
                            spp=spp, seed=seed, progress=progress, cache=cache, **options)


def compare(reference, test, *, mask=None) -> list[dict]:
    """Score ``test`` against ``reference``: every metric beside its reference-noise floor.

    Parameters
    ----------
    reference, test : Image or str or os.PathLike
        The images, or the paths of their EXRs. Where the reference carries its variance,
        each metric gets its noise floor (the value the reference's own noise alone gives)
        and a verdict.
    mask : array_like of bool, shape (H, W), optional
        Score only these pixels (those of an object, say).

    Returns
    -------
    list of dict
        One per metric of the registry (hdr_flip, ldr_flip, relative_mse, relative_mse_raw,
        rmse, psnr, ssim, ciede2000):
        ``metric``, ``value``, ``noise_floor``, ``verdict`` ("resolved", "within reference
        noise", or None without a variance), ``lower_is_better``, ``about``
        (:func:`translucent.reports.metrics.table.metric_rows`).

    Examples
    --------
    >>> import numpy as np, translucent
    >>> truth = np.full((16, 16, 3), 0.5)
    >>> reference = translucent.Image(truth, np.full_like(truth, 1e-6))
    >>> rows = {row["metric"]: row for row in translucent.compare(reference,
    ...                                                            translucent.Image(1.2 * truth))}
    >>> round(rows["rmse"]["value"], 3), rows["rmse"]["verdict"]
    (0.1, 'resolved')
    """
    from .reports.metrics.compute import compare as scores
    from .reports.metrics.compute import noise_floor
    from .reports.metrics.table import metric_rows

    reference, test = _image(reference, "reference"), _image(test, "test")
    floor = noise_floor(reference, mask=mask) if mask is not None else noise_floor(reference)
    return metric_rows(scores(reference, test, mask=mask), floor)


def method(name: str):
    """Return the module of the fast method ``name``: ``precompute(scene, **knobs)`` and more.

    Parameters
    ----------
    name : {"prt", "radiosity", "splatting", "brdf_pca"}

    Returns
    -------
    module
        With ``applies_to(scene)``, ``precompute(scene, **knobs)`` (whose state's
        ``render(lights=None, material=None)`` relights and edits without precomputing
        again) and ``DEFAULT_KNOBS``.

    Examples
    --------
    >>> import translucent
    >>> radiosity = translucent.method("radiosity")
    >>> radiosity.DEFAULT_KNOBS["rays_per_patch"] > 0
    True
    >>> radiosity.applies_to(translucent.load_scene("sphere")) is None  # None: it applies
    True
    """
    from .fast.base import method as fast_method

    return fast_method(name)


def approx(name: str, scene, *, lights=None, material=None, **knobs) -> Image:
    """Render ``scene`` with the fast method ``name``: precompute (cached), then render.

    Parameters
    ----------
    name : {"prt", "radiosity", "splatting", "brdf_pca"}
    scene : Scene, str or os.PathLike
    lights, material : optional
        What the method's ``render`` edits (None: the scene's).
    **knobs
        The method's knobs (``method(name).DEFAULT_KNOBS``); an unknown one is an
        :class:`~translucent.errors.InputError` listing the valid ones.

    Returns
    -------
    Image
        With the method's times and what it skipped in ``metadata``.

    Examples
    --------
    >>> import translucent
    >>> image = translucent.approx("radiosity", "sphere", triangles_per_patch=8)
    >>> image.shape, image.metadata["producer"]
    ((96, 96), 'radiosity')
    """
    return method(name).precompute(_scene(scene), **knobs).render(lights=lights,
                                                                   material=material)


def fit(capture, *, models=("dipole",), out_dir=None, seed: int | None = None,
        progress: bool = False, **options):
    """Fit material profiles to a slab capture with emcee.

    Parameters
    ----------
    capture : str or os.PathLike
        The capture's JSON sidecar (docs/capture-format.md).
    models : sequence of {"dipole", "walk", "subedit"}
    out_dir : str or os.PathLike, optional
        Where the summaries, material files and plots go (default: nothing written).
    seed : int, optional
    progress : bool
    **options
        ``r_min_mm``, ``fit_eta``, ``walkers``, ``max_steps``, ``segments``, ``r_s_mm``,
        ``smoothness`` (:func:`translucent.fitting.fit.fit_capture`).

    Returns
    -------
    dict
        ``model -> FitResult``: ``parameters`` (medians and intervals), ``goodness``
        (the verdict: a model that does not fit says so), ``converged``, ``summary()``.

    Examples
    --------
    >>> import tempfile, pathlib, translucent
    >>> from translucent.fitting.capture import write_capture
    >>> from translucent.fitting.synthetic import dipole_capture
    >>> from translucent.materials import measured_medium
    >>> folder = pathlib.Path(tempfile.mkdtemp())
    >>> image, spec = dipole_capture(measured_medium("Skin1"), size=32, seed=1,
    ...                              image_name="skin1.exr")
    >>> _ = write_capture(folder / "skin1.json", image, spec)
    >>> result = translucent.fit(folder / "skin1.json", seed=1)["dipole"]
    >>> result.converged, result.goodness.verdict
    (True, 'fits')
    """
    from .fitting.fit import fit_capture

    return fit_capture(capture, models=tuple(models), out_dir=out_dir, seed=seed,
                       progress=progress, **options)
