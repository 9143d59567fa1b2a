"""Reference renders: independent Mitsuba passes, their mean and its per-pixel variance, cached.

A reference is rendered as ``passes`` independent Mitsuba renders of ``spp`` samples per
pixel each (different seeds). The image is their mean; the variance stored with it is the
variance *of that mean*, the sample variance across passes divided by ``passes``, so that
metrics can discount the reference's own noise. Results are cached by content
(:class:`translucent.cache.Cache` namespace ``"reference"``): the key hashes the scene and
every setting that changes the result, so a cached reference is never rendered again, and
the EXR is written atomically, so an interrupted render leaves nothing behind.
"""

from __future__ import annotations

import contextlib
import json
import time

import numpy as np

from .. import signals
from ..backend import mitsuba
from ..cache import Cache, content_hash, keep_within_budget, mark_used, report_rejected
from ..errors import InputError, check_count
from ..image import Image, read_exr
from ..scenes import Scene
from .delta_lights import DEFAULT_SIZE
from .mitsuba_scene import convert_scene
from .model_keys import model_key, model_rule, parse_model_key

__all__ = ["render", "render_to_target", "reference_settings", "reference_key", "load_scenes",
           "read_cached_reference",
           "render_sample", "REFERENCE_FORMAT", "PROGRESSIVE_SEED_OFFSET"]

#: Bumped whenever the scene conversion or the estimator changes what a reference holds,
#: so that older cache entries miss (3: ``volpath_mnee`` with a chromatic medium renders
#: one channel at a time where ``per_channel`` is left to the conversion; 4: it finds the
#: refraction paths its solve misses on concave boundaries by specular manifold sampling;
#: 5: rendered in the rendering frame of :mod:`translucent.scenes.frame`).
REFERENCE_FORMAT = 5

#: Show a progress bar only for renders that last longer than this (seconds).
PROGRESS_DELAY_SECONDS = 1.0

#: Progressive pass ``k`` of seed set ``s`` uses the Mitsuba seed
#: ``PROGRESSIVE_SEED_OFFSET + s * PROGRESSIVE_SEED_STRIDE + k``: above every seed a
#: fixed-pass render (``seed * passes + k``) uses, so a progressive reference and a quick
#: fixed-pass render of the same scene are independent estimates.
PROGRESSIVE_SEED_OFFSET = 2**31
PROGRESSIVE_SEED_STRIDE = 2**16


def reference_settings(*, spp: int, passes: int, seed: int, integrator: str | None,
                       max_depth: int | None, rr_depth: int | None,
                       per_channel: bool | None,
                       substitute_delta_lights: bool | None, delta_light_size: float,
                       profile: str | None = None) -> dict:
    """Everything besides the scene that decides a reference image (for its hash)."""
    mi = mitsuba()  # first: it points Dr.Jit at a working libLLVM before drjit loads
    import drjit as dr

    return {"format": REFERENCE_FORMAT, "spp": spp, "passes": passes, "seed": seed,
            "integrator": integrator or "auto", "max_depth": max_depth, "rr_depth": rr_depth,
            "per_channel": "auto" if per_channel is None else bool(per_channel),
            "substitute_delta_lights": substitute_delta_lights,
            "delta_light_size": float(delta_light_size), "mitsuba": mi.__version__,
            "drjit": dr.__version__, "variant": mi.variant(),
            **({"profile": profile} if profile is not None else {}),
            **({"geometry": _geometry_settings(parse_model_key(profile)[1])}
               if profile is not None and parse_model_key(profile)[1] else {})}


def reference_key(scene: Scene, settings: dict) -> str:
    """Return the content hash naming a reference: the scene (without its name) and ``settings``."""
    return content_hash(scene, settings)


def _render_pass(mitsuba_scene, spp: int, seed: int) -> np.ndarray:
    """One Mitsuba render, as float64 ``H x W x 3``."""
    mi = mitsuba()
    # convert in float32 first: asking Dr.Jit for float64 fuses a cast into the render kernel
    return np.array(mi.render(mitsuba_scene, spp=spp, seed=seed)).astype(np.float64)[..., :3]


