"""Atomic file output: write to a temporary name beside the target, rename when complete.

An interrupted run therefore never leaves a half-written file under the final name.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from .errors import InputError

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text"]


@contextlib.contextmanager
def atomic_path(target, suffix: str | None = None):
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    On an exception the temporary file is removed and ``target`` is left untouched.
    ``suffix`` defaults to the target's own (some writers pick a format from it).

    Raises
    ------
    InputError
        When ``target`` is a folder, or its folder cannot be created or written, before
        anything is written.
    """
    target = Path(target)
    if target.is_dir():
        raise InputError("is a folder; give a file name", file=target, field="path",
                         value=str(target))
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError, PermissionError) as error:
        raise InputError(f"cannot create the folder {target.parent} ({error.strerror})",
                         file=target, field="path", value=str(target)) from error
    suffix = target.suffix if suffix is None else suffix
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".part{suffix}",
                                   dir=target.parent)
    except PermissionError as error:
        raise InputError(f"the folder {target.parent} is not writable", file=target,
                         field="path", value=str(target)) from error
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp creates 0600; give the result the permissions an ordinary file would have
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        yield tmp
        os.replace(tmp, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def atomic_write_bytes(target, data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically and return the target path."""
    with atomic_path(target) as tmp:
        tmp.write_bytes(data)
    return Path(target)


def atomic_write_text(target, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``target`` atomically and return the target path."""
    return atomic_write_bytes(target, text.encode("utf-8"))


def atomic_save_figure(target, figure, *, dpi: int = 90) -> Path:
    """Save a Matplotlib ``figure`` as PNG to ``target`` atomically, close it, return the path."""
    import matplotlib.pyplot as plt

    with atomic_path(target, suffix=".png") as tmp:
        figure.savefig(tmp, format="png", dpi=dpi)
    plt.close(figure)
    return Path(target)
