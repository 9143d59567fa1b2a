"""A content-addressed on-disk cache for reference renders and precomputations.

Keys are SHA-256 hashes of a canonical JSON of the inputs (scene, knobs, versions), so a
cached result is never computed again and a change of any input misses the cache.
Entries are written atomically (temporary name, then rename).

The folder is ``TRANSLUCENT_CACHE`` if set, else ``$XDG_CACHE_HOME/translucent`` or
``~/.cache/translucent``. The cache uses only a folder of its own (:func:`check_folder`): one
it made or adopted empty, marked by its ``CACHEDIR.TAG``; any other folder that holds files
is refused, and pruning or clearing removes only files named and placed as its entries
(``NAMESPACE/KE/KEY.SUFFIX``), never anything else. A full disk or quota while writing an
entry is a warning: the result is kept in memory and computed again when next needed.

No pickle is ever loaded from it. Objects (precomputations, method runs) are stored as
``.npz`` entries of arrays and JSON (:mod:`translucent.entries`), read with
``allow_pickle=False`` and rebuilt without running code the file names; each records its
key and the SHA-256 of its arrays. An entry of another key, an altered or truncated one,
or a file of another layout is a miss, said once on standard error, and computed again.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import re
import shutil
import stat
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path, node_kind
from .errors import InputError

__all__ = ["cache_dir", "check_folder", "check_settings", "content_hash", "MARKER_NAME",
           "private_cache", "limited_entries", "entry_limit",
           "environment_variable", "ENTRY_LIMIT_VARIABLE", "ENTRY_SUFFIX", "Cache",
           "BUDGET_VARIABLE", "DEFAULT_BUDGET_BYTES", "CacheEntry", "budget", "cache_entries",
           "prune", "keep_within_budget", "mark_used", "report_rejected", "IN_USE_SECONDS"]

#: The file suffix of an object entry.
ENTRY_SUFFIX = ".entry.npz"

#: The largest entry, in bytes, that :meth:`Cache.store_object` keeps when told its size;
#: unset or empty: no limit. Set by :func:`limited_entries`, inherited by worker processes.
ENTRY_LIMIT_VARIABLE = "TRANSLUCENT_CACHE_MAX_ENTRY_BYTES"


#: The most bytes the whole cache may hold; least recently used entries go first beyond it.
BUDGET_VARIABLE = "TRANSLUCENT_CACHE_MAX_BYTES"

#: The budget where :data:`BUDGET_VARIABLE` is unset: twice what a report that keeps
#: every precomputation writes (``--keep-precomputations``, about 10 GB).
DEFAULT_BUDGET_BYTES = 20 * 2**30

#: An entry written or read this recently (seconds) is in use: never pruned.
IN_USE_SECONDS = 60.0

#: The file at the cache's root that makes a folder the cache's own: a cache directory tag
#: (https://bford.info/cachedir/), so that backup tools skip the folder too.
MARKER_NAME = "CACHEDIR.TAG"

_MARKER_SIGNATURE = b"Signature: 8a477f597d28d172789f06886806bc55"
_MARKER_OWNER = b"created by translucent"
_MARKER_TEXT = (_MARKER_SIGNATURE + b"\n# This file is a cache directory tag " + _MARKER_OWNER
                + b".\n# translucent removes only its own entries here "
                b"(`translucent cache --clear`).\n")

_KEY = r"[0-9a-f]{64}"
#: A namespace's folder, and the folder of the keys that begin with two hex digits.
_NAMESPACE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_-]*$")
_SHARD = re.compile(r"^[0-9a-f]{2}$")
#: An entry: what is counted, pruned and cleared (``.pkl``: the layout before ``.entry.npz``).
_ENTRY = re.compile(rf"^({_KEY})\.(entry\.npz|partial\.npz|exr|pkl)$")
#: What else the cache makes beside its entries: locks, and writes in progress
#: (:func:`translucent.atomic.atomic_path`'s temporary names).
_ENTRY_COMPANION = re.compile(rf"^({_KEY})\.lock$|"
                              rf"^\.({_KEY})(\.entry|\.partial)?\.[A-Za-z0-9_]{{8}}"
                              r"\.part\.(npz|exr|pkl)$")
#: Temporaries at the root: the marker being written, a probe, ``translucent doctor``'s.
_ROOT_TEMPORARY = re.compile(r"^\.(CACHEDIR\.TAG\.|translucent-probe-|doctor-)"
                             r"[A-Za-z0-9_]{8}$")

#: The errors of a write that found no room: a warning, never a failure of the command.
_NO_ROOM = frozenset(code for code in (getattr(errno, name, None)
                                       for name in ("ENOSPC", "EDQUOT", "EFBIG"))
                     if code is not None)


def cache_dir() -> Path:
    """Return the cache folder (made on first use by :func:`check_folder`).

    Raises
    ------
    InputError
        Naming ``TRANSLUCENT_CACHE`` where its ``~user`` names no user.
    """
    given = os.environ.get("TRANSLUCENT_CACHE")
    if given:
        try:
            return Path(given).expanduser()
        except RuntimeError as error:  # "~someone" of no such user
            raise InputError(f"cannot be resolved ({error}): give a folder", field=
                             "TRANSLUCENT_CACHE", value=given) from None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "translucent"


def check_settings() -> None:
    """Check the cache's settings (folder, budget, entry limit) before any work.

    Raises
    ------
    InputError
        Naming the environment variable and its value, where one cannot be used.
    """
    cache_dir()
    budget()
    entry_limit()


def _refused(root: Path, why: str) -> InputError:
    """Return the refusal of the cache folder ``root``, saying ``why``."""
    return InputError(f"the cache cannot be written ({why}); point TRANSLUCENT_CACHE at a "
                      "writable folder", field="TRANSLUCENT_CACHE", value=str(root))


def check_folder(root=None, *, create: bool = True) -> Path:
    """Return the cache folder once it is known to be the cache's own and writable.

    The one check of the folder, before anything is written or removed there: the commands
    (``translucent cache``, a render, a precomputation) and :func:`prune` all pass here.
    A folder that does not exist is made; one marked by the cache's :data:`MARKER_NAME` is
    the cache's; an unmarked one is adopted (marked) only where it is empty or holds
    nothing but what the cache itself makes (an older cache, made before the marker).

    Parameters
    ----------
    root : path, optional
        The folder; default :func:`cache_dir`.
    create : bool
        Make the folder where it does not exist; False: return it as it is (nothing to
        list or remove).

    Returns
    -------
    Path

    Raises
    ------
    InputError
        Naming ``TRANSLUCENT_CACHE`` and the folder, where it is no folder (a file, a FIFO,
        a link to nothing, a loop of links), cannot be made or written, or is not a cache
        (no marker) and holds anything else. A full disk or quota is only a warning.
    """
    root = Path(root) if root is not None else cache_dir()
    try:
        found = os.stat(root)
    except ValueError as error:  # a NUL in the name
        raise InputError(f"is not a usable path ({error})", field="TRANSLUCENT_CACHE",
                         value=str(root)) from None
    except OSError as error:
        if error.errno == errno.ELOOP:
            raise _refused(root, "it is a loop of symbolic links") from None
        if os.path.islink(root):
            raise _refused(root, f"it is a symbolic link to {os.readlink(root)}, which does "
                           "not exist") from None
        if error.errno == errno.ENOTDIR:
            raise _refused(root, "it cannot be made: a file stands in its path") from None
        if error.errno != errno.ENOENT:
            raise _refused(root, error.strerror or str(error)) from None
        if not create:
            return root
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError as made:
            if made.errno in _NO_ROOM:
                _warn_no_room(root, root, made.strerror or str(made))
                return root
            raise _refused(root, f"it cannot be made: {made.strerror or made}") from None
        return _mark(root)
    if not stat.S_ISDIR(found.st_mode):
        kind = "a file" if stat.S_ISREG(found.st_mode) else node_kind(found.st_mode)
        raise _refused(root, f"it is {kind}, not a folder")
    if _is_marked(root):
        return _probe(root)
    foreign = _first_foreign(root)
    if foreign is not None and _is_marked(root):
        # another process (or thread) marked the new folder while this one looked
        return _probe(root)
    if foreign is not None:
        raise InputError(
            f"is not a translucent cache (no {MARKER_NAME} of translucent) and holds other "
            f"files ({foreign}); the cache removes entries to keep within its budget, so it "
            "uses only a folder of its own: point TRANSLUCENT_CACHE at a new or empty folder",
            field="TRANSLUCENT_CACHE", value=str(root))
    return _mark(root)


def _is_marked(root: Path) -> bool:
    """Return whether ``root`` holds the cache's own marker (a regular file, not a link)."""
    flags = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
    try:
        fd = os.open(root / MARKER_NAME, flags)
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        head = os.read(fd, 512)
    except OSError:
        return False
    finally:
        os.close(fd)
    return head.startswith(_MARKER_SIGNATURE) and _MARKER_OWNER in head