def load_scenes(scene: Scene, *, spp: int, per_channel: bool | None = None,
                integrator: str | None = None, max_depth: int | None = None,
                rr_depth: int | None = None, substitute_delta_lights: bool | None = None,
                delta_light_size: float = DEFAULT_SIZE, profile: str | None = None):
    """Convert ``scene`` and load it into Mitsuba: once in RGB, or once per channel.

    Parameters
    ----------
    scene : Scene
    spp : int
        Samples per pixel the conversion's sampler is built with.
    per_channel : bool, optional
        One grey-medium scene per RGB channel; default: where the conversion recommends
        it (``MitsubaConversion.per_channel_recommended``).
    integrator, max_depth, rr_depth, substitute_delta_lights, delta_light_size
        As :func:`~translucent.reference.convert_scene`.

    Returns
    -------
    channels : tuple
        ``(0, 1, 2)`` per channel, else ``(None,)``.
    conversions : list of MitsubaConversion
        One per entry of ``channels``.
    mitsuba_scenes : list
        The loaded Mitsuba scenes, one per entry of ``channels``.
    """
    mi = mitsuba()

    if profile is not None:  # the geometry is rendered beside (geometry_term_of)
        profile = model_key(parse_model_key(profile)[0], False, model_rule(profile))

    def convert(channel):
        return convert_scene(scene, integrator=integrator, max_depth=max_depth, spp=spp,
                             channel=channel, rr_depth=rr_depth,
                             substitute_delta_lights=substitute_delta_lights,
                             delta_light_size=delta_light_size, profile=profile)

    conversions = [] if per_channel else [convert(None)]
    if per_channel is None:
        per_channel = conversions[0].per_channel_recommended
    channels = (0, 1, 2) if per_channel else (None,)
    if per_channel:
        conversions = [convert(channel) for channel in channels]
    return channels, conversions, [mi.load_dict(c.scene_dict) for c in conversions]


def _geometry_settings(model: str) -> dict:
    # imported here: the geometry's diffusion solve needs numba, which a render without
    # the geometry does not (the base install names the render extra it lacks first)
    from .geometry_term import geometry_settings

    return geometry_settings(model)


def geometry_term_of(scene: Scene, profile: str | None, channels, conversions, mitsuba_scenes):
    """Return the geometry term a model key asks for (:mod:`.geometry_term`), or None.

    None where the key has no geometry, or no object of the scene has a correction in view.

    Raises
    ------
    InputError
        The key asks for the geometry with an integrator other than ``bssrdf_path``, or a
        render made one channel at a time.
    """
    from .geometry_term import GeometryTerm

    if profile is None or not parse_model_key(profile)[1]:
        return None
    if conversions[0].integrator != "bssrdf_path" or channels != (None,):
        raise InputError("the geometry term is rendered with bssrdf_path in RGB only",
                         field="profile", value=profile)
    base, model = parse_model_key(profile)
    term = GeometryTerm(scene, conversions[0], mitsuba_scenes[0], base, model=model)
    return None if term.empty else term


def render_sample(channels, mitsuba_scenes, spp: int, seed: int, on_render=None,
                  geometry=None) -> np.ndarray:
    """Render one sample image of scenes loaded by :func:`load_scenes`, float64 ``H x W x 3``.

    Per channel, each channel of the image comes from its own scene's render.
    ``on_render`` (optional) is called after each Mitsuba render. ``geometry`` (a
    :class:`~translucent.reference.geometry_term.GeometryTerm`) adds one estimate of the
    geometry correction, seeded with the pass.
    """
    signals.check()  # a signal a plugin's caller swallowed still ends the render here
    if channels == (None,):
        sample = _render_pass(mitsuba_scenes[0], spp, seed)
        if geometry is not None:
            sample = sample + geometry.sample(seed)
        if on_render is not None:
            on_render()
        return sample
    sample = None
    for channel, mitsuba_scene in zip(channels, mitsuba_scenes, strict=True):
        pixels = _render_pass(mitsuba_scene, spp, seed)
        if sample is None:
            sample = np.empty_like(pixels)
        sample[..., channel] = pixels[..., channel]
        if on_render is not None:
            on_render()
    return sample


#: Mitsuba numbers the samples of one render in 32 bits: pixels x spp of one pass (times
#: one per channel rendered alone) must stay below this.
MAX_SAMPLES_PER_RENDER = 2**32 - 1


