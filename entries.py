"""Cache entries without pickle: arrays in an ``.npz``, everything else in JSON.

A pickle runs code when it is loaded, so a cache that loads pickles trusts whoever can
write its folder. An entry here is an uncompressed ``.npz`` read with
``allow_pickle=False``: one member per array and one, ``__entry__``, holding a JSON
description of the object. Rebuilding it never calls code the entry names: objects are
made with ``object.__new__`` and given their attributes, and only classes of this package
(``translucent.*``) may be named. The JSON also records the entry's key and the SHA-256 of
its arrays, checked on reading: an entry of another key, or whose bytes changed, is a
miss.

What can be stored: None, booleans, integers, floats, strings, bytes, lists, tuples,
sets, dicts, numpy arrays (not of dtype object) and scalars, ``pathlib`` paths, SciPy
sparse matrices, and instances of the package's classes (dataclasses and plain classes)
made of these. Anything else (a function, an open file) is an :class:`EntryError`: the
caller keeps the value in memory only.

Examples
--------
>>> import io
>>> from translucent.fast.base import StageLog
>>> log = StageLog(skipped=["one"], seconds={"solve": 1.5})
>>> buffer = io.BytesIO()
>>> _ = write_entry(buffer, "k", {"log": log, "values": np.arange(3.0)})
>>> _ = buffer.seek(0)
>>> back = read_entry(buffer, "k")
>>> back["log"] == log, back["values"].tolist()
(True, [0.0, 1.0, 2.0])
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import pathlib
import zipfile
from typing import Any

import numpy as np

__all__ = ["ENTRY_FORMAT", "EntryError", "read_entry", "write_entry"]

#: The layout written; an entry of another layout is a miss.
ENTRY_FORMAT = "translucent-entry-1"

#: The member of the ``.npz`` that holds the JSON description.
_META = "__entry__"

#: Modules whose classes an entry may name.
_PACKAGE = "translucent."


class EntryError(ValueError):
    """A value that cannot be stored, or an entry that cannot be trusted (a miss)."""


class _Encoder:
    def __init__(self):
        self.arrays: list[np.ndarray] = []

    def array(self, value: np.ndarray) -> dict:
        if value.dtype.hasobject:
            raise EntryError("an array of Python objects cannot be stored")
        # not ascontiguousarray: it makes a 0-d array 1-d
        self.arrays.append(value if value.flags.c_contiguous else value.copy(order="C"))
        return {"@array": len(self.arrays) - 1}

    def __call__(self, value):  # noqa: C901 - one case a type
        if isinstance(value, np.generic):  # before float: np.float64 is a float
            return {"@scalar": self.array(np.asarray(value))}
        if value is None or isinstance(value, (bool, str)):
            return value
        if isinstance(value, int):
            return value if abs(value) < 2**53 else {"@int": str(value)}
        if isinstance(value, float):
            return value if np.isfinite(value) else {"@float": repr(value)}
        if isinstance(value, np.ndarray):
            return self.array(value)
        if isinstance(value, bytes):
            return {"@bytes": self.array(np.frombuffer(value, dtype=np.uint8))}
        if isinstance(value, list):
            return [self(item) for item in value]
        if isinstance(value, tuple) and not hasattr(value, "_fields"):
            return {"@tuple": [self(item) for item in value]}
        if isinstance(value, (set, frozenset)):
            return {"@set": [self(item) for item in sorted(value, key=repr)],
                    "frozen": isinstance(value, frozenset)}
        if isinstance(value, dict):
            if all(isinstance(key, str) and not key.startswith("@") for key in value):
                return {key: self(item) for key, item in value.items()}
            return {"@dict": [[self(key), self(item)] for key, item in value.items()]}
        if isinstance(value, pathlib.PurePath):
            return {"@path": str(value)}
        try:
            from scipy import sparse
        except ImportError:  # pragma: no cover - scipy is a dependency
            sparse = None
        if sparse is not None and sparse.issparse(value):
            matrix = value.tocsr()
            return {"@csr": [self.array(matrix.data), self.array(matrix.indices),
                             self.array(matrix.indptr)], "shape": list(matrix.shape),
                    "format": value.format}
        return self.instance(value)

    def instance(self, value) -> dict:
        kind = type(value)
        name = f"{kind.__module__}.{kind.__qualname__}"
        if not kind.__module__.startswith(_PACKAGE) or "<locals>" in kind.__qualname__:
            raise EntryError(f"a {name} cannot be stored (only the package's own classes)")
        if dataclasses.is_dataclass(value):
            state = {field.name: getattr(value, field.name)
                     for field in dataclasses.fields(value)}
            extra = {k: v for k, v in getattr(value, "__dict__", {}).items() if k not in state}
            state.update(extra)
        elif hasattr(value, "__dict__"):
            state = dict(vars(value))
        else:
            raise EntryError(f"a {name} has no attributes to store")
        if any(callable(item) and not isinstance(item, type) for item in state.values()):
            raise EntryError(f"a {name} holds a function: it cannot be stored")
        return {"@object": name, "state": {key: self(item) for key, item in state.items()}}


class _Decoder:
    def __init__(self, arrays):
        self.arrays = arrays

    def array(self, index) -> np.ndarray:
        if not isinstance(index, int) or not 0 <= index < len(self.arrays):
            raise EntryError("an entry names an array it does not hold")
        return self.arrays[index]

    def __call__(self, value):  # noqa: C901 - one case a tag
        if isinstance(value, list):
            return [self(item) for item in value]
        if not isinstance(value, dict):
            return value
        if "@array" in value:
            return self.array(value["@array"])
        if "@scalar" in value:
            return self.array(value["@scalar"]["@array"])[()]
        if "@int" in value:
            return int(value["@int"])
        if "@float" in value:
            return float(value["@float"])
        if "@bytes" in value:
            return self.array(value["@bytes"]["@array"]).tobytes()
        if "@tuple" in value:
            return tuple(self(item) for item in value["@tuple"])
        if "@set" in value:
            items = [self(item) for item in value["@set"]]
            return frozenset(items) if value.get("frozen") else set(items)
        if "@dict" in value:
            return {self(key): self(item) for key, item in value["@dict"]}
        if "@path" in value:
            return pathlib.Path(value["@path"])
        if "@csr" in value:
            from scipy import sparse

            data, indices, indptr = (self(part) for part in value["@csr"])
            matrix = sparse.csr_matrix((data, indices, indptr), shape=tuple(value["shape"]))
            return matrix.asformat(value.get("format", "csr"))
        if "@object" in value:
            return self.instance(value["@object"], value.get("state", {}))
        return {key: self(item) for key, item in value.items()}

    def instance(self, name: str, state: dict):
        module_name, _, class_name = str(name).rpartition(".")
        if not module_name.startswith(_PACKAGE):
            raise EntryError(f"an entry names {name}, not one of the package's classes")
        try:
            kind = getattr(importlib.import_module(module_name), class_name)
        except (ImportError, AttributeError) as error:
            raise EntryError(f"an entry names {name}, which does not exist") from error
        if not isinstance(kind, type):
            raise EntryError(f"an entry names {name}, which is not a class")
        value = object.__new__(kind)  # no __init__, no __setstate__: nothing of the entry runs
        for key, item in state.items():
            object.__setattr__(value, key, self(item))
        return value


def _digest(key: str, arrays) -> str:
    digest = hashlib.sha256(key.encode("utf-8"))
    for array in arrays:
        digest.update(str((array.dtype.str, array.shape)).encode("ascii"))
        if array.size:
            flat = array if array.flags.c_contiguous else array.copy(order="C")
            digest.update(memoryview(flat.reshape(-1)).cast("B"))
    return digest.hexdigest()


def write_entry(handle, key: str, value: Any, progress=None) -> int:
    """Write ``value`` as an entry of ``key`` into the binary file ``handle``.

    Returns the bytes of its arrays; ``progress(nbytes)``, where given, is called after
    each array is written. Raises :class:`EntryError` for a value that cannot be stored
    (nothing is written then).
    """
    encoder = _Encoder()
    description = encoder(value)
    meta = json.dumps({"format": ENTRY_FORMAT, "key": key, "value": description,
                       "arrays": len(encoder.arrays),
                       "sha256": _digest(key, encoder.arrays)}, allow_nan=False)
    members = {f"a{index}": array for index, array in enumerate(encoder.arrays)}
    members[_META] = np.frombuffer(meta.encode("utf-8"), dtype=np.uint8)
    # what np.savez writes (an uncompressed zip of .npy members), one member at a time
    with zipfile.ZipFile(handle, mode="w", compression=zipfile.ZIP_STORED,
                         allowZip64=True) as archive:
        for name, array in members.items():
            with archive.open(f"{name}.npy", mode="w", force_zip64=True) as member:
                np.lib.format.write_array(member, array, allow_pickle=False)
            if progress is not None:
                progress(array.nbytes)
    return int(sum(array.nbytes for array in encoder.arrays))


def read_entry(handle, key: str, progress=None):
    """Return the value of the entry of ``key`` in ``handle``.

    ``progress(nbytes)``, where given, is called after each array is read.

    Raises
    ------
    EntryError
        An entry of another layout or key, whose arrays do not match their checksum, that
        holds pickled data or names a class outside the package.
    """
    try:
        with np.load(handle, allow_pickle=False) as archive:
            meta = json.loads(bytes(archive[_META]).decode("utf-8"))
            if meta.get("format") != ENTRY_FORMAT:
                raise EntryError(f"an entry of layout {meta.get('format')!r}")
            if meta.get("key") != key:
                raise EntryError("an entry of another key")
            arrays = []
            for index in range(int(meta["arrays"])):
                arrays.append(archive[f"a{index}"])
                if progress is not None:
                    progress(arrays[-1].nbytes)
    except EntryError:
        raise
    except Exception as error:  # not an npz, pickled members, a truncated file, bad JSON
        raise EntryError(f"not a readable entry ({type(error).__name__}: {error})") from error
    if _digest(key, arrays) != meta.get("sha256"):
        raise EntryError("its arrays do not match their checksum")
    return _Decoder(arrays)(meta["value"])
