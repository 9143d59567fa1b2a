"""Ctrl-C and SIGTERM that a long step notices even where a library swallowed them.

A signal raises in whatever Python code runs when it arrives; inside a Mitsuba Python
plugin that exception can be caught by Dr.Jit and the render go on. The command line's
handlers therefore also record the signal here, and long loops call :func:`check` between
steps, so that a render stops at the next pass at the latest.
"""

from __future__ import annotations

import contextlib
import threading

__all__ = ["Terminated", "check", "deferred", "deferring", "record", "reset"]


class Terminated(Exception):
    """SIGTERM, raised where the program is so that temporary files are cleaned up."""


_received: dict[str, bool] = {"interrupt": False, "terminate": False}
_lock = threading.Lock()


def record(kind: str) -> None:
    """Remember that ``kind`` ("interrupt" or "terminate") was received."""
    with _lock:
        _received[kind] = True


def reset() -> None:
    """Forget what was received (a new command starts)."""
    with _lock:
        _received.update(interrupt=False, terminate=False)


def check() -> None:
    """Raise KeyboardInterrupt or :class:`Terminated` if such a signal was received."""
    if _received["terminate"]:
        raise Terminated()
    if _received["interrupt"]:
        raise KeyboardInterrupt()


_deferred = [0]


@contextlib.contextmanager
def deferred():
    """Hold a received signal as recorded for the block, to be raised by :func:`check`.

    For loops over a library call that reports any exception raised inside it as its own
    failure (emcee prints a traceback for one raised in the log-probability): the loop
    calls :func:`check` between calls, so the signal ends it there, quietly.
    """
    with _lock:
        _deferred[0] += 1
    try:
        yield
    finally:
        with _lock:
            _deferred[0] -= 1


def deferring() -> bool:
    """Whether a signal received now is to be held (inside :func:`deferred`)."""
    return _deferred[0] > 0