def check_samples_per_render(scene: Scene, spp: int, field: str = "spp") -> None:
    """Refuse, before any work, a render the machine cannot hold or Mitsuba cannot number.

    Raises
    ------
    InputError
        A camera whose film needs more memory than is available (the estimate and what
        is there named, :mod:`translucent.resources`); or naming ``field``, the samples a
        pass would take, and the most spp a pass may have at the scene's size (more passes
        of fewer samples give the same image).
    """
    pixels = scene.camera.width * scene.camera.height
    if pixels * spp > MAX_SAMPLES_PER_RENDER:
        raise InputError(f"{scene.camera.width} x {scene.camera.height} pixels x {spp} spp = "
                         f"{pixels * spp:,} samples in one pass; Mitsuba numbers a render's "
                         f"samples in 32 bits (at most {MAX_SAMPLES_PER_RENDER:,}): give at "
                         f"most {MAX_SAMPLES_PER_RENDER // pixels} spp a pass and more passes",
                         file=scene.source, field=field, value=spp)
    from ..resources import RENDER_BYTES_PER_PIXEL, check_memory

    check_memory(pixels * RENDER_BYTES_PER_PIXEL,
                 what=f"a {scene.camera.width} x {scene.camera.height} render",
                 file=scene.source, field="camera", value=f"{scene.camera.width} x "
                 f"{scene.camera.height}")


def render(scene: Scene, *, spp: int = 64, passes: int = 4, seed: int = 0,
           progress: bool = True, cache: bool = True, integrator: str | None = None,
           max_depth: int | None = None, rr_depth: int | None = None,
           per_channel: bool | None = None,
           substitute_delta_lights: bool | None = None,
           delta_light_size: float = DEFAULT_SIZE, profile: str | None = None) -> Image:
    """Render a reference image of ``scene`` with Mitsuba 3 in independent passes.

    Parameters
    ----------
    scene : Scene
    spp : int
        Samples per pixel in each pass (>= 1).
    passes : int
        Independent passes (>= 1; >= 2 to know the variance). Pass ``k`` uses the seed
        ``seed * passes + k``.
    seed : int
        Picks the set of seeds (>= 0).
    progress : bool
        Show a progress bar over passes (only once a render has lasted a second).
    cache : bool
        Look the reference up in, and store it into, the ``"reference"`` cache.
    integrator : {"volpath", "volpathmis", "volpath_mnee", "path", "bssrdf_path"}, optional
        Default ``volpath_mnee`` where a delta light meets a dielectric boundary around a
        medium, ``volpathmis`` with other chromatic media rendered in RGB, ``volpath``
        with other media, ``path`` without
        (:func:`~translucent.reference.mitsuba_scene.convert_scene`); ``bssrdf_path``
        renders each translucent object by ``profile`` (:mod:`.bssrdf_path`).
    max_depth, rr_depth : int, optional
        Path depth limit (-1 unbounded, the default) and the depth where Russian roulette
        starts (default: 5, or none in media of albedo near 1; see
        :data:`~translucent.reference.mitsuba_scene.RR_ALBEDO_THRESHOLD`).
    per_channel : bool, optional
        Render each RGB channel separately, every medium grey with that channel's
        coefficients, and keep that channel (three renders of ``spp`` per pass). Default:
        when a medium is chromatic and of albedo above
        :data:`~translucent.reference.mitsuba_scene.RR_ALBEDO_THRESHOLD`. RGB ``volpath``
        samples each distance with one channel's extinction and weights the other two by
        a ratio of transmittances; over the hundreds of events of a high-albedo walk
        those weights multiply into a heavy tail. Measured with
        ``translucent bench reference --integrators MATERIAL --spp 8 --passes 8`` (built-in
        ``sphere``, 10 mm radius, 48 x 48, constant environment), efficiency (1 / relative
        variance x seconds) as a ratio to RGB ``volpath``: Marble (albedo 0.998)
        ``volpathmis`` 2.3, per-channel 12.5; Skin1 (albedo <= 0.96) ``volpathmis`` 1.26,
        per-channel 0.46; Ketchup ``volpathmis`` 0.73, per-channel 0.23.
    substitute_delta_lights : bool, optional
        Replace delta lights by emitters of finite size (default: where a dielectric
        boundary around a medium would leave the medium black).
    delta_light_size : float
        Size of those emitters (:mod:`translucent.reference.delta_lights`).
    profile : str, optional
        With ``bssrdf_path``: the profile's name; the header's ``profile`` names it and
        each object's.

    Returns
    -------
    Image
        The mean radiance, the per-pixel variance of the mean (None when ``passes == 1``)
        and metadata: ``producer``, ``scene``, ``scene_hash``, ``spp``, ``passes``,
        ``seed``, ``seconds``, ``variant``, ``mitsuba``, ``drjit``, ``integrator``,
        ``max_depth``, ``rr_depth``, ``per_channel``, ``substitutions``, for
        heterogeneous media ``media`` (object -> field and grid), and for ``volpath_mnee``
        ``manifold_nee`` (its counts: :data:`~translucent.reference.manifold_nee.COUNTERS`).

    Raises
    ------
    InputError
        Bad counts, an unknown integrator or material (see ``convert_scene``).
    """
    spp = check_count(spp, "spp", 1)
    passes = check_count(passes, "passes", 1)
    seed = check_count(seed, "seed", 0)
    if passes > PROGRESSIVE_SEED_STRIDE:
        raise InputError(f"must be <= {PROGRESSIVE_SEED_STRIDE} (more samples a pass give the "
                         "same image in fewer passes)", field="passes", value=passes)
    if seed * passes + passes > PROGRESSIVE_SEED_OFFSET:
        # Mitsuba's seeds are 32-bit, and those above are the progressive renders'
        raise InputError(f"with {passes} passes must be < {PROGRESSIVE_SEED_OFFSET // passes}: "
                         f"pass k is seeded seed x passes + k, below 2^31", field="seed",
                         value=seed)
    if not isinstance(scene, Scene):
        raise InputError("expected a translucent.scenes.Scene", field="scene",
                         value=type(scene).__name__)
    check_samples_per_render(scene, spp)
    settings = reference_settings(spp=spp, passes=passes, seed=seed, integrator=integrator,
                                  max_depth=max_depth, rr_depth=rr_depth,
                                  per_channel=per_channel,
                                  substitute_delta_lights=substitute_delta_lights,
                                  delta_light_size=delta_light_size, profile=profile)
    key = reference_key(scene, settings)
    store = Cache("reference") if cache else None
    cached = _cached(store, key, scene, passes)
    if cached is not None:
        return cached
    # two processes asking for one reference: the second waits, then reads the first's
    with _entry_lock(store, key, scene):
        cached = _cached(store, key, scene, passes)
        if cached is not None:
            return cached
        return _render_passes(scene, store, key, settings, spp=spp, passes=passes, seed=seed,
                              progress=progress, per_channel=per_channel,
                              integrator=integrator, max_depth=max_depth, rr_depth=rr_depth,
                              substitute_delta_lights=substitute_delta_lights,
                              delta_light_size=delta_light_size)