def _mark(root: Path) -> Path:
    """Write the marker into ``root`` (the test of writing there too); return ``root``."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{MARKER_NAME}.", dir=root)
    except OSError as error:
        if error.errno in _NO_ROOM:
            _warn_no_room(root, root / MARKER_NAME, error.strerror or str(error))
            return root
        raise _refused(root, error.strerror or str(error)) from None
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(_MARKER_TEXT)
        os.chmod(tmp, 0o644)
        os.replace(tmp, root / MARKER_NAME)
    except OSError as error:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if error.errno in _NO_ROOM:
            _warn_no_room(root, root / MARKER_NAME, error.strerror or str(error))
            return root
        raise _refused(root, error.strerror or str(error)) from None
    return root


def _probe(root: Path) -> Path:
    """Return ``root`` once a file could be made in it (tried: permission bits can mislead)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".translucent-probe-", dir=root)
    except OSError as error:
        if error.errno in _NO_ROOM:
            _warn_no_room(root, root, error.strerror or str(error))
            return root
        raise _refused(root, error.strerror or str(error)) from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return root


def _own_files(root: Path):
    """Yield ``(namespace, path, dir entry)`` of each file where the cache puts its entries.

    ``root/NAMESPACE/KE/NAME``: only real folders are walked (no link is followed), and a
    folder that cannot be read is passed over.
    """
    for namespace in _scan(root) or ():
        if not (_NAMESPACE.match(namespace.name) and namespace.is_dir(follow_symlinks=False)):
            continue
        for shard in _scan(namespace.path) or ():
            if not (_SHARD.match(shard.name) and shard.is_dir(follow_symlinks=False)):
                continue
            for item in _scan(shard.path) or ():
                yield namespace.name, Path(item.path), item


