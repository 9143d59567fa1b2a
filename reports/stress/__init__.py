"""Numerical stability sweeps, one module per area (``translucent stress``).

Each module under this package defines functions decorated with :func:`stress_kernel`;
each returns a :class:`StressResult`: how many NaN/Inf values the kernel produced over
its sweep, the worst relative error against a more precise evaluation (float64 against
float32, mpmath against float64), and the bound that error must stay within.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

__all__ = ["StressResult", "stress_kernel", "all_kernels", "count_nonfinite"]


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
        Negative values where the model is non-negative, and more generally values outside
        the model's range or breaking a stated invariant (a total reflectance above 1, a
        projection with more energy than its profile, a result returned where the method
        must refuse).
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
    details : list of dict
        Per-case numbers of the sweep (what converged, what was refused and how), written
        into the JSON beside the summary.
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
    details: list = field(default_factory=list)

    @property
    def passed(self) -> bool:
        """No NaN, Inf or negative value and the worst error within the bound."""
        return bool(self.nan == 0 and self.inf == 0 and self.negative == 0
                    and self.worst_relative_error <= self.bound)

    def as_dict(self) -> dict:
        """JSON-able form with ``passed``."""
        return {**asdict(self), "passed": self.passed}


def count_nonfinite(values, result: StressResult, *, negative: bool = True) -> None:
    """Add the NaN, Inf (and, if ``negative``, negative) entries of ``values`` to ``result``."""
    import numpy as np

    values = np.asarray(values)
    result.nan += int(np.isnan(values).sum())
    result.inf += int(np.isinf(values).sum())
    if negative:
        result.negative += int((values < 0).sum())


_KERNELS: dict[str, Callable[[], StressResult]] = {}


def stress_kernel(name: str):
    """Register the decorated zero-argument function as the stress kernel ``name``.

    A kernel that raises is registered as failing, not as a crash of the whole run: its
    result has ``negative = 1`` and the exception in ``notes``.
    """

    def register(function: Callable[[], StressResult]):
        @functools.wraps(function)
        def guarded() -> StressResult:
            try:
                return function()
            except Exception as error:  # noqa: BLE001 - a failing kernel is a result
                return StressResult(evaluations=0, negative=1, bound=0.0, against="",
                                    notes=f"the kernel raised {type(error).__name__}: {error}")

        _KERNELS[name] = guarded
        return function

    return register


def all_kernels() -> dict[str, Callable[[], StressResult]]:
    """Every registered kernel, after importing every module of this package."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")
    return dict(sorted(_KERNELS.items()))