def _entry_lock(store, key, scene):
    """Return the cache entry's lock (:meth:`Cache.locked`); no lock without a cache."""
    if store is None:
        return contextlib.nullcontext()
    return store.locked(key, f"the reference of {scene.name!r}")


def _render_passes(scene, store, key, settings, *, spp, passes, seed, progress, per_channel,
                   integrator, max_depth, rr_depth, substitute_delta_lights,
                   delta_light_size) -> Image:
    """Render ``passes`` independent passes, write the image into the cache, return it."""
    start = time.perf_counter()
    channels, conversions, mitsuba_scenes = load_scenes(
        scene, spp=spp, per_channel=per_channel, integrator=integrator, max_depth=max_depth,
        rr_depth=rr_depth, substitute_delta_lights=substitute_delta_lights,
        delta_light_size=delta_light_size, profile=settings.get("profile"))
    geometry = geometry_term_of(scene, settings.get("profile"), channels, conversions,
                                mitsuba_scenes)

    from ..progress import progress_bar

    passes_done = PassAccumulator((scene.camera.height, scene.camera.width, 3))
    bar = progress_bar(total=passes * len(channels), description=f"reference {scene.name}",
                       unit="render", enabled=progress, delay=PROGRESS_DELAY_SECONDS,
                       terminal_only=False)
    try:
        for k in range(passes):
            passes_done.add(render_sample(channels, mitsuba_scenes, spp, seed * passes + k,
                                          bar.update, geometry))
    finally:
        bar.close()
    _check_finite_render(scene, passes_done.mean)
    image = Image(passes_done.mean, passes_done.variance(),
                  _metadata(scene, key, settings, conversions, channels, mitsuba_scenes,
                            spp=spp, passes=passes, seed=seed,
                            seconds=time.perf_counter() - start))
    if store is not None:
        _store_image(store, key, image)
    return image