def _scan(folder) -> list | None:
    """Return the entries of ``folder``; None where it cannot be read."""
    try:
        with os.scandir(folder) as found:
            return list(found)
    except OSError:
        return None


def _entry_key(name: str, shard: str) -> str | None:
    """Return the key an entry's file name holds, if it is an entry's name in ``shard``."""
    match = _ENTRY.match(name)
    return match.group(1) if match and match.group(1).startswith(shard) else None


def _first_foreign(root: Path) -> str | None:
    """Return the first path in ``root`` (relative) the cache did not make; None if none.

    A folder that cannot be read counts as not the cache's.
    """
    items = _scan(root)
    if items is None:
        return "."
    for item in items:
        name = item.name
        if _ROOT_TEMPORARY.match(name) and item.is_file(follow_symlinks=False):
            continue
        if not (_NAMESPACE.match(name) and item.is_dir(follow_symlinks=False)):
            return name
        shards = _scan(item.path)
        if shards is None:
            return name
        for shard in shards:
            if not (_SHARD.match(shard.name) and shard.is_dir(follow_symlinks=False)):
                return f"{name}/{shard.name}"
            files = _scan(shard.path)
            if files is None:
                return f"{name}/{shard.name}"
            for file in files:
                if not (file.is_file(follow_symlinks=False) and _own_name(file.name, shard.name)):
                    return f"{name}/{shard.name}/{file.name}"
    return None


