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

__all__ = ["DEFAULT_PROFILE", "KINDS", "Knob", "KnobSpec", "RADIAL_AVERAGE",
           "UNSUPPORTED_PROFILE", "directional_profile_names", "profile_knob", "radial_profile",
           "radial_profile_names"]

#: What a knob's value is.
KINDS = ("int", "float", "bool", "choice", "any")


#: The largest value an integer knob without a ``high`` of its own takes: counts are held
#: in 32-bit integers by the compiled kernels.
MAX_COUNT = 2**31 - 1

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
    refused : tuple of (value, reason)
        Values of a "choice" knob that the method knows of but cannot take, each with why
        (a :class:`~translucent.fast.base.Refusal`): given one, :meth:`validate` raises an
        :class:`~translucent.errors.InputError` whose message is the reason's sentence,
        and the command line accepts it so that the sentence reaches the user.
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
    refused: tuple = ()
    flags: tuple = ()

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"knob {self.name}: kind must be one of {KINDS}, not {self.kind}")
        if self.kind == "choice" and not self.choices:
            raise ValueError(f"knob {self.name}: a choice knob needs its choices")
        if self.refused and (self.kind != "choice" or any(
                value in self.choices for value, _ in self.refused)):
            raise ValueError(f"knob {self.name}: refused values belong to a choice knob and "
                             "are not among its choices")

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
            for refused, reason in self.refused:
                if type(value) is type(refused) and value == refused:
                    raise InputError(str(reason), field=self.name, value=value)
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
        # a count no kernel can index (they hold counts in 32 bits) is refused, not run on
        if self.high is None and abs(int(number)) > MAX_COUNT:
            raise InputError(f"must be at most {MAX_COUNT} (an integer knob without a bound "
                             "of its own is a count)", field=self.name, value=value)
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
            # refused values pass argparse, so that validate() says why they are refused;
            # the usage line shows the values taken
            options["choices"] = self.choices + tuple(value for value, _ in self.refused)
            if self.refused:
                options["metavar"] = "{" + ",".join(map(str, self.choices)) + "}"
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


# -- the profile knob: a radial scattering profile by name -------------------------------

#: The profile a method uses unless told otherwise: the classical dipole (Jensen et al.
#: 2001), the choice of the three papers (Wang et al. 2008, Chen et al. 2012, Sheng et al.
#: 2014).
DEFAULT_PROFILE = "dipole"

#: The reason code of the :class:`~translucent.fast.base.Refusal` of a profile a method
#: cannot take.
UNSUPPORTED_PROFILE = "unsupported_profile"

#: A directional profile is taken as its azimuthal (radial) average only where the name
#: says so: the registry's name and this suffix (``"directional_dipole_average"``).
RADIAL_AVERAGE = "_average"


def radial_profile_names() -> tuple[str, ...]:
    """Return the names a ``profile`` knob can take, :data:`DEFAULT_PROFILE` first.

    Every radial profile of :data:`~translucent.materials.profiles.PROFILES`, then each
    directional one's radial average (its name and :data:`RADIAL_AVERAGE`).
    """
    from ..materials.profiles.registry import PROFILES

    radial = [name for name, entry in PROFILES.items() if not entry.directional]
    averages = [name + RADIAL_AVERAGE for name, entry in PROFILES.items() if entry.directional]
    return tuple(sorted(radial, key=lambda name: name != DEFAULT_PROFILE)) + tuple(averages)


def directional_profile_names() -> tuple[str, ...]:
    """Return the registry's directional profiles (no radial method takes them as they are)."""
    from ..materials.profiles.registry import PROFILES

    return tuple(name for name, entry in PROFILES.items() if entry.directional)


def radial_profile(name: str, medium, **options):
    """Return the radial profile ``name`` (a value of a ``profile`` knob) of ``medium``.

    Parameters
    ----------
    name : str
        One of :func:`radial_profile_names`.
    medium : Dipole or str
        The medium (RGB coefficients in mm^-1) or a measured medium's name.
    **options
        Passed to :func:`~translucent.materials.profiles.profile`.

    Returns
    -------
    RadialProfile
        Per unit power entering the medium (no entry Fresnel term), mm^-2.

    Raises
    ------
    InputError
        An unknown or directional name, or a medium the profile refuses.
    """
    from ..materials.profiles.base import require_radial
    from ..materials.profiles.registry import profile

    base = name.removesuffix(RADIAL_AVERAGE) if isinstance(name, str) else name
    if base != name and base in directional_profile_names():
        return profile(base, medium, radial=True, **options)
    return require_radial(profile(name, medium, **options), "profile")


def profile_knob(refused: dict, *, keyed: bool, help: str) -> Knob:
    """Return a method's ``profile`` knob: the radial profiles it takes, the others refused.

    Parameters
    ----------
    refused : dict
        Profile name -> its :class:`~translucent.fast.base.Refusal` (code
        :data:`UNSUPPORTED_PROFILE`), for each name of :func:`radial_profile_names` and
        :func:`directional_profile_names` the method cannot take.
    keyed : bool
        Whether the profile changes the precomputation (and so enters its cache key).
    help : str
        One line for ``--help``.
    """
    takes = tuple(name for name in radial_profile_names() if name not in refused)
    return Knob("profile", DEFAULT_PROFILE, help, kind="choice", choices=takes,
                refused=tuple(refused.items()), keyed=keyed)