def read_cached_reference(path, key: str) -> Image | None:
    """Return the reference cached at ``path`` if it was made for ``key``; else None (a miss).

    An entry is served only when it is a file the suite wrote (its pixels' checksum is
    there and holds) whose ``scene_hash`` is ``key``: an entry copied over another key's,
    damaged, changed after writing or put there by another program is a miss, said once
    on standard error, and is rendered again and replaced.
    """
    import os

    if not os.path.isfile(path):
        if os.path.lexists(path):
            report_rejected(path, "it is not a file")
        return None
    try:
        image = read_exr(path, require_checksum=True)
    except InputError as error:
        report_rejected(path, error.reason)
        return None
    if image.metadata.get("scene_hash") != key:
        report_rejected(path, "it was made for another scene or other settings (its "
                        "scene_hash is not this key)")
        return None
    mark_used(path)
    return image


def _cached(store, key, scene, passes) -> Image | None:
    """Return the cached reference under ``key`` if it is whole, else None (a miss).

    An entry that cannot be read (damaged, its pixels changed after writing: the checksum
    tells), made for another key (:func:`read_cached_reference`), of another size than the
    scene's camera, or without the variance its passes give, is rendered again and
    replaced, never served.
    """
    if store is None:
        return None
    path = store.path(key, ".exr")
    image = read_cached_reference(path, key)
    if image is None:
        return None
    if image.shape != (scene.camera.height, scene.camera.width):
        report_rejected(path, "it is not of the camera's size")
        return None
    if passes > 1 and image.variance is None:
        report_rejected(path, "it has no variance")
        return None
    return image


def _store_image(store, key, image) -> None:
    """Write a finished reference into the cache, then keep the cache within its budget.

    A cache without room is a warning: the render is still the command's result.
    """
    path = store.make_room(store.path(key, ".exr"))
    with store.storing(path):
        image.write(path)
    keep_within_budget(store.root)


def _check_finite_render(scene, mean) -> None:
    """Refuse a render with NaN or Inf pixels (it is neither written nor cached)."""
    bad = ~np.isfinite(mean)
    if bad.any():
        raise InputError(f"Mitsuba rendered {int(bad.sum())} NaN or Inf pixel channels of "
                         f"{mean.size}: a material's coefficients are likely too extreme "
                         "for the renderer's single precision", file=scene.source,
                         field="scene", value=scene.name)


class PassAccumulator:
    """Mean and spread of independent sample images, one pass at a time (Welford).

    Parameters
    ----------
    shape : tuple of int
        ``(H, W, 3)``.
    """

    def __init__(self, shape):
        self.mean = np.zeros(shape)
        self.sum_squares = np.zeros(shape)  # Welford's M2: stable for many passes
        self.count = 0

    def add(self, sample: np.ndarray) -> None:
        """Add one pass's image."""
        self.count += 1
        delta = sample - self.mean
        self.mean += delta / self.count
        self.sum_squares += delta * (sample - self.mean)

    def variance(self) -> np.ndarray | None:
        """Variance of the mean (sample variance over passes / passes); None below 2 passes."""
        if self.count < 2:
            return None
        return self.sum_squares / (self.count - 1) / self.count

    def state(self) -> dict:
        """Arrays and counts to resume from (:meth:`from_state`)."""
        return {"mean": self.mean, "sum_squares": self.sum_squares,
                "count": np.array(self.count)}

    @classmethod
    def from_state(cls, state) -> PassAccumulator:
        """Rebuild an accumulator saved by :meth:`state`."""
        accumulator = cls(np.shape(state["mean"]))
        accumulator.mean = np.array(state["mean"], dtype=np.float64)
        accumulator.sum_squares = np.array(state["sum_squares"], dtype=np.float64)
        accumulator.count = int(state["count"])
        return accumulator


def _manifold_counts(mitsuba_scenes, before=None) -> dict | None:
    """Return the ``volpath_mnee`` counts summed over the loaded scenes (None: other).

    ``before``: counts of passes rendered earlier (a resumed render), added to them.
    """
    from .manifold_nee import counts

    total = dict(before) if before else None
    for mitsuba_scene in mitsuba_scenes:
        found = counts(mitsuba_scene)
        if found is not None:
            total = found if total is None else {k: total[k] + v for k, v in found.items()}
    return total


