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

An output that cannot be written (a full disk, a quota, a read-only mount) is an
:class:`OutputError` (an :class:`~translucent.errors.InputError`: the command line's exit
code 2, one line naming the path), whatever the writer raised (``OSError``, OpenEXR's and
Mitsuba's ``RuntimeError``), and leaves nothing behind: no temporary file, no folder made
for it (:func:`output_folder`), no staging folder (:mod:`translucent.staging`). Temporary
names fit the file system's limit on a name whatever the target's
(:mod:`translucent.temporaries`).
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
from pathlib import Path

from .errors import InputError
from .temporaries import ORPHAN_AGE_SECONDS, ORPHAN_NAME, sweep_orphans, temporary_affixes

# ORPHAN_AGE_SECONDS, ORPHAN_NAME and sweep_orphans are named here too, where they were
__all__ = ["ORPHAN_AGE_SECONDS", "ORPHAN_NAME", "OutputError", "atomic_path",
           "atomic_write_bytes", "atomic_write_text", "check_input_file", "check_output_file",
           "check_output_folder", "claim_output", "failed_file", "guarded_files", "is_stream",
           "make_output_folder", "node_kind", "note_input", "output_failure", "output_folder",
           "safe_file_name", "sweep_orphans"]

#: The suffixes a temporary file keeps (some writers pick a format from it); another
#: (long, or of other characters) is left off, so that every temporary matches ORPHAN_NAME.
_PLAIN_SUFFIX = re.compile(r"^\.[A-Za-z0-9]{1,16}$")

#: What says that an output cannot take its bytes, whichever file the error names: no
#: space, a quota, a file too large for the file system, a read-only file system.
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})


class OutputError(InputError):
    """An output that cannot be written (a full disk, a quota, a read-only mount).

    An :class:`~translucent.errors.InputError`: the command line exits 2 with one line that
    names the path; nothing half-written is left. ``why`` is the system's reason alone
    (``"No space left on device"``), where known.
    """

    def __init__(self, message: str, *, why: str | None = None, **where):
        super().__init__(message, **where)
        self.why = why or message


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
    try:
        folder = tempfile.mkdtemp(prefix="translucent-stream-")
    except OSError as error:  # the temporary folder's disk is full, ...
        raise OutputError(f"could not write it: no temporary file can be made in "
                          f"{tempfile.gettempdir()} ({error.strerror or error})", file=target,
                          field="path", value=str(target)) from error
    tmp = Path(folder) / f"output{suffix if _PLAIN_SUFFIX.match(suffix) else ''}"
    try:
        try:
            yield tmp
        except Exception as error:
            reason = output_failure(error, names=(str(tmp),), folder=folder)
            if reason is None:
                raise
            raise OutputError(f"could not write it: its temporary copy in {folder} failed "
                              f"({reason})", file=target, field="path",
                              value=str(target)) from error
        sys.stdout.flush()  # what the command printed comes first on a shared stream
        try:
            # appended: a descriptor that is a regular file keeps what was written to it
            with open(tmp, "rb") as source, open(target, "ab") as sink:
                shutil.copyfileobj(source, sink)
        except OSError as error:  # a full device, a closed pipe, ...
            raise OutputError(f"could not write it ({error.strerror or error})", file=target,
                              field="path", value=str(target), why=error.strerror) from error
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
        Missing, a folder, a FIFO, a device or a socket (refused before it is opened), a
        name too long or holding a NUL, or not readable; the message names the file, the
        field and the value.
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
    if not stat.S_ISREG(found.st_mode):
        # refused before it is opened: opening a FIFO waits for a writer that may never
        # come, and a device (/dev/zero) never ends
        raise InputError(f"is {node_kind(found.st_mode)}, not a regular file; give a {what}",
                         file=file, field=field, value=str(path))
    return Path(path)


def node_kind(mode: int) -> str:
    """Name the kind of a file that is neither a regular file nor a folder (from its mode).

    Examples
    --------
    >>> import stat
    >>> node_kind(stat.S_IFIFO)
    'a FIFO'
    """
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISSOCK(mode):
        return "a socket"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    return "a special file"


def _short_path(path) -> str:
    """``path`` as text, cut short where a message would otherwise be pages long."""
    text = str(path)
    return text if len(text) <= 200 else f"{text[:120]}...{text[-60:]}"


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
        raise OutputError(f"cannot create {what} ({error.strerror or error})", file=file,
                          field=field, value=value, why=error.strerror) from error
    return folder


def _missing_folders(folder) -> list[Path]:
    """Return the folders that making ``folder`` would create, deepest first."""
    missing = []
    folder = Path(folder).absolute()
    while not os.path.lexists(folder) and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    return missing


