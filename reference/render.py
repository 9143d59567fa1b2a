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

import sys
import time

import numpy as np

from ..backend import mitsuba
from ..cache import Cache, content_hash
from ..errors import InputError, check_count
from ..image import Image, read_exr
from ..scenes import Scene
from .delta_lights import DEFAULT_SIZE
from .mitsuba_scene import convert_scene

__all__ = ["render", "reference_settings", "reference_key", "load_scenes", "render_sample",
           "REFERENCE_FORMAT"]

#: Bumped whenever the scene conversion or the estimator changes what a reference holds,
#: so that older cache entries miss.
REFERENCE_FORMAT = 1

#: Show a progress bar only for renders that last longer than this (seconds).
PROGRESS_DELAY_SECONDS = 1.0



def reference_settings(*, spp: int, passes: int, seed: int, integrator: str | None,
                       max_depth: int | None, rr_depth: int | None,
                       per_channel: bool | None,
                       substitute_delta_lights: bool | None, delta_light_size: float) -> dict:
    """Everything besides the scene that decides a reference image (for its hash)."""
    mi = mitsuba()  # first: it points Dr.Jit at a working libLLVM before drjit loads
    import drjit as dr

    return {"format": REFERENCE_FORMAT, "spp": spp, "passes": passes, "seed": seed,
            "integrator": integrator or "auto", "max_depth": max_depth, "rr_depth": rr_depth,
            "per_channel": "auto" if per_channel is None else bool(per_channel),
            "substitute_delta_lights": substitute_delta_lights,
            "delta_light_size": float(delta_light_size), "mitsuba": mi.__version__,
            "drjit": dr.__version__, "variant": mi.variant()}


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
                delta_light_size: float = DEFAULT_SIZE):
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

    def convert(channel):
        return convert_scene(scene, integrator=integrator, max_depth=max_depth, spp=spp,
                             channel=channel, rr_depth=rr_depth,
                             substitute_delta_lights=substitute_delta_lights,
                             delta_light_size=delta_light_size)

    conversions = [] if per_channel else [convert(None)]
    if per_channel is None:
        per_channel = conversions[0].per_channel_recommended
    channels = (0, 1, 2) if per_channel else (None,)
    if per_channel:
        conversions = [convert(channel) for channel in channels]
    return channels, conversions, [mi.load_dict(c.scene_dict) for c in conversions]


def render_sample(channels, mitsuba_scenes, spp: int, seed: int, on_render=None) -> np.ndarray:
    """Render one sample image of scenes loaded by :func:`load_scenes`, float64 ``H x W x 3``.

    Per channel, each channel of the image comes from its own scene's render.
    ``on_render`` (optional) is called after each Mitsuba render.
    """
    if channels == (None,):
        sample = _render_pass(mitsuba_scenes[0], spp, seed)
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


def render(scene: Scene, *, spp: int = 64, passes: int = 4, seed: int = 0,
           progress: bool = True, cache: bool = True, integrator: str | None = None,
           max_depth: int | None = None, rr_depth: int | None = None,
           per_channel: bool | None = None,
           substitute_delta_lights: bool | None = None,
           delta_light_size: float = DEFAULT_SIZE) -> Image:
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
    integrator : {"volpath", "volpathmis", "path"}, optional
        Default ``volpath`` with media, ``path`` without
        (:func:`~translucent.reference.mitsuba_scene.convert_scene`).
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

    Returns
    -------
    Image
        The mean radiance, the per-pixel variance of the mean (None when ``passes == 1``)
        and metadata: ``producer``, ``scene``, ``scene_hash``, ``spp``, ``passes``,
        ``seed``, ``seconds``, ``variant``, ``mitsuba``, ``drjit``, ``integrator``,
        ``max_depth``, ``rr_depth``, ``per_channel``, ``substitutions``.

    Raises
    ------
    InputError
        Bad counts, an unknown integrator or material (see ``convert_scene``).
    """
    spp = check_count(spp, "spp", 1)
    passes = check_count(passes, "passes", 1)
    seed = check_count(seed, "seed", 0)
    if not isinstance(scene, Scene):
        raise InputError("expected a translucent.scenes.Scene", field="scene",
                         value=type(scene).__name__)
    settings = reference_settings(spp=spp, passes=passes, seed=seed, integrator=integrator,
                                  max_depth=max_depth, rr_depth=rr_depth,
                                  per_channel=per_channel,
                                  substitute_delta_lights=substitute_delta_lights,
                                  delta_light_size=delta_light_size)
    key = reference_key(scene, settings)
    store = Cache("reference") if cache else None
    if store is not None:
        path = store.path(key, ".exr")
        if path.is_file():
            try:
                return read_exr(path)
            except InputError:
                pass  # an unreadable entry is a miss: render again and replace it

    start = time.perf_counter()
    channels, conversions, mitsuba_scenes = load_scenes(
        scene, spp=spp, per_channel=per_channel, integrator=integrator, max_depth=max_depth,
        rr_depth=rr_depth, substitute_delta_lights=substitute_delta_lights,
        delta_light_size=delta_light_size)
    per_channel = channels != (None,)

    from tqdm.auto import tqdm

    height, width = scene.camera.height, scene.camera.width
    mean = np.zeros((height, width, 3))
    sum_squares = np.zeros((height, width, 3))  # Welford's M2: stable for many passes
    bar = tqdm(total=passes * len(channels), delay=PROGRESS_DELAY_SECONDS,
               disable=not progress, desc=f"reference {scene.name}", unit="render",
               leave=False, file=sys.stderr)
    try:
        for k in range(passes):
            sample = render_sample(channels, mitsuba_scenes, spp, seed * passes + k,
                                   bar.update)
            delta = sample - mean
            mean += delta / (k + 1)
            sum_squares += delta * (sample - mean)
    finally:
        bar.close()
    seconds = time.perf_counter() - start

    variance = sum_squares / (passes - 1) / passes if passes > 1 else None
    first = conversions[0]
    metadata = {
        "producer": "reference",
        "scene": scene.name,
        "scene_hash": key,
        "spp": spp,
        "passes": passes,
        "seed": seed,
        "seconds": seconds,
        "variant": settings["variant"],
        "mitsuba": settings["mitsuba"],
        "drjit": settings["drjit"],
        "integrator": first.integrator,
        "max_depth": first.max_depth,
        "rr_depth": first.rr_depth,
        "per_channel": bool(per_channel),
        "substitutions": list(first.substitutions),
    }
    image = Image(mean, variance, metadata)
    if store is not None:
        image.write(store.path(key, ".exr"))
    return image
