"""Benchmarks, one module each (``translucent bench <module>``)."""

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
    import sys

    from tqdm.auto import tqdm

    return tqdm(total=total, desc=description, unit=unit, leave=False, file=sys.stderr,
                delay=PROGRESS_DELAY_SECONDS, disable=None if enabled else True)


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