def _remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (deepest first) as long as each is empty; stop at one that is not."""
    for folder in folders:
        try:
            folder.rmdir()
        except FileNotFoundError:
            continue
        except OSError:
            break


def output_failure(error: BaseException, *, names=(), folder=None) -> str | None:
    """Return why an output could not be written, where ``error`` says so; else None.

    Parameters
    ----------
    error : BaseException
        What a writer raised.
    names : iterable of str
        The files being written: an ``OSError`` about one of them, or another exception
        whose message names one, is the output's.
    folder : str or PathLike, optional
        Where they are written: a writer's exception that says nothing more (OpenEXR's
        "Failed to write pixel data") is the output's when that file system is full.

    Returns
    -------
    str or None
        The reason, for a message (``"No space left on device"``); None for an exception
        that is not the output's (a bug, an input, an interrupt) and for an
        :class:`~translucent.errors.InputError`, which says what it is already.
    """
    if isinstance(error, InputError) or not isinstance(error, Exception):
        return None
    names = [str(name) for name in names]
    if isinstance(error, OSError):
        if error.errno in WRITE_ERRNOS or failed_file(error) in names:
            return error.strerror or str(error)
        return None
    # OpenEXR and Mitsuba raise RuntimeError with the system's words in the message
    text = str(error)
    for code in sorted(WRITE_ERRNOS):
        if os.strerror(code) in text:
            return os.strerror(code)
    if any(name and name in text for name in names):
        return text
    if folder is not None:
        try:
            if os.statvfs(folder).f_bavail == 0:
                return os.strerror(errno.ENOSPC)
        except (OSError, ValueError):
            pass
    return None


def failed_file(error: BaseException) -> str | None:
    """Return the file an ``OSError`` names (its ``filename``), as text; None if none."""
    name = getattr(error, "filename", None)
    return os.fsdecode(name) if isinstance(name, str | bytes | os.PathLike) else None


@contextlib.contextmanager
def output_folder(folder, *, field: str, value=None, file=None, create: bool = False,
                  what: str | None = None):
    """Write the block's outputs into ``folder``; a failure leaves no folder made for them.

    On an exception in the block the folders that did not exist before it (``folder`` and
    those above it) are removed where empty, and a failure to write
    (:func:`output_failure`) becomes an :class:`OutputError` naming ``value``.

    Parameters
    ----------
    folder : str or PathLike
        Where the outputs go.
    field, value, file
        What a message names: the option, its value (default ``folder``), the file.
    create : bool
        Create ``folder`` before the block (:func:`make_output_folder`): before work that
        would be lost if it could not be made.
    what : str, optional
        How a message calls the folder.

    Yields
    ------
    Path
    """
    folder = Path(folder)
    value = str(folder) if value is None else value
    missing = _missing_folders(folder)
    try:
        if create:
            make_output_folder(folder, field=field, value=value, file=file, what=what)
        yield folder
    except BaseException as error:
        _remove_empty(missing)
        existing = folder.absolute()
        while not existing.exists() and existing != existing.parent:
            existing = existing.parent
        if isinstance(error, OutputError) and error.field == "path" and isinstance(
                error.value, str) and _inside(os.path.abspath(error.value), str(folder.absolute())):
            # a writer's own (atomic_path's) in the folder: named by the option that gave it
            raise OutputError(error.reason, why=error.why, field=field,
                              value=error.value) from error
        reason = output_failure(error, folder=existing)
        if reason is None:
            raise
        where = failed_file(error)
        where = f"{where}: " if where else ""
        raise OutputError(f"could not write it ({where}{reason})", why=f"{where}{reason}",
                          file=file, field=field, value=value) from error


def _umask() -> int:
    umask = os.umask(0)
    os.umask(umask)
    return umask


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
    OutputError
        When the block fails to write the temporary file (:func:`output_failure`: no space
        left, a quota, a writer's own error about it); the temporary file is removed.
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
    # kept only where short and plain; the name cut to fit the longest name allowed
    tail = f".part{suffix if _PLAIN_SUFFIX.match(suffix) else ''}"
    prefix, tail = temporary_affixes(target.stem, tail, target.parent)
    try:
        fd, tmp = tempfile.mkstemp(prefix=prefix, suffix=tail, dir=target.parent)
    except OSError as error:  # no permission, a read-only mount, /proc, no space, ...
        raise OutputError(f"cannot write in {target.parent} ({error.strerror or error})",
                          file=target, field="path", value=str(target),
                          why=error.strerror) from error
    os.close(fd)
    tmp = Path(tmp)
    # mkstemp creates 0600; give the result the permissions an ordinary file would have
    os.chmod(tmp, 0o666 & ~_umask())
    try:
        try:
            yield tmp
            os.replace(tmp, target)
            if _LEDGERS:
                _LEDGERS[-1].written |= {key for key in _identity(target) if key[0] == "inode"}
        except Exception as error:
            # not the output's (an input read inside the block, a bug): raised as it is
            reason = output_failure(error, names=(str(tmp),), folder=target.parent)
            if reason is None:
                raise
            reason = reason.replace(str(tmp), str(target))
            raise OutputError(f"could not write it ({reason})", why=reason, file=target,
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

    try:
        with atomic_path(target, suffix=".png") as tmp:
            figure.savefig(tmp, format="png", dpi=dpi)
    finally:
        plt.close(figure)  # closed on a failure too: figures are held until closed
    return Path(target)