def _metadata(scene, key, settings, conversions, channels, mitsuba_scenes=(),
              manifold_before=None, **items) -> dict:
    from ..cache import content_hash

    first = conversions[0]
    manifold = _manifold_counts(mitsuba_scenes, manifold_before)
    return {
        "producer": "reference",
        "scene": scene.name,
        "scene_hash": key,
        # the scene alone, without the renderer's settings and versions: what a committed
        # reference is checked against when its scene changes
        "scene_content_hash": content_hash(scene),
        **items,
        "variant": settings["variant"],
        "mitsuba": settings["mitsuba"],
        "drjit": settings["drjit"],
        "integrator": first.integrator,
        "max_depth": first.max_depth,
        "rr_depth": first.rr_depth,
        "per_channel": channels != (None,),
        "substitutions": list(first.substitutions),
        **({"media": dict(first.media)} if first.media else {}),
        **({"manifold_nee": manifold} if manifold is not None else {}),
        **({"profile": dict(first.profile)} if first.profile else {}),
        **({"geometry": _geometry_settings(parse_model_key(settings.get("profile") or "")[1])}
           if parse_model_key(settings.get("profile") or "")[1] else {}),
    }


def check_noise_target(target_rse, target_p99_rse=None, budget_seconds=None,
                       *, fields=("--target-rse", "--target-p99", "--budget")):
    """Validate a noise target and budget; return them as floats (None stays None).

    Raises
    ------
    InputError
        A target outside (0, 1) or a budget that is not a positive number of seconds.
    """
    from ..errors import check_finite

    checked = []
    for value, field in zip((target_rse, target_p99_rse), fields[:2], strict=True):
        if value is None:
            checked.append(None)
            continue
        value = float(check_finite(value, field))
        if not 0 < value < 1:
            raise InputError("a relative standard error must lie in (0, 1), e.g. 0.01 for "
                             "1 %", field=field, value=value)
        checked.append(value)
    if budget_seconds is not None:
        budget_seconds = float(check_finite(budget_seconds, fields[2]))
        if not budget_seconds > 0:
            raise InputError("must be > 0 seconds", field=fields[2], value=budget_seconds)
    return checked[0], checked[1], budget_seconds


