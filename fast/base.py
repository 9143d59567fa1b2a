"""What every fast method offers, so that the command line and the report treat them alike.

A fast method is a module (of :mod:`translucent.fast`, or of any distribution that
registers it: :mod:`translucent.fast.registry`) with these module-level names:

``applies_to(scene) -> Refusal | str | None``
    None when the method can render the scene; otherwise why it cannot, best as a
    :class:`Refusal` (a reason code and a sentence; shown in the report as "not
    applicable: ...").
``precompute(scene, **knobs) -> PrecomputedState``
    The slow step: cached on disk by a hash of what it depends on (geometry, knobs), never
    by lights or materials when those are edited interactively.
``DEFAULT_KNOBS: dict``
    The knobs and their defaults (quality settings the benchmarks sweep). An unknown
    knob given to ``precompute`` is an :class:`~translucent.errors.InputError`
    (:func:`with_defaults`).

and a state whose ``render(lights=None, material=None) -> Image`` is the interactive
path: relighting (new lights) and editing (new material) without precomputing again.

A method that renders only some of a scene's objects (the translucent ones, others left
black) also has

``scored_objects(scene) -> list[str]``
    The names of the objects it renders: the report scores it on their pixels only
    (:func:`scored_object_names`), and says so.

and may have ``QUICK_KNOBS`` (cheap knobs for smoke runs and the conformance checks of
:mod:`translucent.fast.conformance`) and ``approx(scene, args)`` with
``add_approx_arguments(parser)`` (its own ``translucent approx`` options; without them
the command takes ``--knob NAME=VALUE``).
"""

from __future__ import annotations

import contextlib
import time
import weakref
from dataclasses import dataclass, field
from typing import Any, Protocol

from ..errors import InputError
from ..image import Image
from .registry import METHODS, method

__all__ = ["METHODS", "PrecomputedState", "Refusal", "applicability", "method", "refusal_of",
           "refuse_inapplicable", "StageLog", "NO_LIGHT", "NO_TRANSLUCENT_OBJECT",
           "NOTHING_TO_EDIT", "UNSUPPORTED_LIGHT", "UNSUPPORTED_MATERIAL", "StageProgress",
           "scored_object_names", "with_defaults"]

@dataclass(frozen=True)
class Refusal:
    """Why a method does not apply to a scene: a reason code for programs, a sentence for people.

    Parameters
    ----------
    code : str
        A short stable identifier (``"no_translucent_object"``) that callers branch on.
    sentence : str
        What is shown to the user.

    Examples
    --------
    >>> reason = Refusal("no_translucent_object", "no translucent object in the scene")
    >>> str(reason), reason.code
    ('no translucent object in the scene', 'no_translucent_object')
    """

    code: str
    sentence: str

    def __str__(self) -> str:
        return self.sentence


#: Reason codes of :class:`Refusal` that the built-in methods share (a method may add its own).
NO_LIGHT = "no_light"
NO_TRANSLUCENT_OBJECT = "no_translucent_object"
UNSUPPORTED_LIGHT = "unsupported_light"
UNSUPPORTED_MATERIAL = "unsupported_material"
NOTHING_TO_EDIT = "nothing_to_edit"


def refusal_of(reason) -> Refusal | None:
    """Return what ``applies_to`` gave as a :class:`Refusal` (a plain sentence: code "other")."""
    if reason is None or isinstance(reason, Refusal):
        return reason
    return Refusal("other", str(reason))


#: scene -> {applies_to function: its Refusal or None}; a scene is frozen, so its answer
#: holds for as long as the scene object lives
_APPLICABILITY: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_UNKNOWN = object()


def applicability(applies_to, scene, known=_UNKNOWN) -> Refusal | None:
    """Return ``applies_to(scene)`` as a :class:`Refusal` or None, evaluated once per scene.

    The command line, the report and a method's own ``precompute`` all ask; the first
    answer for a scene object is kept (scenes are immutable) and given to the others.

    Parameters
    ----------
    applies_to : callable
        A method's ``applies_to``.
    scene : Scene
    known : Refusal or None, optional
        An answer already obtained for this scene elsewhere (the report plans in one
        process and runs in another): kept instead of asking again.

    Examples
    --------
    >>> calls = []
    >>> def applies_to(scene):
    ...     calls.append(scene)
    ...     return None
    >>> from translucent.scenes import load_scene
    >>> scene = load_scene("sphere")
    >>> applicability(applies_to, scene), applicability(applies_to, scene), len(calls)
    (None, None, 1)
    """
    try:
        answers = _APPLICABILITY.setdefault(scene, {})
    except TypeError:  # an object that cannot be weakly referenced: ask every time
        return refusal_of(applies_to(scene) if known is _UNKNOWN else known)
    if known is not _UNKNOWN:
        answers[applies_to] = refusal_of(known)
    elif applies_to not in answers:
        answers[applies_to] = refusal_of(applies_to(scene))
    return answers[applies_to]


class PrecomputedState(Protocol):
    """The result of ``precompute``: renders interactively."""

    def render(self, lights=None, material=None) -> Image:
        """Render with new lights and/or material (None keeps the scene's)."""


@dataclass
class StageLog:
    """What a run did, skipped and how long each stage took, for the report.

    ``skipped`` holds sentences ("no form factors: a single convex object sees nothing
    else"); ``seconds`` maps a stage name to wall-clock seconds.
    """

    skipped: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    notes: dict[str, Any] = field(default_factory=dict)

    def skip(self, sentence: str) -> None:
        """Record that a step was skipped and why."""
        self.skipped.append(sentence)


