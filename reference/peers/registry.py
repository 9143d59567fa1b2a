"""Other renderers the report scores like methods: the ``translucent.renderers`` entry points.

A renderer is one module (or object) with, in its own words:

``NAME`` : str
    Its name (letters, digits, ``_``), the first part of each report entry ``NAME.MODE``.
``MODES`` : dict
    Mode name -> one line on what the mode is (Cycles: ``burley``, ``random_walk``, ...).
``available()`` -> str or None
    Why it cannot render on this machine (its program is not installed), else None.
``applies_to(scene, mode)`` -> str or None
    Why a scene is beyond the mode (a sentence naming the part), else None.
``model_of(mode)`` -> str or None
    The suite's model a mode renders (a radial profile's name, for the error split), or
    None where the mode's model is not one the suite knows.
``render(scene, mode, spp_values, seed)`` -> list of dict
    One timed render per samples-per-pixel count: ``spp``, ``seconds`` (wall clock of the
    render as a user would wait for it) and ``image`` (an :class:`~translucent.image.Image`
    in the suite's radiance units), or ``error``.

The suite's own, Blender Cycles (:mod:`.cycles`), is registered in its ``pyproject.toml``;
another distribution adds its renderer (pbrt-v4, LuxCore, an in-house one) the same way::

    [project.entry-points."translucent.renderers"]
    pbrt = "my_package.pbrt_renderer"

or, for this process only, with :func:`register_renderer`. ``translucent report
--renderers NAME[.MODE],...`` then scores it on every scene it applies to.
"""

from __future__ import annotations

import functools
import re
from typing import Any

from ...errors import InputError
from ...plugins import EntryPointTarget, discovered

__all__ = ["RENDERER_GROUP", "REQUIRED", "entry_mode", "register_renderer", "renderer",
           "renderer_entries", "renderer_names", "unregister_renderer"]

#: The entry-point group renderers are registered under.
RENDERER_GROUP = "translucent.renderers"

#: The suite's own renderers, by module: used where the installed metadata cannot be read.
BUILTIN_RENDERERS = {"cycles": "translucent.reference.peers.cycles"}

#: What a renderer or mode name may be (it names report entries, files and cache keys).
NAME_PATTERN = re.compile(r"^[a-z][a-z0-9_]{0,29}$")

#: The contract: attribute -> what it is.
REQUIRED = {
    "NAME": "its name",
    "MODES": "a dict of mode name -> description",
    "available": "a function available() returning why it cannot run here, or None",
    "applies_to": "a function applies_to(scene, mode) returning why not, or None",
    "model_of": "a function model_of(mode) returning the suite's model name, or None",
    "render": "a function render(scene, mode, spp_values, seed) returning timed images",
}

_registered: dict[str, Any] = {}


@functools.cache
def _discovered() -> dict:
    """Return the installed renderers, read once a process (the metadata does not change)."""
    return discovered(RENDERER_GROUP, BUILTIN_RENDERERS)[0]


def renderer_names() -> list[str]:
    """Return the renderers known: the suite's first, then the others by name."""
    known = {**_discovered(), **_registered}
    builtin = [name for name in BUILTIN_RENDERERS if name in known]
    return builtin + sorted(set(known) - set(builtin))


def register_renderer(name: str, target) -> None:
    """Add a renderer for this process: its module, a module's name, or an object."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise InputError("a renderer's name is lower-case letters, digits and '_' (at most "
                         "30), starting with a letter", field="name", value=name)
    _registered[name] = target


def unregister_renderer(name: str) -> None:
    """Remove a renderer :func:`register_renderer` added (nothing if it is not there)."""
    _registered.pop(name, None)


def renderer(name: str):
    """Return the renderer called ``name``, its contract checked.

    Raises
    ------
    InputError
        An unknown name (naming the known ones), a module that cannot be imported, or one
        that lacks part of the contract (naming the parts).
    """
    known = {**_discovered(), **_registered}
    if name not in known:
        raise InputError(f"unknown renderer; known: {', '.join(renderer_names()) or 'none'}",
                         field="--renderers", value=name)
    target = known[name]
    if isinstance(target, str):
        target = EntryPointTarget(target)
    if isinstance(target, EntryPointTarget):
        try:
            target = target.load()
        except (ImportError, AttributeError) as error:
            raise InputError(f"cannot be loaded: {error}", field="--renderers",
                             value=name) from None
    missing = [f"{part} ({what})" for part, what in REQUIRED.items()
               if not hasattr(target, part)]
    if missing:
        raise InputError(f"does not follow the renderer contract: lacks {'; '.join(missing)}",
                         field="--renderers", value=name)
    return target


def renderer_entries(spec: str) -> list[str]:
    """Return the report entries ``NAME.MODE`` that ``spec`` asks for.

    ``spec`` is a comma-separated list of renderers (every mode) or ``NAME.MODE``.

    Examples
    --------
    >>> renderer_entries("cycles.burley,cycles.volume")
    ['cycles.burley', 'cycles.volume']
    """
    entries: list[str] = []
    parts = [part.strip() for part in str(spec).split(",") if part.strip()]
    if not parts:
        raise InputError("give at least one renderer", field="--renderers", value=spec)
    for part in parts:
        name, _, mode = part.partition(".")
        module = renderer(name)
        if mode and mode not in module.MODES:
            raise InputError(f"{name} has no mode {mode!r}; its modes: "
                             f"{', '.join(module.MODES)}", field="--renderers", value=part)
        for chosen in [mode] if mode else list(module.MODES):
            entry = f"{name}.{chosen}"
            if entry not in entries:
                entries.append(entry)
    return entries


def entry_mode(entry: str):
    """Return ``(renderer, mode)`` of a report entry ``NAME.MODE``, or None for a method."""
    name, dot, mode = entry.partition(".")
    if not dot or name not in {**_discovered(), **_registered}:
        return None
    module = renderer(name)
    return (module, mode) if mode in module.MODES else None