def render_to_target(scene: Scene, *, target_rse: float = 0.01,
                     target_p99_rse: float | None = None,
                     budget_seconds: float | None = None, spp: int = 64,
                     min_passes: int = 8, max_passes: int = 4096, seed: int = 0,
                     mask=None, mask_name: str = "scored", progress: bool = True,
                     cache: bool = True, integrator: str | None = None,
                     max_depth: int | None = None, rr_depth: int | None = None,
                     per_channel: bool | None = None,
                     substitute_delta_lights: bool | None = None,
                     delta_light_size: float = DEFAULT_SIZE, on_pass=None,
                     profile: str | None = None) -> Image:
    """Render a reference of ``scene`` pass after pass until it is as quiet as asked.

    Independent passes of ``spp`` samples per pixel are added until the relative standard
    error (:func:`translucent.noise.noise_summary`: over the lit pixels, and ``mask``) has a
    median of at most ``target_rse`` and, if given, a 99th percentile of at most
    ``target_p99_rse``; or until the next pass would overrun ``budget_seconds``; or
    ``max_passes``. At least ``min_passes`` are rendered, so that the variance the
    stopping rule reads is itself estimated from enough passes.

    The state after every pass is kept in the cache, so an interrupted render resumes
    where it stopped when it is called again with the same scene and settings.

    Parameters
    ----------
    scene : Scene
    target_rse : float
        Median relative standard error to reach, in (0, 1).
    target_p99_rse : float, optional
        99th-percentile relative standard error to reach, in (0, 1).
    budget_seconds : float, optional
        Rendering time (seconds, resumed passes included) not to exceed; None: no limit.
    spp : int
        Samples per pixel of each pass.
    min_passes, max_passes : int
        Bounds on the number of passes (``2 <= min_passes <= max_passes``).
    seed : int
        Picks the seed set (``0 <= seed < 2**15``); see :data:`PROGRESSIVE_SEED_OFFSET`.
    mask : array_like of bool, shape (H, W), optional
        The pixels the target is about (with the lit pixels), e.g. an object's pixels.
    mask_name : str
        How the metadata call ``mask``.
    progress, cache, integrator, max_depth, rr_depth, per_channel
        As :func:`render`.
    substitute_delta_lights, delta_light_size, profile
        As :func:`render`.
    on_pass : callable, optional
        Called after each pass as ``on_pass(passes, seconds, summary)``.

    Returns
    -------
    Image
        The mean of the passes, the variance of the mean, and :func:`render`'s metadata
        plus ``noise`` (the reached :class:`~translucent.noise.NoiseSummary` as a dict),
        ``target_rse``, ``target_p99_rse``, ``budget_seconds`` and ``stopped`` (``"target
        reached"``, ``"budget spent"`` or ``"max passes"``).

    Raises
    ------
    InputError
        Bad counts, a target outside (0, 1), a budget <= 0.
    """
    from ..noise import noise_summary

    spp = check_count(spp, "spp", 1)
    min_passes = check_count(min_passes, "min_passes", 2)
    max_passes = check_count(max_passes, "max_passes", min_passes,
                             why=" (at least min_passes)")
    seed = check_count(seed, "seed", 0)
    if seed >= PROGRESSIVE_SEED_OFFSET // PROGRESSIVE_SEED_STRIDE:
        raise InputError(f"must be < {PROGRESSIVE_SEED_OFFSET // PROGRESSIVE_SEED_STRIDE}",
                         field="seed", value=seed)
    target_rse, target_p99_rse, budget_seconds = check_noise_target(
        target_rse, target_p99_rse, budget_seconds,
        fields=("target_rse", "target_p99_rse", "budget_seconds"))
    check_samples_per_render(scene, spp)
    if max_passes > PROGRESSIVE_SEED_STRIDE:
        raise InputError(f"must be <= {PROGRESSIVE_SEED_STRIDE}", field="max_passes",
                         value=max_passes)
    if not isinstance(scene, Scene):
        raise InputError("expected a translucent.scenes.Scene", field="scene",
                         value=type(scene).__name__)
    shape = (scene.camera.height, scene.camera.width)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != shape:
            raise InputError(f"must be a boolean image of the camera's size {shape}",
                             field="mask", value=mask.shape)
    settings = reference_settings(spp=spp, passes=0, seed=seed, integrator=integrator,
                                  max_depth=max_depth, rr_depth=rr_depth,
                                  per_channel=per_channel,
                                  substitute_delta_lights=substitute_delta_lights,
                                  delta_light_size=delta_light_size, profile=profile)
    settings["progressive"] = {"target_rse": target_rse, "target_p99_rse": target_p99_rse,
                               "budget_seconds": budget_seconds, "min_passes": min_passes,
                               "max_passes": max_passes,
                               "mask": None if mask is None else mask}
    key = reference_key(scene, settings)
    # the partial state is keyed without the stopping rule: a render resumed with a
    # tighter target or a larger budget goes on from the passes already made
    partial_key = reference_key(scene, {**settings, "progressive": None})
    store = Cache("reference") if cache else None
    cached = _cached(store, key, scene, 2)
    if cached is not None:
        return cached

    # two processes on one reference: the second waits for the first's passes
    with _entry_lock(store, partial_key, scene):
        cached = _cached(store, key, scene, 2)
        if cached is not None:
            return cached
        accumulator = PassAccumulator((*shape, 3))
        seconds_before = 0.0
        manifold_before = None
        partial = store.path(partial_key, ".partial.npz") if store is not None else None
        resumed = _load_partial(partial, partial_key, shape)
        if resumed is not None:
            accumulator, seconds_before, manifold_before = resumed

        start = time.perf_counter()
        channels, conversions, mitsuba_scenes = load_scenes(
            scene, spp=spp, per_channel=per_channel, integrator=integrator, max_depth=max_depth,
            rr_depth=rr_depth, substitute_delta_lights=substitute_delta_lights,
            delta_light_size=delta_light_size, profile=profile)
        geometry = geometry_term_of(scene, profile, channels, conversions, mitsuba_scenes)

        def summary():
            if accumulator.count < 2:
                return None
            return noise_summary(accumulator.mean, accumulator.variance(), mask,
                                 mask_name=mask_name)

        def elapsed():
            return seconds_before + time.perf_counter() - start

        from ..progress import progress_bar

        bar = progress_bar(description=f"reference {scene.name}", unit="pass",
                           enabled=progress, delay=PROGRESS_DELAY_SECONDS,
                           terminal_only=False)
        stopped = "max passes"
        try:
            while accumulator.count < max_passes:
                reached = summary()
                if accumulator.count >= min_passes and reached is not None and \
                        reached.meets(target_rse, target_p99_rse):
                    stopped = "target reached"
                    break
                if budget_seconds is not None and accumulator.count >= 2:
                    per_pass = elapsed() / accumulator.count
                    if elapsed() + per_pass > budget_seconds:
                        stopped = "budget spent"
                        break
                accumulator.add(render_sample(
                    channels, mitsuba_scenes, spp,
                    PROGRESSIVE_SEED_OFFSET + seed * PROGRESSIVE_SEED_STRIDE + accumulator.count,
                    geometry=geometry))
                if partial is not None:
                    _save_partial(store, partial, partial_key, accumulator, elapsed(),
                                  _manifold_counts(mitsuba_scenes, manifold_before))
                reached = summary()
                bar.update()
                if reached is not None:
                    bar.set_postfix_str(f"median RSE {100 * reached.median:.3g} %")
                if on_pass is not None:
                    on_pass(accumulator.count, elapsed(), reached)
            else:
                reached = summary()
                if reached is not None and reached.meets(target_rse, target_p99_rse):
                    stopped = "target reached"
        finally:
            bar.close()
        reached = summary()
        _check_finite_render(scene, accumulator.mean)
        image = Image(accumulator.mean, accumulator.variance(),
                      _metadata(scene, key, settings, conversions, channels, mitsuba_scenes,
                                manifold_before, spp=spp, passes=accumulator.count, seed=seed,
                                seconds=elapsed(),
                                seed_offset=PROGRESSIVE_SEED_OFFSET,
                                noise=reached.as_dict(), target_rse=target_rse,
                                target_p99_rse=target_p99_rse, budget_seconds=budget_seconds,
                                stopped=stopped))
        if store is not None:
            _store_image(store, key, image)
        return image


