"""Folders built under a temporary name beside their target, and put in place when complete.

A report's folder, a fit's files, an exported scene: written into a
:func:`staging_folder` (``.NAME.XXXXXXXX.part``, locked by the process that writes it),
then renamed onto the target (:func:`replace_folder`) or moved into it file by file
(:func:`staged_outputs`). An interrupted or failed run, a full disk included, leaves
neither a half-written target nor its staging folder; one that was killed leaves a folder
that the next write beside it sweeps at once (:func:`~translucent.temporaries.sweep_orphans`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

from .atomic import OutputError, claim_output, output_folder
from .temporaries import lock, locked_folder, same_file, sweep_orphans, temporary_affixes

__all__ = ["replace_folder", "staged_outputs", "staging_folder"]


@contextlib.contextmanager
def staging_folder(target, *, field: str, value=None):
    """Yield a new hidden folder beside ``target`` to build it in; remove it at the end.

    The folder (``.NAME.XXXXXXXX.part``, named as the suite's temporaries are) is locked by
    this process while the block runs: :func:`~translucent.temporaries.sweep_orphans`
    removes it at once should the process be killed, never while it runs. What is left of
    it when the block ends, successful or not, is removed; rename it onto ``target`` within
    the block (:func:`replace_folder`) to keep it. Folders made above it for ``target`` are
    removed on a failure.

    Parameters
    ----------
    target : str or PathLike
        The folder (or file) being built.
    field, value
        What a message names: the option and its value (default ``target``).

    Yields
    ------
    Path

    Raises
    ------
    OutputError
        Where the folder cannot be made (no space, no permission), and where the block
        fails to write (:func:`~translucent.atomic.output_failure`).
    """
    target = Path(target)
    value = str(target) if value is None else value
    parent = target.absolute().parent
    with output_folder(parent, field=field, value=value, create=True):
        sweep_orphans(parent)  # staging folders of killed runs
        prefix, suffix = temporary_affixes(target.name, ".part", parent)
        try:
            folder, fd = locked_folder(parent, prefix, suffix)
        except OSError as error:
            raise OutputError(f"cannot write in {parent} ({error.strerror or error})",
                              field=field, value=value) from error
        try:
            yield folder
        except OutputError as error:
            written = next((Path(os.path.abspath(where)) for where in (error.file, error.value)
                            if isinstance(where, str | os.PathLike)
                            and folder in Path(os.path.abspath(where)).parents), None)
            if written is None:
                raise
            # named as it is in the target: the staging folder's name means nothing to a user
            raise OutputError(f"could not write it ({written.relative_to(folder)}: "
                              f"{error.why})", why=error.why, field=field,
                              value=value) from error
        finally:
            try:
                if same_file(folder, fd):
                    shutil.rmtree(folder, ignore_errors=True)
            finally:
                os.close(fd)


@contextlib.contextmanager
def staged_outputs(out_dir, *, field: str):
    """Yield a staging folder for files bound for ``out_dir``; move them in on success.

    For a command that writes several files into a folder that may hold others: the files
    are written into a :func:`staging_folder` beside ``out_dir``, and only when all are
    there each is checked against the command's inputs
    (:func:`~translucent.atomic.claim_output`) and renamed into ``out_dir`` (made where
    missing). A failure, a full disk included, leaves nothing in ``out_dir`` and no folder
    made for it.

    Parameters
    ----------
    out_dir : str or PathLike
        The folder the files are for.
    field : str
        The option that named it, for the messages.

    Yields
    ------
    Path
    """
    out_dir = Path(out_dir)
    with staging_folder(out_dir, field=field) as staging:
        yield staging
        staged = sorted(path for path in staging.rglob("*") if path.is_file())
        for path in staged:
            claim_output(out_dir / path.relative_to(staging), field)
        with output_folder(out_dir, field=field, create=True):
            for path in staged:
                target = out_dir / path.relative_to(staging)
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(path, target)


def replace_folder(staging, target, *, field: str = "path") -> Path:
    """Rename the finished folder ``staging`` onto ``target``; what was there goes only then.

    A folder at ``target`` is first renamed aside (``.NAME.XXXXXXXX.old``, locked while it
    is there), and removed once ``staging`` has taken its place. ``field`` (the option that
    named ``target``) is for the message.

    Raises
    ------
    OutputError
        Where a rename fails: ``staging`` is then still in place, and so is ``target``.
    """
    staging, target = Path(staging), Path(target)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(staging, 0o777 & ~umask)  # mkdtemp made it 0700
    old = fd = None
    try:
        if os.path.lexists(target):
            if target.is_dir() and not target.is_symlink():
                fd = os.open(target, os.O_RDONLY | os.O_DIRECTORY)
                lock(fd, wait=True)  # held while it is aside: swept only if we are killed
            parent = target.absolute().parent
            prefix, suffix = temporary_affixes(target.name, ".old", parent)
            old = Path(tempfile.mkdtemp(prefix=prefix, suffix=suffix, dir=parent))
            os.rmdir(old)
            os.rename(target, old)
        try:
            os.rename(staging, target)
        except OSError:
            if old is not None:
                os.rename(old, target)  # the previous folder back in its place
                old = None
            raise
    except OSError as error:
        raise OutputError(f"could not write it ({error.strerror or error})", field=field,
                          value=str(target)) from error
    finally:
        if fd is not None:
            os.close(fd)
    if old is not None:
        if old.is_symlink():
            old.unlink()  # a link put aside: what it led to stays
        else:
            shutil.rmtree(old, ignore_errors=True)
    return target