def _own_name(name: str, shard: str) -> bool:
    """Return whether ``name`` in the folder ``shard`` is a name the cache gives its files."""
    if _entry_key(name, shard) is not None:
        return True
    match = _ENTRY_COMPANION.match(name)
    return bool(match) and (match.group(1) or match.group(2)).startswith(shard)


def _no_room(error: BaseException) -> str | None:
    """Return the system's words where ``error`` says the disk or quota is full; else None.

    An ``OSError`` says it by its number; the writers' own errors (an ``InputError`` of
    :mod:`translucent.atomic` naming the file) by the ``OSError`` behind them or by their
    ``why``.
    """
    for found in (error, error.__cause__):
        if isinstance(found, OSError) and found.errno in _NO_ROOM:
            return found.strerror or os.strerror(found.errno)
    why = getattr(error, "why", None)
    return why if why in {os.strerror(code) for code in _NO_ROOM} else None


_NO_ROOM_SAID: set[str] = set()


def _warn_no_room(root: Path, path: Path, reason: str) -> None:
    """Say once per cache folder that ``path`` found no room; the command goes on."""
    if str(root) in _NO_ROOM_SAID:
        return
    _NO_ROOM_SAID.add(str(root))
    print(f"translucent: warning: the cache cannot store {path} ({reason}); results are not "
          "kept there and are computed again when next needed", file=sys.stderr, flush=True)


@contextlib.contextmanager
def environment_variable(name: str, value: str | None):
    """Set the environment variable ``name`` to ``value`` (None: unset) for the block.

    The previous setting comes back afterwards; worker processes started inside inherit
    the block's.
    """
    previous = os.environ.get(name)
    if value is None:
        os.environ.pop(name, None)
    else:
        os.environ[name] = value
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = previous


@contextlib.contextmanager
def private_cache(prefix: str = "translucent-cold-"):
    """Point ``TRANSLUCENT_CACHE`` at an empty temporary folder for the block.

    Precomputations inside run cold (what a benchmark or a cold-cache report measures);
    the folder is removed and the previous setting restored afterwards. Yields the folder.
    """
    folder = tempfile.mkdtemp(prefix=prefix)
    try:
        with environment_variable("TRANSLUCENT_CACHE", folder):
            yield Path(folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def entry_limit() -> int | None:
    """Return the entry limit of :data:`ENTRY_LIMIT_VARIABLE` in bytes, or None (no limit).

    Raises
    ------
    InputError
        When the variable holds anything but a whole number >= 0.
    """
    return _bytes_setting(ENTRY_LIMIT_VARIABLE, "or unset: no limit")


def _bytes_setting(variable: str, zero_or_unset: str) -> int | None:
    """Return the whole number of bytes >= 0 that ``variable`` holds; None where unset.

    Raises
    ------
    InputError
        Naming the variable, when it holds anything else; ``zero_or_unset`` says what
        0 or no value means for it.
    """
    given = os.environ.get(variable, "").strip()
    if not given:
        return None
    try:
        value = int(given)
    except ValueError:
        value = -1
    if value < 0:
        raise InputError(f"must be a whole number of bytes >= 0 ({zero_or_unset})",
                         field=variable, value=given)
    return value


@contextlib.contextmanager
def limited_entries(max_bytes: int | None):
    """Keep cache entries of at most ``max_bytes`` for the block (None: no limit).

    Sets :data:`ENTRY_LIMIT_VARIABLE`, so worker processes started inside inherit it; the
    previous setting is restored afterwards.
    """
    if max_bytes is not None and (int(max_bytes) != max_bytes or max_bytes < 0):
        raise InputError("must be a whole number of bytes >= 0", field="max_bytes",
                         value=max_bytes)
    with environment_variable(ENTRY_LIMIT_VARIABLE,
                              None if max_bytes is None else str(int(max_bytes))):
        yield


def _canonical(value: Any) -> Any:
    """Return a JSON-able, order-independent form; arrays hash by dtype, shape and bytes."""
    if isinstance(value, np.ndarray):
        return {"__ndarray__": hashlib.sha256(np.ascontiguousarray(value).tobytes()).hexdigest(),
                "dtype": str(value.dtype), "shape": list(value.shape)}
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "cache_key"):
        return _canonical(value.cache_key())
    return value


