"""The options every command shares: ``--no-progress``, ``--quiet`` and ``--json FILE``.

``--quiet`` prints nothing on standard output (warnings and errors still go to standard
error) and shows no progress bar. ``--json FILE`` writes, when the command ends with exit
code 0 or 1, one JSON object: ``command``, ``exit_code`` and what the command found (its
figures, the files it wrote). ``-`` writes it on standard output, and then nothing else is
printed there. A command that ends on bad input (exit 2) or is interrupted writes none.

A command adds to its record with :func:`record`; :func:`~translucent.reports.cli.main`
checks the file before the command runs and writes it afterwards (:func:`write_record`).
Commands whose ``--json`` came before this convention (``bench``, ``stress``) keep their own
meaning of it.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

__all__ = ["add_common_options", "record", "json_target", "quiet", "write_record"]

#: The attribute of the parsed arguments that holds the record.
_RECORD = "_record"


def add_common_options(parser: argparse.ArgumentParser) -> None:
    """Give ``parser`` (a command's) the common options it does not define itself."""
    known = parser._option_string_actions
    if "--no-progress" not in known:
        parser.add_argument("--no-progress", action="store_true",
                            help="no progress bars (of the steps that show one)")
    if "--quiet" not in known:
        parser.add_argument("--quiet", "-q", action="store_true",
                            help="print nothing on standard output (warnings and errors "
                                 "still go to standard error); no progress bars")
    if "--json" not in known:
        parser.add_argument("--json", dest="json_record", default=None, metavar="FILE",
                            help="also write what the command found as one JSON object "
                                 "('-': standard output, and nothing else there)")


def json_target(args) -> str | None:
    """Return the file of the common ``--json`` (None: not given, or the command's own)."""
    return getattr(args, "json_record", None)


def quiet(args) -> bool:
    """Whether standard output stays silent: ``--quiet``, or the record goes there."""
    return bool(getattr(args, "quiet", False)) or json_target(args) == "-"


def record(args, **fields) -> None:
    """Add ``fields`` to the command's record (kept only where ``--json`` asks for it)."""
    if json_target(args) is None:
        return
    held = getattr(args, _RECORD, None)
    if held is None:
        held = {}
        setattr(args, _RECORD, held)
    held.update(fields)


def _plain(value):
    """Return ``value`` as JSON can hold it (numpy numbers and arrays, paths; NaN as null)."""
    if isinstance(value, dict):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return _plain(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_record(args, exit_code: int) -> None:
    """Write the record of a command that ended with ``exit_code`` where ``--json`` asks."""
    target = json_target(args)
    if target is None:
        return
    content = {"command": args.command, "exit_code": int(exit_code)}
    content.update(getattr(args, _RECORD, None) or {})
    text = json.dumps(_plain(content), indent=2, allow_nan=False) + "\n"
    if target == "-":
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    from ...atomic import atomic_write_text

    atomic_write_text(target, text)
