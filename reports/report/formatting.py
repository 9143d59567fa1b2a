"""How numbers are written for people: metrics, durations and speed-ups, one way everywhere.

The HTML page, the summary the command prints and the benches all format with these.

Examples
--------
>>> format_value(0.012345), format_seconds(0.0123), format_seconds(12.34), format_speedup(38.2)
('0.01235', '12 ms', '12.3 s', '38x')
"""

from __future__ import annotations

import math

__all__ = ["format_seconds", "format_speedup", "format_value"]


def format_value(value, digits: int = 4) -> str:
    """Return a metric for a table: ``digits`` significant figures, a dash for None."""
    if value is None:
        return "–"
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        return f"{value:.{digits}g}"
    return str(value)


def format_seconds(value) -> str:
    """Return a duration for a table: ms below a second, else s; a dash for None."""
    if value is None:
        return "–"
    return f"{value * 1000:.0f} ms" if value < 1 else f"{value:.1f} s"


def format_speedup(value, extrapolated: bool = False) -> str:
    """Return a speed-up over path tracing: ``"38x"``, ``"~5x"`` (extrapolated), "–" (None)."""
    if value is None:
        return "–"
    text = f"{value:.2g}x" if value < 100 else f"{value:.0f}x"
    return ("~" if extrapolated else "") + text
