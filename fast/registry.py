"""The fast methods the suite knows: the ``translucent.methods`` entry points, and more.

A fast method is found by name. The four built-in ones are registered in the suite's own
``pyproject.toml`` under the entry-point group ``translucent.methods``, the same group
another distribution uses to add its own::

    [project.entry-points."translucent.methods"]
    lambert = "my_package.lambert_method"

Code that is not installed joins with :func:`register_method`. Either way the method then
runs in ``translucent approx``, ``translucent report --methods``, ``translucent bench
tradeoff`` and the conformance checks of :mod:`translucent.fast.conformance`, with no edit
to the suite.

The contract a method's module (or object) follows is written once, in
:mod:`translucent.fast.contract` (and docs/methods.md, derived from it), and checked here
by :func:`contract_problems`.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.metadata
import re
import threading
from collections.abc import Iterator, MutableMapping
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..plugins import EntryPointTarget, discovered
from .contract import CONTRACT, OPTIONAL, REQUIRED

__all__ = ["ENTRY_POINT_GROUP", "EntryPointTarget", "METHODS", "MethodContractError",
           "MethodRegistry", "check_known", "contract_problems", "method", "method_fingerprint",
           "register_method", "unregister_method"]

#: The entry-point group fast methods are registered under.
ENTRY_POINT_GROUP = "translucent.methods"

#: What a method name may be: it names command-line sub-commands, files and cache keys.
NAME_PATTERN = re.compile(r"^[a-z][a-z0-9_]{0,39}$")

#: The four methods of the suite itself, by the module that holds each. Used only where
#: the suite's own distribution metadata cannot be read (a source tree run without being
#: installed); an installed suite finds them through its entry points.
BUILTIN_METHODS = {
    "prt": "translucent.fast.prt",
    "radiosity": "translucent.fast.radiosity",
    "splatting": "translucent.fast.splatting",
    "brdf_pca": "translucent.fast.brdf_pca",
}

#: Where the contract is written (parts by name): required and optional attributes.
_PARTS = {part.name: part for part in CONTRACT if part.kind != "state"}


class MethodContractError(InputError):
    """A registered method that does not follow the contract (it is not merely unbuilt)."""


def contract_problems(target) -> list[str]:
    """Return what ``target`` (a method's module or object) lacks of the contract; [] if none.

    Examples
    --------
    >>> import types
    >>> contract_problems(types.SimpleNamespace(DEFAULT_KNOBS={}, applies_to=print))
    ['precompute: missing (a function precompute(scene, **knobs) returning a state)']
    """
    from ..materials.profiles import HETEROGENEOUS_RULES

    problems = []
    for name, what in REQUIRED.items():
        if not hasattr(target, name):
            problems.append(f"{name}: missing ({what})")
    for name, part in _PARTS.items():
        if not hasattr(target, name):
            continue
        value = getattr(target, name)
        if part.kind == "function" and not callable(value):
            problems.append(f"{name}: not callable ({part.summary})")
        elif part.kind == "dict" and (not isinstance(value, dict)
                                      or not all(isinstance(k, str) for k in value)):
            problems.append(f"{name}: not a dict with str keys ({part.summary})")
        elif part.kind == "rule" and value not in HETEROGENEOUS_RULES:
            problems.append(f"{name}: {value!r} is not one of {', '.join(HETEROGENEOUS_RULES)} "
                            f"({part.summary})")
    quick = getattr(target, "QUICK_KNOBS", {})
    defaults = getattr(target, "DEFAULT_KNOBS", {})
    if hasattr(target, "KNOBS"):
        from .knobs import KnobSpec

        spec = target.KNOBS
        if not isinstance(spec, KnobSpec):
            problems.append(f"KNOBS: not a KnobSpec ({OPTIONAL['KNOBS']})")
        elif isinstance(defaults, dict) and spec.defaults != defaults:
            problems.append("KNOBS: its defaults differ from DEFAULT_KNOBS (derive one from "
                            "the other: DEFAULT_KNOBS = KNOBS.defaults)")
    if isinstance(quick, dict) and isinstance(defaults, dict):
        unknown = sorted(set(quick) - set(defaults))
        if unknown:
            problems.append(f"QUICK_KNOBS: knobs not in DEFAULT_KNOBS: {', '.join(unknown)}")
    return problems


def check_known(name, field: str = "method") -> str:
    """Return ``name`` if a fast method of that name is registered; otherwise refuse it.

    The one place an unknown method name is refused, with the valid ones listed.

    Raises
    ------
    InputError
        ``name`` is not registered.
    """
    if name not in METHODS:
        raise InputError(f"unknown fast method; valid: {', '.join(METHODS)}", field=field,
                         value=name)
    return name


def _check_name(name) -> str:
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise InputError("a method name is lower-case letters, digits and '_', starting "
                         "with a letter, at most 40 characters", field="method", value=name)
    return name


def _discovered() -> tuple[dict[str, Any], dict[str, list[str]]]:
    """Return the entry points of the group by name, and the names claimed twice."""
    return discovered(ENTRY_POINT_GROUP, BUILTIN_METHODS)


class MethodRegistry(MutableMapping):
    """Method name -> where its code is: an entry point, a module name, or the module itself.

    Read lazily from the ``translucent.methods`` entry points at first use; assignment
    (``registry[name] = "my.module"``) and :func:`register_method` add to it for this
    process only. Iteration order: the built-in methods first, then the others by name.
    """

    def __init__(self, group: str = ENTRY_POINT_GROUP):
        self.group = group
        self._entries: dict[str, Any] | None = None
        self._conflicts: dict[str, list[str]] = {}
        self._lock = threading.Lock()

    def _table(self) -> dict[str, Any]:
        with self._lock:
            if self._entries is None:
                found, self._conflicts = _discovered()
                builtin = [n for n in BUILTIN_METHODS if n in found]
                self._entries = {n: found[n] for n in builtin + sorted(set(found) - set(builtin))}
            return self._entries

    def __getitem__(self, name):
        return self._table()[name]

    def __setitem__(self, name, target):
        self._table()[_check_name(name)] = target

    def __delitem__(self, name):
        del self._table()[name]

    def __iter__(self) -> Iterator[str]:
        return iter(list(self._table()))

    def __len__(self) -> int:
        return len(self._table())

    def conflict(self, name: str) -> list[str] | None:
        """Return the distributions that claim ``name`` with different code, or None."""
        self._table()
        return self._conflicts.get(name)

    def reload(self) -> None:
        """Read the entry points again (after installing a distribution in this process)."""
        with self._lock:
            self._entries = None


#: The registry every command reads.
METHODS = MethodRegistry()


def register_method(name: str, target) -> None:
    """Make a fast method known by ``name`` in this process.

    Parameters
    ----------
    name : str
        Lower-case letters, digits and ``_``; replaces a method of that name.
    target : module, object or str
        The method's module (or any object with the contract's attributes), or the name
        of a module to import when the method is first used.

    Raises
    ------
    InputError
        A bad name, or a module or object that does not follow the contract (each
        missing part named).

    Examples
    --------
    >>> import types
    >>> from translucent.fast import registry
    >>> flat = types.SimpleNamespace(DEFAULT_KNOBS={}, applies_to=lambda scene: None,
    ...                              precompute=lambda scene, **knobs: None)
    >>> registry.register_method("flat_example", flat)
    >>> registry.method("flat_example") is flat
    True
    >>> registry.unregister_method("flat_example")
    """
    _check_name(name)
    if not isinstance(target, str):
        problems = contract_problems(target)
        if problems:
            raise MethodContractError("does not follow the fast-method contract: "
                                      + "; ".join(problems), field="method", value=name)
    elif not target or not all(part.isidentifier() for part in target.split(".")):
        raise InputError("must be a module's dotted name", field="module", value=target)
    METHODS[name] = target


def unregister_method(name: str) -> None:
    """Forget a method registered in this process (an unknown name is an error)."""
    del METHODS[check_known(name)]


def _load(name: str, target):
    if isinstance(target, str):
        try:
            return importlib.import_module(target)
        except ModuleNotFoundError as error:
            if error.name is not None and (target == error.name
                                           or target.startswith(error.name + ".")):
                raise InputError(f"this fast method is not installed (no module {target})",
                                 field="method", value=name) from error
            raise
    if isinstance(target, EntryPointTarget):
        module_name = target.value.split(":", 1)[0].strip()
        try:
            return target.load()
        except ModuleNotFoundError as error:
            if error.name is not None and (module_name == error.name
                                           or module_name.startswith(error.name + ".")):
                raise InputError(f"this fast method is not installed (entry point "
                                 f"{target.value} of group {ENTRY_POINT_GROUP})",
                                 field="method", value=name) from error
            raise
        except AttributeError as error:
            raise MethodContractError(f"its entry point {target.value} names nothing: "
                                      f"{error}", field="method", value=name) from error
    return target


def method(name: str):
    """Return the module (or object) of the fast method ``name``, checked against the contract.

    Raises
    ------
    InputError
        An unknown name (the valid ones listed), a method whose module is not installed
        ("not installed"), a name two installed distributions claim.
    MethodContractError
        A method that does not follow the contract (each missing part named).
    """
    check_known(name)
    conflict = METHODS.conflict(name)
    if conflict and isinstance(METHODS[name], EntryPointTarget):
        raise InputError("two installed distributions register this fast method: "
                         + ", ".join(conflict) + "; uninstall one", field="method", value=name)
    target = _load(name, METHODS[name])
    problems = contract_problems(target)
    if problems:
        raise MethodContractError("does not follow the fast-method contract: "
                                  + "; ".join(problems), field="method", value=name)
    return target


def method_fingerprint(name: str) -> str:
    """SHA-256 of a method's own source outside the suite ("" for the suite's own methods).

    The report keys its cache of runs by the suite's sources; a method from another
    distribution adds its own files (the folder of its package, or its one module), so that
    editing it makes the next report run it again.
    """
    target = _load(name, METHODS[name])
    file = getattr(target, "__file__", None)
    if file is None:
        module = getattr(target, "__module__", None)
        file = getattr(importlib.import_module(module), "__file__", None) if module else None
    if file is None:
        return ""
    path = Path(file).resolve()
    suite = Path(__file__).resolve().parents[1]
    if suite in path.parents:
        return ""
    files = sorted(path.parent.rglob("*.py")) if path.name == "__init__.py" else [path]
    digest = hashlib.sha256()
    for source in files:
        digest.update(source.name.encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()
