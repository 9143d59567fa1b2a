"""A content-addressed on-disk cache for reference renders and precomputations.

Keys are SHA-256 hashes of a canonical JSON of the inputs (scene, knobs, versions), so a
cached result is never computed again and a change of any input misses the cache.
Entries are written atomically (temporary name, then rename).

The folder is ``TRANSLUCENT_CACHE`` if set, else ``$XDG_CACHE_HOME/translucent`` or
``~/.cache/translucent``.

Pickled entries are authenticated: each file starts with an HMAC-SHA256 of its bytes under
a secret key kept outside the cache (:func:`cache_key_file`), checked before anything is
unpickled. A file placed in the cache by someone without the key (a crafted pickle that
would run code, a truncated or altered entry, another version's layout) is a miss, said
once on standard error, never loaded.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import json
import os
import pickle
import secrets
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path
from .errors import InputError

__all__ = ["cache_dir", "cache_key_file", "cache_secret", "content_hash", "private_cache",
           "limited_entries", "entry_limit", "environment_variable", "ENTRY_LIMIT_VARIABLE",
           "KEY_FILE_VARIABLE", "Cache"]

#: The file of the secret key that authenticates pickled entries; default
#: ``$XDG_CONFIG_HOME/translucent/cache-key`` (``~/.config/...``). Machines that share one
#: cache (Dask workers on a shared disk) share this file too.
KEY_FILE_VARIABLE = "TRANSLUCENT_CACHE_KEY_FILE"

#: First bytes of an authenticated pickle entry; the HMAC-SHA256 of the rest follows.
PICKLE_MAGIC = b"TLPKL001"

#: Bytes read at a time when an entry is authenticated.
_CHUNK = 1 << 22

#: The largest entry, in bytes, that :meth:`Cache.store_pickle` keeps when told its size;
#: unset or empty: no limit. Set by :func:`limited_entries`, inherited by worker processes.
ENTRY_LIMIT_VARIABLE = "TRANSLUCENT_CACHE_MAX_ENTRY_BYTES"


def cache_dir() -> Path:
    """Return the cache folder (created on first use)."""
    given = os.environ.get("TRANSLUCENT_CACHE")
    if given:
        return Path(given).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "translucent"


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
    given = os.environ.get(ENTRY_LIMIT_VARIABLE, "").strip()
    if not given:
        return None
    try:
        value = int(given)
    except ValueError:
        value = -1
    if value < 0:
        raise InputError("must be a whole number of bytes >= 0 (or unset: no limit)",
                         field=ENTRY_LIMIT_VARIABLE, value=given)
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

    def path(self, key: str, suffix: str) -> Path:
        """Where the entry for ``key`` lives (it may not exist)."""
        return self.folder / key[:2] / f"{key}{suffix}"

    @contextlib.contextmanager
    def locked(self, key: str, what: str = "this entry"):
        """Hold the entry's lock for the block: one process makes an entry, the others wait.

        Use it around "look the entry up, else compute and store it", looking up again
        inside: a process that waited then finds what the other one stored instead of
        computing it a second time. The lock is ``fcntl.flock`` on ``KEY.lock`` beside the
        entry, released when the block ends or the process dies (``kill -9`` included).
        Where locks cannot be taken (no ``fcntl``, a cache folder that cannot be written),
        the block runs unlocked.

        Parameters
        ----------
        key : str
        what : str
            Named in the one line said on standard error while waiting.
        """
        try:
            import fcntl
        except ImportError:  # not POSIX
            yield
            return
        path = self.path(key, ".lock")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            handle = open(path, "a+b")  # noqa: SIM115 - held for the block
        except OSError:
            yield
            return
        try:
            try:
                fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                print(f"translucent: waiting for another process making {what} "
                      f"({path})", file=sys.stderr, flush=True)
                fcntl.flock(handle, fcntl.LOCK_EX)
            except OSError:  # a file system without locks
                pass
            yield
        finally:
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
            ``nbytes(value) -> int`` for :meth:`store_pickle`'s entry limit.
        """
        def usable(value):
            return value is not None and (valid is None or valid(value))

        value = self.load_pickle(key)
        if usable(value):
            return value, False
        with self.locked(key, what):
            value = self.load_pickle(key)
            if usable(value):
                return value, False
            value = make()
            self.store_pickle(key, value, nbytes=None if nbytes is None else nbytes(value))
            return value, True

    def load_pickle(self, key: str):
        """Return the pickled object stored under ``key``, or None when absent or unusable.

        The entry's HMAC is checked before anything is unpickled: an entry that fails it is
        a miss and is said once on standard error.
        """
        path = self.path(key, ".pkl")
        if not path.is_file():
            return None
        try:
            with open(path, "rb") as handle, _byte_progress(
                    f"reading the {self.folder.name} cache", 2 * path.stat().st_size) as bar:
                counted = _Counted(handle, bar)
                if not _authentic(counted):
                    _report_rejected(path)
                    return None
                return pickle.load(counted)
        except Exception:  # a stale entry of an older layout is a miss, not a crash
            return None

    def store_pickle(self, key: str, value, *, nbytes: int | None = None) -> Path | None:
        """Store ``value`` under ``key`` atomically and return the path.

        Parameters
        ----------
        key : str
        value : object
            Anything picklable.
        nbytes : int, optional
            The size of ``value``'s arrays. Above :func:`entry_limit` nothing is written and
            None is returned: the caller recomputes next time (and may say so).

        Raises
        ------
        InputError
            When the cache folder cannot be written; the message names
            ``TRANSLUCENT_CACHE``, the setting that moves it.
        """
        limit = entry_limit()
        if nbytes is not None and limit is not None and nbytes > limit:
            return None
        path = self.path(key, ".pkl")
        try:
            with atomic_path(path) as tmp, open(tmp, "w+b") as handle, _byte_progress(
                    f"writing the {self.folder.name} cache", nbytes) as bar:
                handle.write(PICKLE_MAGIC + bytes(hashlib.sha256().digest_size))
                signer = _Signing(_Counted(handle, bar))
                pickle.dump(value, signer, protocol=pickle.HIGHEST_PROTOCOL)
                handle.seek(len(PICKLE_MAGIC))
                handle.write(signer.mac.digest())
        except InputError as error:
            raise InputError(f"the cache cannot be written ({error.reason}); point "
                             "TRANSLUCENT_CACHE at a writable folder", field="TRANSLUCENT_CACHE",
                             value=str(self.root)) from error
        return path


