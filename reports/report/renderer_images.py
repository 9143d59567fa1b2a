"""Another renderer's images, read to be scored like a fast method's (``report --images``).

``DIR/<renderer>/<scene name>.exr``: one folder per renderer, named as the report shows it
(:func:`renderers_in`); each image becomes a :class:`~translucent.reports.report.runs.MethodRun`
with the times its header holds (:func:`renderer_images`).
"""

from __future__ import annotations

import errno
import math
import os
import re
from pathlib import Path

from ...errors import InputError
from .runs import MethodRun, timestamp

__all__ = ["HEADER_SECONDS", "RENDERER_NAME", "renderer_images", "renderers_in"]


#: What a renderer's folder name may be: it is shown in the page and keys metrics.json.
RENDERER_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,39}$")


#: EXR header attributes read as a foreign image's frame time, seconds, in this order.
HEADER_SECONDS = ("seconds", "renderTime", "render_time", "rendertime")


def renderers_in(images, methods: list[str]) -> list[str]:
    """Return the renderer folders of ``images`` (sorted); bad folders are input errors."""
    if images is None:
        return []
    folder = Path(images)
    if not folder.is_dir():
        raise InputError("must be a folder with one subfolder of images per renderer",
                         field="--images", value=str(folder))
    names = sorted(p.name for p in folder.iterdir() if p.is_dir() and
                   not p.name.startswith("."))
    if not names:
        raise InputError("has no subfolder: put each renderer's <scene>.exr files in a "
                         "folder named after the renderer", field="--images",
                         value=str(folder))
    for name in names:
        if not RENDERER_NAME.match(name):
            raise InputError("a renderer's folder is named with letters, digits, '_', '.' "
                             "and '-' (at most 40)", file=folder / name, field="--images",
                             value=name)
        if name in methods:
            raise InputError("a renderer's folder has the name of a fast method being run: "
                             "rename the folder", file=folder / name, field="--images",
                             value=name)
    return names


def renderer_images(images, renderers: list[str], scene) -> dict:
    """Return each renderer's image of ``scene`` as a run to score (``name -> MethodRun``).

    The image is ``images/<renderer>/<scene name>.exr``, linear radiance at the scene's
    camera size. Its times come from its header where written there: ``seconds`` (a
    frame) and ``precompute_seconds``, as the suite's own images carry them, or a number
    attribute named in :data:`HEADER_SECONDS` (``renderTime``, ...). A renderer with no
    image of the scene (nothing of that name in its folder) is "not run".

    Raises
    ------
    InputError
        An unreadable image: a folder, a FIFO, a link loop or one leading nowhere, or no
        readable OpenEXR; or one of another size than the scene's camera (naming the file).
    """
    from ...atomic import check_input_file
    from ...image import header_number, read_exr

    runs = {}
    for name in renderers:
        path = Path(images) / name / f"{scene.name}.exr"
        base = {"method": name, "scene": scene.name, "measured_at": timestamp()}
        if not _exists(path):
            runs[name] = MethodRun(status="not run", reason=f"no image {path}", **base)
            continue
        # anything else of that name is the renderer's image, and one that cannot be read
        # is an input error, not a renderer that did not run
        check_input_file(path, "--images", what="renderer's image")
        image = read_exr(path)
        shape = (scene.camera.height, scene.camera.width)
        if image.rgb.shape[:2] != shape:
            raise InputError(f"is {image.rgb.shape[1]} x {image.rgb.shape[0]} pixels; the "
                             f"scene's camera is {shape[1]} x {shape[0]}", file=path,
                             field="shape", value=list(image.rgb.shape[:2]))
        meta = image.metadata
        times = {key: float(meta[key]) for key in ("seconds", "precompute_seconds")
                 if isinstance(meta.get(key), (int, float)) and not isinstance(meta[key], bool)
                 and math.isfinite(meta[key]) and meta[key] >= 0}
        if "seconds" not in times:
            seconds = header_number(path, HEADER_SECONDS)
            if seconds is not None and seconds >= 0:
                times["seconds"] = seconds
        runs[name] = MethodRun(
            status="ok", image=image, frame_seconds=times.get("seconds"),
            precompute_seconds=times.get("precompute_seconds"),
            skipped=[f"an image read from {path}, not rendered by the suite"
                     + ("" if "seconds" in times else "; its header has no time")],
            notes={"image": str(path)}, **base)
    return runs


def _exists(path: Path) -> bool:
    """Return whether anything (a link too, even one leading nowhere) is named ``path``."""
    try:
        os.lstat(path)
    except OSError as error:  # another error (no permission) is the check's to name
        return error.errno not in (errno.ENOENT, errno.ENAMETOOLONG)
    return True