def content_hash(*parts: Any) -> str:
    """SHA-256 hex digest of the canonical JSON of ``parts``.

    Objects with a ``cache_key()`` method (scenes, materials) contribute what it returns.
    """
    text = json.dumps(_canonical(list(parts)), sort_keys=True, separators=(",", ":"),
                      default=repr)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class Cache:
    """One namespace of the cache: ``Cache("reference").path(key, ".exr")``.

    Parameters
    ----------
    namespace : str
        Sub-folder (``"reference"``, ``"prt"``, ...).
    root : path, optional
        Overrides :func:`cache_dir`.
    """

    def __init__(self, namespace: str, root=None):
        self.root = Path(root) if root is not None else cache_dir()
        self.folder = self.root / namespace
        self._checked = False

    def check(self) -> Path:
        """Check the folder (:func:`check_folder`) before the first write; return the root.

        Reading needs no check: an entry is served only once its key and checksum match.
        """
        if not self._checked:
            check_folder(self.root)
            self._checked = True
        return self.root

    def path(self, key: str, suffix: str) -> Path:
        """Where the entry for ``key`` lives (it may not exist)."""
        return self.folder / key[:2] / f"{key}{suffix}"

    def make_room(self, path: Path) -> Path:
        """Remove what stands at the entry ``path`` but is no file (a folder, a link): a miss.

        Said once on standard error; the entry is then made again in its place. Returns
        ``path``.

        Raises
        ------
        InputError
            Where the cache's folder may not be used (:func:`check_folder`).
        """
        self.check()
        try:
            found = os.lstat(path)
        except OSError:
            return path
        if stat.S_ISREG(found.st_mode):
            return path
        report_rejected(path, "it is not a file")
        with contextlib.suppress(OSError):
            if stat.S_ISDIR(found.st_mode):
                shutil.rmtree(path)
            else:
                path.unlink()
        return path

    @contextlib.contextmanager
    def locked(self, key: str, what: str = "this entry"):
        """Hold the entry's lock for the block: one process makes an entry, the others wait.

        Use it around "look the entry up, else compute and store it", looking up again
        inside: a process that waited then finds what the other one stored instead of
        computing it a second time. The lock is ``fcntl.flock`` on ``KEY.lock`` beside the
        entry, released when the block ends or the process dies (``kill -9`` included; the
        file is removed when the block ends, and one a killed process left is only ever
        locked again, never trusted as an entry).
        Where locks cannot be taken (no ``fcntl``, a full disk), the block runs unlocked;
        a folder that is not the cache's or cannot be written (:func:`check_folder`) is
        refused before the block, so before any work.

        Parameters
        ----------
        key : str
        what : str
            Named in the one line said on standard error while waiting.
        """
        self.check()
        try:
            import fcntl
        except ImportError:  # not POSIX
            yield
            return
        path = self.path(key, ".lock")
        waited = False
        while True:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                handle = open(path, "a+b")  # noqa: SIM115 - held for the block
            except OSError:
                yield
                return
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                if not waited:
                    print(f"translucent: waiting for another process making {what} "
                          f"({path})", file=sys.stderr, flush=True)
                    waited = True
                fcntl.flock(handle, fcntl.LOCK_EX)
            except OSError:  # a file system without locks
                break
            # the holder before us removed the file it locked: lock the one on disk now
            try:
                current = os.fstat(handle.fileno()).st_ino == os.stat(path).st_ino
            except OSError:
                current = False
            if current:
                break
            handle.close()
        try:
            yield
        finally:
            # removed while still held, so that no lock file is left in the cache; a waiter
            # on this file finds it gone and locks a new one
            with contextlib.suppress(OSError):
                path.unlink()
            handle.close()  # releases the lock

    def load_or_make(self, key: str, make, *, valid=None, what: str = "this entry",
                     nbytes=None):
        """Return ``(value, made)``: the entry under ``key``, or ``make()`` stored there.

        Under the entry's lock (:meth:`locked`), looked up again once the lock is held: of
        several processes asking at once, one makes it and the others read it.

        Parameters
        ----------
        key : str
        make : callable
            ``make() -> value``, called only on a miss.
        valid : callable, optional
            ``valid(value) -> bool``: a stored value it refuses is a miss (another layout).
        what : str
            Named while a process waits.
        nbytes : callable, optional
            ``nbytes(value) -> int`` for :meth:`store_object`'s entry limit.
        """
        def usable(value):
            return value is not None and (valid is None or valid(value))

        value = self.load_object(key)
        if usable(value):
            return value, False
        with self.locked(key, what):
            value = self.load_object(key)
            if usable(value):
                return value, False
            value = make()
            self.store_object(key, value, nbytes=None if nbytes is None else nbytes(value))
            return value, True

    def load_object(self, key: str):
        """Return the object stored under ``key``, or None when absent or untrusted.

        The entry is read without pickle (:func:`translucent.entries.read_entry`); one of
        another key or layout, or whose arrays changed, is a miss and is said once on
        standard error.
        """
        from .entries import EntryError, read_entry

        path = self.path(key, ENTRY_SUFFIX)
        if not path.is_file():
            if os.path.lexists(path):
                report_rejected(path, "it is not a file")
            return None
        try:
            with _byte_progress(f"reading the {self.folder.name} cache",
                                path.stat().st_size) as bar:
                value = read_entry(path, key, progress=bar.update)
            mark_used(path)
            return value
        except EntryError as error:
            report_rejected(path, str(error))
            return None
        except OSError:
            return None

    def store_object(self, key: str, value, *, nbytes: int | None = None) -> Path | None:
        """Store ``value`` under ``key`` atomically and return the path.

        Parameters
        ----------
        key : str
        value : object
            What :mod:`translucent.entries` stores: arrays, numbers, strings, containers
            and the package's own objects made of them.
        nbytes : int, optional
            The size of ``value``'s arrays. Above :func:`entry_limit` nothing is written and
            None is returned: the caller recomputes next time (and may say so).

        Returns
        -------
        Path or None
            None where nothing was kept: over the limit, a value that cannot be stored, or
            no room on the disk or in the quota (said once on standard error; nothing of the
            entry is left behind).

        Raises
        ------
        InputError
            When the cache folder cannot be written or is not the cache's
            (:func:`check_folder`); the message names ``TRANSLUCENT_CACHE``, the setting
            that moves it.
        """
        from .entries import EntryError, write_entry

        limit = entry_limit()
        if nbytes is not None and limit is not None and nbytes > limit:
            return None
        path = self.make_room(self.path(key, ENTRY_SUFFIX))
        stored = False
        with self.storing(path):
            try:
                with atomic_path(path, suffix=".npz") as tmp, open(tmp, "w+b") as handle, \
                        _byte_progress(f"writing the {self.folder.name} cache", nbytes) as bar:
                    write_entry(handle, key, value, progress=bar.update)
            except EntryError:
                return None  # kept in memory only; the atomic write left nothing behind
            stored = True
        if not stored:
            return None
        keep_within_budget(self.root)
        return path

    @contextlib.contextmanager
    def storing(self, path: Path):
        """Write the entry ``path`` in the block (atomically); no room is only a warning.

        A disk or quota that is full (``ENOSPC``, ``EDQUOT``, ``EFBIG``) is said once on
        standard error, naming the path, and the block ends quietly: the caller keeps its
        result, and the atomic write left no partial entry. Any other failure to write is
        an :class:`InputError` naming ``TRANSLUCENT_CACHE``.
        """
        try:
            yield
        except (InputError, OSError) as error:
            full = _no_room(error)
            if full is not None:
                _warn_no_room(self.root, path, full)
                return
            reason = error.reason if isinstance(error, InputError) else \
                f"{path}: {error.strerror or error}"
            raise InputError(f"the cache cannot be written ({reason}); point "
                             "TRANSLUCENT_CACHE at a writable folder", field="TRANSLUCENT_CACHE",
                             value=str(self.root)) from error


