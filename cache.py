"""A content-addressed on-disk cache for reference renders and precomputations.

Keys are SHA-256 hashes of a canonical JSON of the inputs (scene, knobs, versions), so a
cached result is never computed again and a change of any input misses the cache.
Entries are written atomically (temporary name, then rename).

The folder is ``TRANSLUCENT_CACHE`` if set, else ``$XDG_CACHE_HOME/translucent`` or
``~/.cache/translucent``.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import pickle
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from .atomic import atomic_path
from .errors import InputError

__all__ = ["cache_dir", "content_hash", "private_cache", "limited_entries", "entry_limit",
           "environment_variable", "ENTRY_LIMIT_VARIABLE", "Cache"]

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

    def load_pickle(self, key: str):
        """Return the pickled object stored under ``key``, or None when absent or unreadable."""
        path = self.path(key, ".pkl")
        if not path.is_file():
            return None
        try:
            with open(path, "rb") as handle:
                return pickle.load(handle)
        except Exception:  # a stale or foreign entry is a miss, not a crash
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
            with atomic_path(path) as tmp, open(tmp, "wb") as handle:
                pickle.dump(value, handle, protocol=pickle.HIGHEST_PROTOCOL)
        except InputError as error:
            raise InputError(f"the cache cannot be written ({error.reason}); point "
                             "TRANSLUCENT_CACHE at a writable folder", field="TRANSLUCENT_CACHE",
                             value=str(self.root)) from error
        return path
