"""The suite's temporary files and staging folders: their names, their locks, their sweeping.

Every temporary is named ``.NAME.XXXXXXXX.part[.EXT]`` (``.old`` for a folder put aside
while it is replaced): hidden, beside what it becomes, and recognised by
:data:`ORPHAN_NAME` when an interrupted write leaves it. ``NAME`` is cut short where the
whole would exceed the file system's longest name (:func:`temporary_affixes`), so that a
target of any legal name can be written.

A staging folder is locked (:func:`locked_folder`) by the process that builds it for as long
as it does: the kernel releases the lock when that process ends, killed or not, so that
:func:`sweep_orphans` removes a killed run's folder at once, and never a live one's.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import time
from pathlib import Path

__all__ = ["NAME_MAX", "ORPHAN_AGE_SECONDS", "ORPHAN_NAME", "lock", "locked_folder",
           "same_file", "sweep_orphans", "temporary_affixes"]

#: A temporary file of an interrupted write (``.NAME.XXXXXXXX.part[.EXT]``) older than this
#: is swept when something is next written beside it: no live write takes that long between
#: creating it and renaming it, except a render, whose temporary file is made only once the
#: pixels are done. A staging folder (``.part``, or ``.old`` for a folder being replaced) is
#: swept as soon as no process holds its lock; this age only where locks are not supported.
ORPHAN_AGE_SECONDS = 600.0

#: The names :func:`~translucent.atomic.atomic_path` and
#: :func:`~translucent.staging.staging_folder` give their temporaries
#: (``tempfile``'s 8 random characters between the prefix and the suffix).
ORPHAN_NAME = re.compile(r"^\..+\.[A-Za-z0-9_]{8}\.(part(\.[A-Za-z0-9]+)?|old)$")

#: The longest file name where the file system does not say (``NAME_MAX`` of Linux's).
NAME_MAX = 255


def sweep_orphans(folder, *, older_than: float = ORPHAN_AGE_SECONDS) -> list[Path]:
    """Remove the temporaries that interrupted writes left in ``folder``; return them.

    Only names of the suite's own temporaries (:data:`ORPHAN_NAME`) are removed: a staging
    folder as soon as no process holds its lock (:func:`locked_folder`: its process was
    killed), one that a live process holds never; a temporary file, or a staging folder
    where the file system has no locks, once older than ``older_than`` seconds. A folder
    that cannot be read is left alone.
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
            if entry.is_dir(follow_symlinks=False):
                if _sweep_folder(entry, now - older_than):
                    removed.append(Path(entry.path))
                continue
            if now - entry.stat(follow_symlinks=False).st_mtime < older_than:
                continue
            os.unlink(entry.path)
            removed.append(Path(entry.path))
        except OSError:
            continue  # another process swept it, or it is not ours to remove
    return removed


def _sweep_folder(entry: os.DirEntry, before: float) -> bool:
    """Remove the staging folder ``entry`` unless a live process holds it; say if it went.

    Its lock is taken first and held while it is removed: the process that made it takes
    the lock at once and checks that its folder is still there (:func:`locked_folder`).
    """
    fd = os.open(entry.path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    try:
        held = lock(fd, wait=False)
        if held is False:
            return False  # its process is alive
        if held is None and entry.stat(follow_symlinks=False).st_mtime > before:
            return False  # no locks here: only the age tells
        if not same_file(entry.path, fd):
            return False  # replaced meanwhile
        shutil.rmtree(entry.path)
        return True
    finally:
        os.close(fd)


def lock(fd: int, *, wait: bool) -> bool | None:
    """Lock ``fd`` exclusively; False where another process holds it, None without locks.

    The kernel releases the lock when its process ends, killed or not.
    """
    try:
        import fcntl
    except ImportError:  # not a POSIX system
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
    except BlockingIOError:
        return False
    except OSError:  # a file system without locks
        return None
    return True


def same_file(path, fd: int) -> bool:
    """Return whether ``path`` still leads to the file open as ``fd``."""
    try:
        found, held = os.stat(path, follow_symlinks=False), os.fstat(fd)
    except OSError:
        return False
    return (found.st_dev, found.st_ino) == (held.st_dev, held.st_ino)


def temporary_affixes(name: str, tail: str, folder) -> tuple[str, str]:
    """Return ``tempfile``'s prefix and suffix for ``.NAME.XXXXXXXX<tail>`` in ``folder``.

    ``NAME`` is cut short where the whole would exceed the file system's longest name.
    """
    try:
        longest = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        longest = NAME_MAX
    if longest <= 0:
        longest = NAME_MAX
    room = max(1, longest - len(os.fsencode(tail)) - 10)  # the two dots, the 8 characters
    encoded = os.fsencode(name)
    if len(encoded) > room:
        name = os.fsdecode(encoded[:room])  # bytes of a character cut stay as they were
    return f".{name}.", tail


def locked_folder(parent: Path, prefix: str, suffix: str) -> tuple[Path, int]:
    """Make a folder in ``parent`` and lock it; return it and the descriptor holding the lock.

    A sweep in another process may take a folder in the instant between its making and
    its locking (it holds no lock yet): the folder is checked to be there once locked, and
    made afresh if not.
    """
    while True:
        folder = tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=parent)
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
        lock(fd, wait=True)
        if same_file(folder, fd):
            return Path(folder), fd
        os.close(fd)
