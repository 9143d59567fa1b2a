"""Atomic file output: write to a temporary name beside the target, rename when complete.

An interrupted run therefore never leaves a half-written file under the final name.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import tempfile
import time
from pathlib import Path

from .errors import InputError

__all__ = ["ORPHAN_AGE_SECONDS", "atomic_path", "atomic_write_bytes", "atomic_write_text",
           "check_output_file", "check_output_folder", "make_output_folder", "sweep_orphans"]

#: A temporary file or folder of an interrupted write (``.NAME.XXXXXXXX.part[.EXT]``, or
#: ``.old`` for a report folder being replaced) older than this is swept when something is
#: next written beside it: no live write takes that long between creating it and renaming
#: it, except a render, whose temporary file is made only once the pixels are done.
ORPHAN_AGE_SECONDS = 600.0

#: The names :func:`atomic_path` and the report's staging folders give their temporaries
#: (``tempfile``'s 8 random characters between the prefix and the suffix).
ORPHAN_NAME = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.(part(\.[A-Za-z0-9]+)?|old)$")


#: Folders this process has swept already.
_SWEPT: set[str] = set()


def sweep_orphans(folder, *, older_than: float = ORPHAN_AGE_SECONDS) -> list[Path]:
    """Remove the temporaries that interrupted writes left in ``folder``; return them.

    Only names of the suite's own temporaries (:data:`ORPHAN_NAME`) older than
    ``older_than`` seconds are removed; a folder that cannot be read is left alone.
    """
    removed = []
    now = time.time()
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return removed
    for entry in entries:
        if not ORPHAN_NAME.match(entry.name):
            continue
        try:
            if now - entry.stat(follow_symlinks=False).st_mtime < older_than:
                continue
            if entry.is_dir(follow_symlinks=False):
                shutil.rmtree(entry.path)
            else:
                os.unlink(entry.path)
            removed.append(Path(entry.path))
        except OSError:
            continue  # another process swept it, or it is not ours to remove
    return removed


def make_output_folder(folder, *, field: str, value, file=None, what: str | None = None
                       ) -> Path:
    """Create ``folder`` (and its parents) for an output, or raise :class:`InputError`.

    Parameters
    ----------
    folder : str or PathLike
        The folder to create (existing is fine).
    field, value, file
        What the message names: the option or key, its value, the file it is about.
    what : str, optional
        How the message calls the folder (default ``"the folder <folder>"``).

    Returns
    -------
    Path
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:  # a file in the way, no permission, a read-only mount, ...
        what = what or f"the folder {folder}"
        raise InputError(f"cannot create {what} ({error.strerror or error})", file=file,
                         field=field, value=value) from error
    return folder


def _unwritable(folder: Path) -> str | None:
    """Return why nothing can be written in ``folder``; None when a file can be made there.

    Where ``folder`` does not exist yet, the nearest folder above it that does is tried.

    Tried, not guessed from permission bits (a read-only mount, /proc, a full quota): a
    temporary file is created and removed at once.
    """
    existing = folder.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        return None  # a file in the way: the callers say so in their own words
    try:
        fd, probe = tempfile.mkstemp(prefix=".translucent-probe-", dir=existing)
    except OSError as error:
        return f"cannot write in {existing} ({error.strerror or error})"
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return None


def _not_a_folder(path, field: str, *, file=None, what: str = "a file name") -> Path:
    """Refuse an output file path that names a folder (the check the writers share)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"is a folder; give {what}", file=file, field=field, value=str(path))
    return path


def check_output_file(path, field: str, *, file=None, what: str = "a file name") -> Path:
    """Refuse an output file path that is a folder or cannot be written, before any work.

    Parameters
    ----------
    path : str or PathLike
        The file to be written (it may not exist yet).
    field : str
        The option or key that gave it (``"--out"``), for the message.
    file : str or PathLike, optional
        The file the message is about, where it is not ``path`` itself.
    what : str
        What to give instead, for the message (``"a file name ending in .exr"``).

    Returns
    -------
    Path
    """
    path = _not_a_folder(path, field, file=file, what=what)
    problem = _unwritable(path.parent)
    if problem:
        raise InputError(problem, file=file, field=field, value=str(path))
    return path


def check_output_folder(path, field: str) -> Path:
    """Refuse an output-folder option that names a file, or lies under one, before any work.

    Parameters
    ----------
    path : str or PathLike
        The folder (it may not exist yet).
    field : str
        The option's name, for the message (``"--out"``).

    Returns
    -------
    Path

    Raises
    ------
    InputError
        ``path`` is a file, or the nearest existing folder above it is a file.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError("exists and is not a folder", field=field, value=str(path))
    ancestor = path.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(f"cannot be created: {ancestor} is not a folder", field=field,
                         value=str(path))
    problem = _unwritable(path)
    if problem:
        raise InputError(problem, field=field, value=str(path))
    return path


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
    # its own temporary file below is the test of writing there: no probe first
    target = _not_a_folder(target, "path", file=target)
    make_output_folder(target.parent, field="path", value=str(target), file=target)
    if str(target.parent) not in _SWEPT:  # once a folder and process: orphans are old
        _SWEPT.add(str(target.parent))
        sweep_orphans(target.parent)
    suffix = target.suffix if suffix is None else suffix
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".part{suffix}",
                                   dir=target.parent)
    except OSError as error:  # no permission, a read-only mount, /proc, no space, ...
        raise InputError(f"cannot write in {target.parent} ({error.strerror or error})",
                         file=target, field="path", value=str(target)) from error
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp creates 0600; give the result the permissions an ordinary file would have
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    try:
        try:
            yield tmp
            os.replace(tmp, target)
        except OSError as error:
            if error.filename not in (str(tmp), str(target)):
                raise  # not the output's: an input read inside the block, for example
            raise InputError(f"could not write it ({error.strerror or error})", file=target,
                             field="path", value=str(target)) from error
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