class StageProgress:
    """Time a precomputation's stages into a :class:`StageLog`, one progress-bar step each.

    The bar (:func:`translucent.progress.progress_bar`) names the stage under way; it
    stays hidden where standard error is not a terminal, and inside
    :func:`translucent.progress.hidden` (the command line's ``--no-progress``).

    Parameters
    ----------
    log : StageLog
        Where each stage's wall-clock seconds go (``log.seconds[name]``).
    description : str
        The bar's label (``"radiosity precomputation"``).
    stages : int
        How many stages the bar counts.
    enabled : bool
        False hides the bar (the seconds are still recorded).

    Examples
    --------
    >>> log = StageLog()
    >>> with StageProgress(log, "example", stages=1, enabled=False) as progress:
    ...     with progress.stage("patches"):
    ...         pass
    >>> list(log.seconds)
    ['patches']
    """

    def __init__(self, log: StageLog, description: str, stages: int, enabled: bool = True):
        from ..progress import progress_bar

        self.log = log
        self._bar = progress_bar(total=stages, description=description, unit="stage",
                                 enabled=enabled)

    @contextlib.contextmanager
    def stage(self, name: str):
        """Time the block as stage ``name`` and advance the bar when it ends."""
        self._bar.set_postfix_str(name, refresh=True)
        started = time.perf_counter()
        yield
        self.log.seconds[name] = time.perf_counter() - started
        self._bar.update(1)

    def __enter__(self) -> StageProgress:
        return self

    def __exit__(self, *exc) -> None:
        self._bar.close()


#: The note a precomputation leaves in ``StageLog.notes["cache"]``: made now, or read back.
CACHE_MISS = "miss"
CACHE_HIT = "hit"


def load_or_precompute(namespace: str, key: str, make, *, what: str, log_of, valid=None,
                       nbytes=None, part: str | None = None):
    """Return a precomputation from the method's cache, or ``make()`` it and store it.

    The one load-or-make step of every method: under the entry's lock (of several processes
    asking at once one computes, the others read), with one wording of the cache note
    (:data:`CACHE_HIT` or :data:`CACHE_MISS` in ``log.notes["cache"]``, per ``part`` where
    a method stores several entries), and the sentence saying when an entry was too large
    to keep (``TRANSLUCENT_CACHE_ENTRY_LIMIT``).

    Parameters
    ----------
    namespace : str
        The method's cache folder (``"prt"``).
    key : str
        The content hash of everything the precomputation depends on.
    make : callable
        ``make() -> value``, called on a miss.
    what : str
        Named while another process waits for the entry ("the PRT transfer of 'bunny'").
    log_of : callable
        ``log_of(value) -> StageLog`` where the note goes.
    valid : callable, optional
        ``valid(value) -> bool``: a stored value it refuses (another layout) is a miss.
    nbytes : callable, optional
        ``nbytes(value) -> int`` for the cache's entry limit.
    part : str, optional
        The note goes to ``notes["cache"][part]`` (one entry per object).

    Returns
    -------
    value, made : object, bool
    """
    from ..cache import ENTRY_LIMIT_VARIABLE, Cache, entry_limit

    value, made = Cache(namespace).load_or_make(key, make, valid=valid, what=what,
                                                nbytes=nbytes)
    log = log_of(value)
    note = CACHE_MISS if made else CACHE_HIT
    if part is None:
        log.notes["cache"] = note
    else:
        log.notes.setdefault("cache", {})[part] = note
    limit = entry_limit()
    if made and nbytes is not None and limit is not None and nbytes(value) > limit:
        log.skip(f"the precomputation ({nbytes(value) / 2**20:.0f} MiB) is not kept in the "
                 f"cache: over its entry limit of {limit / 2**20:.4g} MiB "
                 f"({ENTRY_LIMIT_VARIABLE}); the next run computes it again")
    return value, made


def scored_object_names(module, scene) -> list[str]:
    """Return the objects a method is scored on: its ``scored_objects``, else all of them."""
    chosen = getattr(module, "scored_objects", None)
    return list(chosen(scene)) if chosen is not None else [o.name for o in scene.objects]


def with_defaults(knobs: dict, defaults: dict) -> dict:
    """Return ``defaults`` updated with ``knobs``; an unknown knob lists the valid ones.

    Raises
    ------
    InputError
        When ``knobs`` names a knob that ``defaults`` does not have.
    """
    unknown = sorted(set(knobs) - set(defaults))
    if unknown:
        raise InputError(f"unknown knob; valid: {', '.join(defaults)}", field="knobs",
                         value=unknown)
    return {**defaults, **knobs}


def refuse_inapplicable(scene, reason: Refusal | str | None, sentence: str) -> None:
    """Refuse a scene for which a method's ``applies_to`` gave a reason; None returns.

    Parameters
    ----------
    scene : Scene
    reason : Refusal, str or None
        What the method's ``applies_to(scene)`` returned (best through
        :func:`applicability`, which asks once per scene).
    sentence : str
        The start of the message, naming the method ("the prt method cannot render this
        scene"); the reason follows it after a colon.

    Raises
    ------
    InputError
        When ``reason`` is not None, naming the scene's file and name.
    """
    if reason is not None:
        raise InputError(f"{sentence}: {reason}", file=scene.source, field="scene",
                         value=scene.name)
