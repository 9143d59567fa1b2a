"""Benchmarks, one module each (``translucent bench <module>``)."""

import contextlib
import contextvars

#: Whether the running benchmark is a ``--quick`` smoke run (its JSON says so).
_QUICK = contextvars.ContextVar("translucent_bench_quick", default=False)


@contextlib.contextmanager
def quick_run():
    """Mark the figures written inside the block as a quick run's (``"quick": true``)."""
    token = _QUICK.set(True)
    try:
        yield
    finally:
        _QUICK.reset(token)


def is_quick() -> bool:
    """Return whether the running benchmark is a ``--quick`` smoke run."""
    return _QUICK.get()


def quick_knobs(methods) -> dict | None:
    """Return each method's cheap knobs (its ``QUICK_KNOBS``) in a quick run; else None.

    Parameters
    ----------
    methods : iterable of str
        Registered fast methods.

    Returns
    -------
    dict or None
        Method name -> knobs, for the benches' ``knobs`` arguments; None (each method's
        defaults) outside a ``--quick`` run.
    """
    if not is_quick():
        return None
    from ...fast.registry import method

    return {name: dict(getattr(method(name), "QUICK_KNOBS", {}) or {}) for name in methods}


#: A bench's progress bar appears once a step has lasted this long (seconds), as the
#: reference renders' do.
PROGRESS_DELAY_SECONDS = 1.0


def steps_bar(description: str, total: int, unit: str = "step", enabled: bool = True):
    """Return a bench's progress bar over its steps (tqdm, on standard error).

    It appears once a step has lasted :data:`PROGRESS_DELAY_SECONDS`, stays hidden where
    standard error is not a terminal and under ``--no-progress``; name each step with
    ``bar.set_postfix_str(name)`` and count it with ``bar.update()``. ``enabled=False``
    hides it too.
    """
    from ...progress import progress_bar

    return progress_bar(total=total, description=description, unit=unit, enabled=enabled,
                        delay=PROGRESS_DELAY_SECONDS)


def at_width(scene, width: int):
    """Return ``scene`` seen ``width`` pixels wide, the height following its aspect.

    Parameters
    ----------
    scene : Scene
    width : int
        Image width in pixels; 0 keeps the scene's own size.

    Returns
    -------
    Scene
        The same scene with a camera of ``width`` x ``round(width * height / width)``
        pixels (at least 1 high), or ``scene`` itself for width 0.
    """
    if not width:
        return scene
    camera = scene.camera
    return with_size(scene, width, max(1, round(width * camera.height / camera.width)))


def with_size(scene, width: int, height: int):
    """Return ``scene`` with its camera resized to ``width`` x ``height`` pixels.

    Parameters
    ----------
    scene : Scene
    width, height : int
        Image size in pixels.

    Returns
    -------
    Scene
        The same scene and camera pose, another film size.
    """
    from dataclasses import replace

    return scene.with_camera(replace(scene.camera, width=width, height=height))


def count_list(text: str, field: str, *, allow_empty: bool = False) -> list[int]:
    """Parse a comma-separated option of counts (``"16384,65536"``).

    Parameters
    ----------
    text : str
        The option's value.
    field : str
        The option's name, for the message (``"--samples"``).
    allow_empty : bool
        Whether no count at all is accepted (an option whose empty value skips a step).

    Returns
    -------
    list of int
        The counts, each >= 1.

    Raises
    ------
    InputError
        A part that is not an integer >= 1, or no count where one is needed.
    """
    from ...errors import InputError

    parts = [part.strip() for part in str(text).split(",") if part.strip()]
    counts = []
    for part in parts:
        try:
            count = int(part)
        except ValueError:
            count = 0
        if count < 1:
            break
        counts.append(count)
    if len(counts) != len(parts) or not (counts or allow_empty):
        raise InputError("must be comma-separated integers >= 1"
                         + ("" if allow_empty else " (at least one)"), field=field, value=text)
    return counts


def json_figures(value):
    """Return ``value`` as strict JSON data.

    Numpy numbers and arrays become Python ones, NaN and infinities None, tuples lists, and
    anything else its text.

    Examples
    --------
    >>> import numpy as np
    >>> json_figures({"fps": np.float32(2.5), "error": float("nan"), "shape": (2, 3)})
    {'fps': 2.5, 'error': None, 'shape': [2, 3]}
    """
    import math

    import numpy as np

    if isinstance(value, dict):
        return {str(key): json_figures(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_figures(item) for item in value]
    if isinstance(value, np.ndarray):
        return json_figures(value.tolist())
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if value is None or isinstance(value, str):
        return value
    return str(value)


def write_figures(path, name: str, figures: dict):
    """Write a bench's figures as JSON: to ``path``, or ``bench_NAME.json`` without one.

    The one writer of every bench (``--json FILE``): strict JSON (:func:`json_figures`),
    indented, written whole or not at all. Returns the path written.
    """
    import json
    from pathlib import Path

    from ...atomic import atomic_write_text

    out = Path(path) if path else Path(f"bench_{name}.json")
    figures = {**figures, "quick": is_quick()}
    atomic_write_text(out, json.dumps(json_figures(figures), indent=2, allow_nan=False) + "\n")
    return out
