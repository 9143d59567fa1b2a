"""What other distributions add to the suite through entry points: methods, renderers.

A group (``translucent.methods``, ``translucent.renderers``) maps a name to
``module`` or ``module:attribute``; :func:`discovered` reads a group once, and
:class:`EntryPointTarget` imports what an entry names when it is first used.
"""

from __future__ import annotations

import importlib
import importlib.metadata
from dataclasses import dataclass
from typing import Any

__all__ = ["EntryPointTarget", "discovered"]


@dataclass(frozen=True)
class EntryPointTarget:
    """A target found through an entry point: ``module`` or ``module:attribute``, and whose."""

    value: str
    distribution: str = "?"

    def load(self):
        """Import the module (and look up the attribute) the entry point names."""
        module_name, _, attribute = self.value.partition(":")
        target = importlib.import_module(module_name.strip())
        for part in filter(None, attribute.strip().split(".")):
            target = getattr(target, part)
        return target


def discovered(group: str, builtin: dict[str, str]) -> tuple[dict[str, Any],
                                                              dict[str, list[str]]]:
    """Return the group's entries by name, and the names claimed by more than one value.

    ``builtin`` (name -> module) stands in for the suite's own entries where its
    distribution metadata cannot be read (a source tree run without being installed).
    """
    found: dict[str, Any] = {}
    claims: dict[str, set[str]] = {}
    owners: dict[str, list[str]] = {}
    for entry in importlib.metadata.entry_points(group=group):
        dist = getattr(entry, "dist", None)
        owner = getattr(dist, "name", None) or "?"
        claims.setdefault(entry.name, set()).add(entry.value)
        owners.setdefault(entry.name, []).append(f"{owner} ({entry.value})")
        found.setdefault(entry.name, EntryPointTarget(entry.value, owner))
    conflicts = {name: owners[name] for name, values in claims.items() if len(values) > 1}
    try:
        importlib.metadata.distribution("translucent")
    except importlib.metadata.PackageNotFoundError:
        for name, module in builtin.items():
            found.setdefault(name, module)
    return found, conflicts
