"""Progress bars: one constructor for every bar of the suite, one switch that hides them all.

A bar is shown on standard error while a step lasts, and only where standard error is a
terminal. The command line's ``--no-progress`` and ``--quiet``, the report's worker
processes (whose bars would garble the run's own) and a fast method's caller hide every bar
at once with :func:`hidden`; nothing is passed down to the code that draws them.

Examples
--------
>>> with hidden():
...     with progress_bar(total=3, description="example") as bar:
...         bar.update(3)
...     shown()
False
>>> shown()
True
"""

from __future__ import annotations

import contextlib
import threading

__all__ = ["hidden", "progress_bar", "shown"]

# a process-wide switch: bars are drawn from worker threads of one command too
_LOCK = threading.Lock()
_HIDDEN_DEPTH = 0


def shown() -> bool:
    """Return whether bars may be drawn now (no :func:`hidden` block is open)."""
    return _HIDDEN_DEPTH == 0


@contextlib.contextmanager
def hidden(hide: bool = True):
    """Hide every bar made inside the block (``hide=False``: change nothing).

    Blocks nest; a bar made before the block keeps its state.
    """
    global _HIDDEN_DEPTH
    if not hide:
        yield
        return
    with _LOCK:
        _HIDDEN_DEPTH += 1
    try:
        yield
    finally:
        with _LOCK:
            _HIDDEN_DEPTH -= 1


def progress_bar(iterable=None, *, total=None, description: str | None = None,
                 unit: str = "it", enabled: bool = True, leave: bool = False,
                 terminal_only: bool = True, **options):
    """Return a tqdm bar on standard error, hidden off a terminal and inside :func:`hidden`.

    Parameters
    ----------
    iterable : iterable, optional
        Wrapped as tqdm wraps it.
    total : int, optional
        Steps the bar counts.
    description : str, optional
        Its label.
    unit : str
        What a step is ("vertex", "image").
    enabled : bool
        False hides this bar alone.
    leave : bool
        Keep the finished bar on the terminal.
    terminal_only : bool
        Hide the bar where standard error is not a terminal (False: a long step, such as a
        reference render, also shows in a log).
    **options
        Passed to tqdm (``position``, ``dynamic_ncols``, ...).
    """
    from tqdm.auto import tqdm

    # disable=None: tqdm hides the bar where standard error is not a terminal
    disable = True if not (enabled and shown()) else (None if terminal_only else False)
    return tqdm(iterable, total=total, desc=description, unit=unit, leave=leave,
                disable=disable, **options)
