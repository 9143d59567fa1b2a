"""Knobs declared once: validation, cache keys, command-line flags and ladders from one spec.

A method lists its knobs as :class:`Knob` entries of a :class:`KnobSpec`; everything that
used to be written beside them per method is derived:

- ``spec.defaults``: the ``DEFAULT_KNOBS`` of the method contract;
- ``spec.resolve(knobs)``: the defaults filled in, each value checked (an
  :class:`~translucent.errors.InputError` names the knob and the value) and converted,
  then the spec's cross-knob checks;
- ``spec.keyed(resolved)``: the knobs that enter the precomputation's cache key (those
  read only when rendering, or that change how and not what is computed, do not);
- ``spec.add_arguments(parser)`` and ``spec.from_arguments(args)``: the ``translucent
  approx`` flags, with the help text and the default;
- ``spec.ladders``: the quality ladders ``bench tradeoff`` and the report sweep.

Examples
--------
>>> spec = KnobSpec([Knob("samples", 64, "samples per pixel", kind="int", low=1,
...                       ladder=(4, 16)),
...                  Knob("workers", 2, "threads", kind="int", low=1, keyed=False)])
>>> spec.defaults
{'samples': 64, 'workers': 2}
>>> spec.resolve({"samples": 16.0})
{'samples': 16, 'workers': 2}
>>> spec.keyed(spec.resolve({}))
{'samples': 64}
>>> spec.ladders
{'samples': [{'samples': 4}, {'samples': 16}, {}]}
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError

__all__ = ["KINDS", "Knob", "KnobSpec"]

#: What a knob's value is.
KINDS = ("int", "float", "bool", "choice", "any")


@dataclass(frozen=True)
class Knob:
    """One knob of a method.

    Parameters
    ----------
    name : str
        The keyword of ``precompute`` (``"rays_per_patch"``).
    default : object
        Its value when not given (None where ``optional``: derived from the scene).
    help : str
        One line for ``--help`` and docs, with units.
    kind : {"int", "float", "bool", "choice", "any"}
    low, high : float, optional
        Inclusive bounds of an int or float knob.
    positive : bool
        A float knob must be > 0 (``low`` is then an exclusive 0).
    unit : str
        Of a number knob (``"mm"``), for messages and help.
    choices : tuple, optional
        The values of a "choice" knob.
    optional : bool
        None is accepted too (and kept).
    keyed : bool
        Part of the precomputation's cache key: False for knobs read only when rendering
        or that change how, not what, is computed (threads, progress bars).
    ladder : tuple
        Values from cheap towards the default, for a one-knob quality ladder of
        ``bench tradeoff`` (the default itself closes it).
    check : callable, optional
        ``check(value) -> value`` after the kind's own check (a power of two, ...);
        raises :class:`~translucent.errors.InputError`.
    flags : tuple of str
        Other spellings of the command-line flag (``("--rays",)``); the first flag is
        always ``--`` and the name with dashes.
    """

    name: str
    default: Any
    help: str
    kind: str = "any"
    low: float | None = None
    high: float | None = None
    positive: bool = False
    unit: str = ""
    choices: tuple = ()
    optional: bool = False
    keyed: bool = True
    ladder: tuple = ()
    check: Callable | None = None
    flags: tuple = ()

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"knob {self.name}: kind must be one of {KINDS}, not {self.kind}")
        if self.kind == "choice" and not self.choices:
            raise ValueError(f"knob {self.name}: a choice knob needs its choices")

    # -- checking ----------------------------------------------------------------------

    def validate(self, value):
        """Return ``value`` checked and converted to the knob's kind.

        Raises
        ------
        InputError
            Naming the knob and the value, and what it must be.
        """
        if value is None and self.optional:
            return None
        kind = self.kind
        if kind == "int":
            value = self._integer(value)
        elif kind == "float":
            value = self._real(value)
        elif kind == "bool":
            if not isinstance(value, (bool, np.bool_)):
                raise InputError("must be true or false", field=self.name, value=value)
            value = bool(value)
        elif kind == "choice" and value not in self.choices:
            raise InputError(f"must be one of {', '.join(map(repr, self.choices))}",
                             field=self.name, value=value)
        return self.check(value) if self.check is not None else value

    def _bounds_text(self) -> str:
        """``>= 1``, ``<= 255`` or ``in [1, 255]``, with the unit."""
        def shown(bound) -> str:
            return str(int(bound)) if self.kind == "int" else f"{bound:g}"

        unit = f" {self.unit}" if self.unit else ""
        if self.low is not None and self.high is not None:
            return f"in [{shown(self.low)}, {shown(self.high)}]{unit}"
        if self.low is not None:
            return f">= {shown(self.low)}{unit}"
        return f"<= {shown(self.high)}{unit}" if self.high is not None else ""

    def _outside(self, number) -> bool:
        return (self.low is not None and number < self.low) or \
            (self.high is not None and number > self.high)

    def _integer(self, value) -> int:
        number = value if isinstance(value, (int, float, np.integer, np.floating)) \
            and not isinstance(value, (bool, np.bool_)) else math.nan
        if not math.isfinite(number) or int(number) != number or self._outside(number):
            either = "None or " if self.optional else ""
            raise InputError(f"must be {either}an integer {self._bounds_text()}".rstrip(),
                             field=self.name, value=value)
        return int(number)

    def _real(self, value) -> float:
        number = float(value) if isinstance(value, (int, float, np.integer, np.floating)) \
            and not isinstance(value, (bool, np.bool_)) else math.nan
        unit = f" {self.unit}" if self.unit else ""
        if not math.isfinite(number):
            raise InputError(f"must be a finite number{' > 0' if self.positive else ''}{unit}"
                             + (" (or None)" if self.optional else ""),
                             field=self.name, value=value)
        if self.positive and not number > 0:
            raise InputError(f"must be > 0{unit}", field=self.name, value=value)
        if self._outside(number):
            raise InputError(f"must be {self._bounds_text()}", field=self.name, value=value)
        return number

    # -- the command line --------------------------------------------------------------

    @property
    def flag(self) -> str:
        """The command-line flag: ``--`` and the name with dashes."""
        return "--" + self.name.replace("_", "-")

    def add_argument(self, parser) -> None:
        """Add the knob's flag to ``parser``; an absent flag leaves the method's default."""
        shown = self.help if self.default is None else f"{self.help} (default: {self.default})"
        shown = shown.replace("%", "%%")  # argparse formats help texts with %
        if self.kind == "bool":
            parser.add_argument(self.flag, *self.flags, dest=self.name, default=None,
                                action=argparse.BooleanOptionalAction, help=shown)
            return
        types = {"int": int, "float": float}
        options = {"dest": self.name, "default": None, "help": shown}
        if self.kind in types:
            options["type"] = types[self.kind]
            options["metavar"] = self.kind.upper()
        elif self.kind == "choice":
            options["choices"] = self.choices
        parser.add_argument(self.flag, *self.flags, **options)


class KnobSpec:
    """The knobs of one method, in order, and the checks that involve several of them.

    Parameters
    ----------
    knobs : iterable of Knob
    checks : iterable of callable, optional
        ``check(resolved)`` after every knob's own check; may change ``resolved`` in
        place; raises :class:`~translucent.errors.InputError`.
    ladders : dict, optional
        Named ladders over several knobs (``{name: [knob dicts from cheap to {}]}``),
        before the one-knob ladders the knobs declare.
    """

    def __init__(self, knobs: Iterable[Knob], *, checks: Iterable[Callable] = (),
                 ladders: dict | None = None):
        self.knobs: dict[str, Knob] = {}
        for knob in knobs:
            if knob.name in self.knobs:
                raise ValueError(f"knob {knob.name} is declared twice")
            self.knobs[knob.name] = knob
        self.checks = tuple(checks)
        self._ladders = dict(ladders or {})
        for name, points in self._ladders.items():
            for point in points:
                unknown = set(point) - set(self.knobs)
                if unknown:
                    raise ValueError(f"ladder {name!r} names unknown knobs {sorted(unknown)}")

    def __iter__(self):
        return iter(self.knobs.values())

    def __contains__(self, name) -> bool:
        return name in self.knobs

    def __getitem__(self, name) -> Knob:
        return self.knobs[name]

    @property
    def defaults(self) -> dict:
        """Every knob's default, in declaration order (``DEFAULT_KNOBS``)."""
        return {name: knob.default for name, knob in self.knobs.items()}

    @property
    def unkeyed(self) -> tuple[str, ...]:
        """The knobs left out of the precomputation's cache key."""
        return tuple(name for name, knob in self.knobs.items() if not knob.keyed)

    def resolve(self, knobs: dict | None = None) -> dict:
        """Return the defaults updated with ``knobs``, every value checked and converted.

        Raises
        ------
        InputError
            An unknown knob (the valid ones listed), or a value its knob refuses.
        """
        knobs = dict(knobs or {})
        unknown = sorted(set(knobs) - set(self.knobs))
        if unknown:
            raise InputError(f"unknown knob; valid: {', '.join(self.knobs)}", field="knobs",
                             value=unknown)
        resolved = self.defaults | knobs
        for name, knob in self.knobs.items():
            resolved[name] = knob.validate(resolved[name])
        for check in self.checks:
            check(resolved)
        return resolved

    def keyed(self, resolved: dict) -> dict:
        """Return the knobs of ``resolved`` that enter the precomputation's cache key."""
        return {name: value for name, value in resolved.items()
                if name not in self.knobs or self.knobs[name].keyed}

    @property
    def ladders(self) -> dict[str, list[dict]]:
        """Named ladders, then one per knob that declares values; each ends at ``{}``."""
        ladders = {name: [dict(point) for point in points]
                   for name, points in self._ladders.items()}
        for name, knob in self.knobs.items():
            if knob.ladder:
                ladders[name] = [{name: value} for value in knob.ladder] + [{}]
        return ladders

    # -- the command line --------------------------------------------------------------

    def add_arguments(self, parser, names: Iterable[str] | None = None) -> None:
        """Give ``parser`` a flag per knob (``names``: only those), in a group of its own."""
        group = parser.add_argument_group("knobs (absent: the method's default)")
        for name in (self.knobs if names is None else names):
            self.knobs[name].add_argument(group)

    def from_arguments(self, args, names: Iterable[str] | None = None) -> dict:
        """Return the knobs given on the command line (flags left out are not in it)."""
        chosen = self.knobs if names is None else names
        return {name: getattr(args, name) for name in chosen
                if getattr(args, name, None) is not None}