def budget() -> int | None:
    """Return the cache's budget in bytes (:data:`BUDGET_VARIABLE`), or None (no limit).

    Unset: :data:`DEFAULT_BUDGET_BYTES`; ``0``: no limit.

    Raises
    ------
    InputError
        When the variable holds anything but a whole number >= 0.
    """
    value = _bytes_setting(BUDGET_VARIABLE, "0: no limit")
    return DEFAULT_BUDGET_BYTES if value is None else (value or None)


def mark_used(path) -> None:
    """Mark a cache entry as just used (its modification time): pruned last."""
    with contextlib.suppress(OSError):
        os.utime(path)


@dataclass(frozen=True)
class CacheEntry:
    """One file of the cache: an entry, a reference image or a resumable render.

    Attributes
    ----------
    path : Path
    namespace : str
        Its sub-folder (``"radiosity"``, ``"reference"``, ...).
    nbytes : int
    used : float
        When it was last written or read (POSIX time).
    """

    path: Path
    namespace: str
    nbytes: int
    used: float


def cache_entries(root=None) -> list[CacheEntry]:
    """Return the cache's entries, least recently used first.

    Only regular files named and placed as entries are (``NAMESPACE/KE/KEY.SUFFIX``, no
    link followed): lock files, the hidden temporary files of a write in progress and
    anything else in the folder are not.
    """
    root = Path(root) if root is not None else cache_dir()
    found = []
    if not root.is_dir():
        return found
    for namespace, path, item in _own_files(root):
        if _entry_key(path.name, path.parent.name) is None:
            continue
        try:
            info = item.stat(follow_symlinks=False)
        except OSError:  # removed meanwhile
            continue
        if stat.S_ISREG(info.st_mode):
            found.append(CacheEntry(path, namespace, info.st_size, info.st_mtime))
    return sorted(found, key=lambda entry: (entry.used, str(entry.path)))


