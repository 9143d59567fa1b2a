"""Numerical stability sweeps, one module per area (``translucent stress``).

Each module under this package defines functions decorated with :func:`stress_kernel`;
each returns a :class:`StressResult`: how many NaN/Inf values the kernel produced over
its sweep, the worst relative error against a more precise evaluation (float64 against
float32, mpmath against float64), and the bound that error must stay within.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

__all__ = ["StressResult", "stress_kernel", "all_kernels"]


@dataclass
class StressResult:
    """The outcome of one kernel's sweep.

    Parameters
    ----------
    evaluations : int
        How many values the sweep computed.
    nan, inf : int
        Non-finite values where the model is finite.
    negative : int
        Negative values where the model is non-negative.
    worst_relative_error : float
        Largest relative error against the more precise evaluation named in ``against``.
    bound : float
        The largest acceptable ``worst_relative_error`` (a sentence in ``notes`` says why).
    against : str
        What the errors are measured against ("float64", "mpmath 50 digits", ...).
    worst_at : dict
        The inputs where the worst error occurred.
    notes : str
        Where the bound comes from.
    """

    evaluations: int
    nan: int = 0
    inf: int = 0
    negative: int = 0
    worst_relative_error: float = 0.0
    bound: float = 0.0
    against: str = ""
    worst_at: dict = field(default_factory=dict)
    notes: str = ""

    @property
    def passed(self) -> bool:
        """No NaN, Inf or negative value and the worst error within the bound."""
        return (self.nan == 0 and self.inf == 0 and self.negative == 0
                and self.worst_relative_error <= self.bound)

    def as_dict(self) -> dict:
        """JSON-able form with ``passed``."""
        return {**asdict(self), "passed": self.passed}


_KERNELS: dict[str, Callable[[], StressResult]] = {}


def stress_kernel(name: str):
    """Register the decorated zero-argument function as the stress kernel ``name``."""

    def register(function: Callable[[], StressResult]):
        _KERNELS[name] = function
        return function

    return register


def all_kernels() -> dict[str, Callable[[], StressResult]]:
    """Every registered kernel, after importing every module of this package."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")
    return dict(sorted(_KERNELS.items()))