def cache_key_file() -> Path:
    """Return where the secret key of the cache's pickled entries is kept."""
    given = os.environ.get(KEY_FILE_VARIABLE)
    if given:
        return Path(given).expanduser()
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"),
                                                             ".config")
    return Path(base) / "translucent" / "cache-key"


def cache_secret() -> bytes:
    """Return the key (32 bytes), created on first use with permissions 0600.

    Where it can be neither read nor created (an unwritable home), this process makes one
    of its own: its entries are then authentic to it alone and the next run misses them.
    Read once per process and key file, not at every entry.
    """
    path = cache_key_file()
    if str(path) not in _KEYS:
        _KEYS[str(path)] = _read_or_make_key(path)
    return _KEYS[str(path)]


#: The keys read or made in this process, by key file.
_KEYS: dict[str, bytes] = {}


def _read_or_make_key(path: Path) -> bytes:
    try:
        key = path.read_bytes()
        if len(key) >= 32:
            return key
    except OSError:
        pass
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".cache-key.", dir=path.parent)  # 0600
        with os.fdopen(fd, "wb") as handle:
            handle.write(secrets.token_bytes(32))
        with contextlib.suppress(FileExistsError):
            os.link(tmp, path)  # never replaces a key another process made meanwhile
        os.unlink(tmp)
        return path.read_bytes()
    except OSError:
        return secrets.token_bytes(32)  # this process's own


def _byte_progress(description: str, total: int | None):
    """Return a progress bar over bytes, shown only once the transfer has taken a second."""
    from tqdm import tqdm

    return tqdm(total=total, desc=description, unit="B", unit_scale=True, leave=False,
                delay=1.0, disable=None)


class _Counted:
    """A file wrapper that advances a byte progress bar as it is read or written."""

    def __init__(self, handle, bar):
        self.handle = handle
        self.bar = bar

    def read(self, size=-1):
        data = self.handle.read(size)
        self.bar.update(len(data))
        return data

    def readline(self, size=-1):
        data = self.handle.readline(size)
        self.bar.update(len(data))
        return data

    def readinto(self, buffer):
        count = self.handle.readinto(buffer)
        self.bar.update(count or 0)
        return count

    def write(self, data) -> int:
        self.bar.update(memoryview(data).nbytes)  # pickle also writes PickleBuffers
        return self.handle.write(data)

    def seek(self, *args):
        return self.handle.seek(*args)


class _Signing:
    """A file wrapper that feeds what is written to an HMAC."""

    def __init__(self, handle):
        self.handle = handle
        self.mac = hmac.new(cache_secret(), digestmod=hashlib.sha256)

    def write(self, data) -> int:
        self.mac.update(data)
        return self.handle.write(data)


def _authentic(handle) -> bool:
    """Check an entry's magic and HMAC, then leave ``handle`` at the start of the pickle."""
    size = hashlib.sha256().digest_size
    head = handle.read(len(PICKLE_MAGIC) + size)
    if len(head) != len(PICKLE_MAGIC) + size or not head.startswith(PICKLE_MAGIC):
        return False
    mac = hmac.new(cache_secret(), digestmod=hashlib.sha256)
    for chunk in iter(lambda: handle.read(_CHUNK), b""):
        mac.update(chunk)
    if not hmac.compare_digest(mac.digest(), head[len(PICKLE_MAGIC):]):
        return False
    handle.seek(len(head))
    return True


_REPORTED: set[str] = set()


def _report_rejected(path: Path) -> None:
    if str(path) not in _REPORTED:
        _REPORTED.add(str(path))
        print(f"translucent: note: the cache entry {path} is not one this installation "
              "wrote (its authentication failed); it is ignored and computed again",
              file=sys.stderr)

