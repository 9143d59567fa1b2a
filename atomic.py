"""File output that never destroys: atomic writes, streams, and outputs kept off inputs.

Regular files are written to a temporary name beside the target and renamed when complete,
so an interrupted run never leaves a half-written file under the final name. A character
device or a FIFO (``/dev/stdout``, a named pipe) is written as a stream instead, never
renamed over.

Within :func:`guarded_files` (the command line opens it around every command) the inputs a
command reads (:func:`note_input`) and the outputs it will write (:func:`claim_output`,
which :func:`check_output_file` and :func:`check_output_folder` call) are compared as they
are named, resolved (symbolic links followed, hard links by device and inode): an output
that is an input, or that another output also names, is refused before any work, and
:func:`atomic_path` refuses to write over a noted input whatever asked it to.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import stat
import sys
import tempfile
import time
from pathlib import Path

from .errors import InputError

__all__ = ["ORPHAN_AGE_SECONDS", "atomic_path", "atomic_write_bytes", "atomic_write_text",
           "check_input_file", "check_output_file", "check_output_folder", "claim_output",
           "guarded_files", "is_stream", "make_output_folder", "note_input", "safe_file_name",
           "sweep_orphans"]

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

#: The longest file name :func:`safe_file_name` makes (characters, all ASCII): far below
#: the 255 bytes most file systems allow, with room for the suffixes put after it.
SAFE_NAME_LENGTH = 100

#: A descriptor of this process named as a path (``/dev/fd/1``, ``/proc/self/fd/1``):
#: what ``/dev/stdout`` and ``/dev/stderr`` lead to.
_DESCRIPTOR_PATH = re.compile(r"^/(dev|proc/[^/]+)/fd/\d+$")


# ---------------------------------------------------------------------- inputs and outputs


class _Ledger:
    """The inputs and outputs one command has named so far: ``(keys, field, path)`` each."""

    def __init__(self):
        self.inputs: list[tuple[frozenset, str, str]] = []
        self.outputs: list[tuple[frozenset, str, str]] = []
        #: Output folders whose whole content is replaced (a report): ``(real path, field)``.
        self.replaced: list[tuple[str, str]] = []
        #: Device and inode of each file the command has written: read back, not an input.
        self.written: set[tuple] = set()


#: The open ledgers, innermost last (:func:`guarded_files`).
_LEDGERS: list[_Ledger] = []


@contextlib.contextmanager
def guarded_files():
    """Compare every output named in the block with every input named in it.

    The command line opens one around each command. Outside any block :func:`note_input`
    and :func:`claim_output` check nothing: a library caller may read a file and write it
    back on purpose.
    """
    _LEDGERS.append(_Ledger())
    try:
        yield
    finally:
        _LEDGERS.pop()


def _identity(path) -> frozenset:
    """Return what names the file ``path`` leads to: its resolved path, and its inode."""
    keys = set()
    with contextlib.suppress(OSError, ValueError):
        keys.add(("path", os.path.realpath(path)))
    with contextlib.suppress(OSError, ValueError):
        found = os.stat(path)
        keys.add(("inode", found.st_dev, found.st_ino))
    return frozenset(keys)


def _inside(path: str, folder: str) -> bool:
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def note_input(path, field: str) -> None:
    """Name ``path`` as an input of the command (see :func:`guarded_files`).

    Parameters
    ----------
    path : str or PathLike
        A file the command reads.
    field : str
        Where it came from (``"reference"``, ``"lights[0].file"``), for the messages.

    Raises
    ------
    InputError
        When an output already named is that file, or a folder the command replaces
        holds it.
    """
    if not _LEDGERS or path is None:
        return
    ledger = _LEDGERS[-1]
    keys = _identity(path)
    if keys & ledger.written:  # what the command wrote, read back to check it
        return
    for output_keys, output_field, output in ledger.outputs:
        if keys & output_keys:
            raise _collision(output_field, output, f"the input {field} ({path})")
    real = next((key[1] for key in keys if key[0] == "path"), None)
    for folder, output_field in ledger.replaced:
        if real is not None and _inside(real, folder):
            raise _collision(output_field, folder, f"the folder of the input {field} ({path}), "
                             "and its content is replaced")
    ledger.inputs.append((keys, field, str(path)))


def claim_output(path, field: str, *, replaces_folder: bool = False,
                 hint: str = "give another name") -> Path:
    """Name ``path`` as an output of the command, before any work (see :func:`guarded_files`).

    Parameters
    ----------
    path : str or PathLike
        A file (or folder) the command will write.
    field : str
        The option that gave it (``"--out"``), for the messages.
    replaces_folder : bool
        ``path`` is a folder whose whole content is replaced: no input may lie inside.
    hint : str
        How to choose another output, for the message.

    Returns
    -------
    Path

    Raises
    ------
    InputError
        When ``path`` is an input named already (or holds one, for a replaced folder), or
        another output names the same file (streams such as ``/dev/null`` may be shared).
    """
    path = Path(path)
    if not _LEDGERS:
        return path
    ledger = _LEDGERS[-1]
    keys = _identity(path)
    real = next((key[1] for key in keys if key[0] == "path"), None)
    for input_keys, input_field, source in ledger.inputs:
        if keys & input_keys:
            raise _collision(field, path, f"the input {input_field} ({source})", hint)
        if replaces_folder and real is not None and any(
                key[0] == "path" and _inside(key[1], real) for key in input_keys):
            raise _collision(field, path, f"the folder of the input {input_field} ({source}), "
                             "and its content would be replaced", hint)
    if not is_stream(path):
        for output_keys, output_field, output in ledger.outputs:
            if output_field != field and keys & output_keys:
                raise _collision(field, path, f"also the output {output_field} ({output})",
                                 hint)
    ledger.outputs.append((keys, field, str(path)))
    if replaces_folder and real is not None:
        ledger.replaced.append((real, field))
    return path


def _collision(field: str, output, what: str, hint: str = "give another name") -> InputError:
    return InputError(f"is {what}: an output never replaces an input or another output; "
                      f"{hint}", field=field, value=str(output))


def _refuse_input(target: Path) -> None:
    """Refuse to write ``target`` where it is a noted input (the last line of defence)."""
    if not _LEDGERS:
        return
    keys = _identity(target)
    for input_keys, input_field, source in _LEDGERS[-1].inputs:
        if keys & input_keys:
            raise InputError(f"would replace the input {input_field} ({source}); nothing was "
                             "written", file=target, field="path", value=str(target))


def is_stream(path) -> bool:
    """Return whether ``path`` is written as a stream, never renamed over.

    Streams are character devices, FIFOs and sockets, and the descriptors of this process
    named as paths (``/dev/stdout``).
    """
    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return False
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
        return True
    current = os.path.abspath(path)
    for _ in range(40):  # the kernel's own limit on links followed
        if _DESCRIPTOR_PATH.match(current):
            return True
        if not os.path.islink(current):
            return False
        current = os.path.normpath(os.path.join(os.path.dirname(current),
                                                os.readlink(current)))
    return False


@contextlib.contextmanager
def _stream_path(target: Path, suffix: str):
    """Yield a private temporary file; copy it into the stream ``target`` on success."""
    folder = tempfile.mkdtemp(prefix="translucent-stream-")
    tmp = Path(folder) / f"output{suffix}"
    try:
        yield tmp
        sys.stdout.flush()  # what the command printed comes first on a shared stream
        try:
            # appended: a descriptor that is a regular file keeps what was written to it
            with open(tmp, "rb") as source, open(target, "ab") as sink:
                shutil.copyfileobj(source, sink)
        except OSError as error:  # a full device, a closed pipe, ...
            raise InputError(f"could not write it ({error.strerror or error})", file=target,
                             field="path", value=str(target)) from error
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def safe_file_name(name, *, fallback: str = "unnamed") -> str:
    """Return a file name made from ``name`` (a scene's or a capture's), in the working folder.

    Letters and digits (ASCII), ``-``, ``_`` and ``.`` are kept, anything else (``/``, NUL,
    spaces) becomes ``_``; leading dots are dropped (no ``..``, no hidden file); the result
    is at most :data:`SAFE_NAME_LENGTH` characters, ``fallback`` where nothing is left.

    Examples
    --------
    >>> safe_file_name("../../etc/passwd")
    'etc_passwd'
    >>> safe_file_name("sphere")
    'sphere'
    """
    text = "".join(c if (c.isascii() and c.isalnum()) or c in "-_." else "_"
                   for c in str(name))
    if text.startswith("."):
        text = text.lstrip("._")
    return text[:SAFE_NAME_LENGTH] or fallback


def check_input_file(path, field: str, *, file=None, what: str = "file") -> Path:
    """Return ``path`` as a Path if it names a readable regular file; else say what it is.

    Parameters
    ----------
    path : str or PathLike
        The input.
    field : str
        The option or key that gave it, for the message.
    file : str or PathLike, optional
        The file the message is about (a scene file naming a mesh); default ``path``.
    what : str
        What the input is, for the message (``"scene file"``).

    Raises
    ------
    InputError
        Missing, a folder, a name too long or holding a NUL, or not readable; the message
        names the file, the field and the value.
    """
    where = path if file is None else file
    try:
        found = os.stat(path)
    except ValueError as error:  # a NUL in the name
        raise InputError(f"is not a usable path ({error})", file=file, field=field,
                         value=str(path)) from None
    except OSError as error:
        if error.errno in (errno.ENOENT, errno.ENOTDIR):
            reason = f"no such {what}"
        elif error.errno == errno.ENAMETOOLONG:
            reason = f"is not a usable path: a name in it is too long ({len(str(path))} " \
                     "characters in all)"
        else:
            reason = f"cannot be read ({error.strerror or error})"
        raise InputError(reason, file=where if error.errno != errno.ENAMETOOLONG else file,
                         field=field, value=_short_path(path)) from None
    if stat.S_ISDIR(found.st_mode):
        raise InputError(f"is a folder; give a {what}", file=file, field=field, value=str(path))
    return Path(path)


def _short_path(path) -> str:
    """``path`` as text, cut short where a message would otherwise be pages long."""
    text = str(path)
    return text if len(text) <= 200 else f"{text[:120]}...{text[-60:]}"


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
    """Refuse an output file path that names a folder, or no usable path (too long, a NUL).

    The check the writers share.
    """
    path = Path(path)
    found = _usable(path, field, file=file)
    if found is not None and stat.S_ISDIR(found.st_mode):
        raise InputError(f"is a folder; give {what}", file=file, field=field, value=str(path))
    return path


def _usable(path: Path, field: str, *, file=None):
    """Return ``os.stat(path)`` (None where missing); refuse a name too long or with a NUL."""
    try:
        return os.stat(path)
    except ValueError as error:  # a NUL in the name
        raise InputError(f"is not a usable path ({error})", file=file, field=field,
                         value=_short_path(path)) from None
    except OSError as error:
        if error.errno == errno.ENAMETOOLONG:
            raise InputError(f"is not a usable path: a name in it is too long "
                             f"({len(str(path))} characters in all)", file=file, field=field,
                             value=_short_path(path)) from None
        return None  # missing (to be made), or a problem its writer names


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
    claim_output(path, field)
    if is_stream(path):  # written as a stream: nothing is made beside it
        if not os.access(path, os.W_OK):
            raise InputError("cannot be written (no permission)", file=file, field=field,
                             value=str(path))
        return path
    problem = _unwritable(path.parent)
    if problem:
        raise InputError(problem, file=file, field=field, value=str(path))
    return path


def check_output_folder(path, field: str, *, replaces: bool = False) -> Path:
    """Refuse an output-folder option that names a file, or lies under one, before any work.

    Parameters
    ----------
    path : str or PathLike
        The folder (it may not exist yet).
    field : str
        The option's name, for the message (``"--out"``).
    replaces : bool
        The command replaces the folder's whole content: no input may lie inside it
        (:func:`claim_output`).

    Returns
    -------
    Path

    Raises
    ------
    InputError
        ``path`` is a file, or the nearest existing folder above it is a file.
    """
    path = Path(path)
    _usable(path, field)
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
    claim_output(path, field, replaces_folder=replaces)
    return path


@contextlib.contextmanager
def atomic_path(target, suffix: str | None = None):
    """Yield a temporary path beside ``target``; rename it onto ``target`` on success.

    On an exception the temporary file is removed and ``target`` is left untouched.
    ``suffix`` defaults to the target's own (some writers pick a format from it). A
    ``target`` that is a stream (:func:`is_stream`: a character device, a FIFO,
    ``/dev/stdout``) gets a private temporary file whose bytes are written into it on
    success: it is never renamed over.

    Raises
    ------
    InputError
        When ``target`` is a folder, an input of the command (:func:`note_input`), or its
        folder cannot be created or written, before anything is written.
    """
    # its own temporary file below is the test of writing there: no probe first
    target = _not_a_folder(target, "path", file=target)
    _refuse_input(target)
    if is_stream(target):
        with _stream_path(target, target.suffix if suffix is None else suffix) as tmp:
            yield tmp
        return
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
            if _LEDGERS:
                _LEDGERS[-1].written |= {key for key in _identity(target) if key[0] == "inode"}
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