def _save_partial(store, path, key: str, accumulator: PassAccumulator, seconds: float,
                  manifold: dict | None = None) -> None:
    """Keep the passes made so far as a checked entry of ``key`` (:mod:`translucent.entries`)."""
    from ..atomic import atomic_path
    from ..entries import EntryError, write_entry

    state = {"mean": accumulator.mean, "sum_squares": accumulator.sum_squares,
             "count": accumulator.count, "seconds": float(seconds),
             "manifold_nee": None if manifold is None else json.dumps(manifold)}
    try:
        with atomic_path(store.make_room(path), suffix=".npz") as tmp, \
                open(tmp, "wb") as handle:
            write_entry(handle, key, state)
    except (InputError, OSError, EntryError):
        pass  # resuming is a convenience: a cache that cannot be written costs only that


def _load_partial(path, key: str, shape):
    """Return ``(accumulator, seconds, manifold counts)`` of a resumable render, or None.

    The state is read as an entry of ``key`` (its key and checksum checked, so a state
    edited, damaged or copied from another render is refused) and then checked for what
    no render leaves: another size, NaN or Inf, a negative spread, a pass count outside
    [1, :data:`PROGRESSIVE_SEED_STRIDE`] or a negative time. A refused state is said once on
    standard error and the render starts again; it never reaches the image.
    """
    import os

    from ..entries import EntryError, read_entry

    if path is None or not os.path.lexists(path):
        return None
    if not os.path.isfile(path):
        report_rejected(path, "it is not a file")
        return None
    try:
        state = read_entry(path, key)
        mean = np.asarray(state["mean"], dtype=np.float64)
        spread = np.asarray(state["sum_squares"], dtype=np.float64)
        count, seconds = state["count"], float(state["seconds"])
        manifold = None if state["manifold_nee"] is None else json.loads(state["manifold_nee"])
        problem = None
        if mean.shape != (*shape, 3) or spread.shape != mean.shape:
            problem = "it is not of the camera's size"
        elif not (np.isfinite(mean).all() and np.isfinite(spread).all()) or \
                (spread < 0).any():
            problem = "it holds NaN, Inf or a negative spread"
        elif isinstance(count, bool) or not isinstance(count, int) or \
                not 1 <= count <= PROGRESSIVE_SEED_STRIDE or \
                not 0 <= seconds < float("inf"):
            problem = f"its pass count {count!r} or time {seconds!r} is impossible"
    except (EntryError, KeyError, TypeError, ValueError) as error:
        problem = str(error)
    if problem:
        report_rejected(path, problem)
        return None
    accumulator = PassAccumulator(mean.shape)
    accumulator.mean, accumulator.sum_squares, accumulator.count = mean, spread, count
    return accumulator, seconds, manifold