def prune(max_bytes: int | None, root=None, *, keep_recent: bool = True) -> list[CacheEntry]:
    """Remove least recently used entries until the cache holds at most ``max_bytes``.

    Parameters
    ----------
    max_bytes : int or None
        None: remove nothing. 0 with ``keep_recent=False``: remove every entry.
    root : path, optional
        Overrides :func:`cache_dir`.
    keep_recent : bool
        Never remove an entry written or read in the last :data:`IN_USE_SECONDS` (another
        process may be about to read what it just stored).

    Returns
    -------
    list of CacheEntry
        What was removed: only the cache's entries (:func:`cache_entries`), never another
        file. A reader that meets a removed entry computes it again.

    Raises
    ------
    InputError
        Where the folder is not the cache's or cannot be written (:func:`check_folder`).
    OSError
        Where an entry cannot be removed (no permission); those before it are removed.
    """
    if max_bytes is None:
        return []
    root = check_folder(root, create=False)
    entries = cache_entries(root)
    total = sum(entry.nbytes for entry in entries)
    recent = time.time() - IN_USE_SECONDS
    removed = []
    for entry in entries:
        if total <= max_bytes:
            break
        if keep_recent and entry.used > recent:
            continue
        with contextlib.suppress(FileNotFoundError):
            entry.path.unlink()
            removed.append(entry)
        total -= entry.nbytes
    return removed


def keep_within_budget(root=None) -> list[CacheEntry]:
    """Prune the cache to :func:`budget`, least recently used first (after every store)."""
    try:
        return prune(budget(), root)
    except OSError:  # a folder another process is pruning or removing: the next store tries
        return []


def _byte_progress(description: str, total: int | None):
    """Return a progress bar over bytes, shown only once the transfer has taken a second."""
    from .progress import progress_bar

    return progress_bar(total=total, description=description, unit="B", unit_scale=True,
                        delay=1.0)


_REPORTED: set[str] = set()


def report_rejected(path: Path, reason: str) -> None:
    """Say once on standard error that the cache entry ``path`` is not used, and why."""
    if str(path) not in _REPORTED:
        _REPORTED.add(str(path))
        print(f"translucent: note: the cache entry {path} is not trusted ({reason}); it is "
              "ignored and computed again", file=sys.stderr)

