"""The one exception type for bad input, naming the file, field and value."""

from __future__ import annotations

from typing import Any

__all__ = ["InputError", "check_finite", "check_positive", "check_nonnegative"]


class InputError(ValueError):
    """Bad input: says which file, which field, which value, and what is accepted.

    Subclasses :class:`ValueError` so that callers catching ``ValueError`` keep working.
    The command line turns it into exit code 2.

    Parameters
    ----------
    message : str
        What is wrong and what would be accepted ("must be >= 0").
    file : str or os.PathLike, optional
        The file the value came from.
    field : str, optional
        The field (key, argument, channel) holding the value.
    value : object, optional
        The offending value, printed with ``repr``.
    """

    def __init__(self, message: str, *, file: Any = None, field: str | None = None,
                 value: Any = ...):
        self.file = None if file is None else str(file)
        self.field = field
        self.value = value
        self.reason = message
        parts = []
        if self.file is not None:
            parts.append(self.file)
        if field is not None:
            parts.append(f"{field} = {_short_repr(value)}" if value is not ... else field)
        parts.append(message)
        super().__init__(": ".join(parts))


def _short_repr(value: Any, limit: int = 120) -> str:
    if hasattr(value, "tolist") and hasattr(value, "dtype"):  # numpy arrays and scalars
        value = value.tolist()
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def check_finite(value, field: str, *, file=None):
    """Return ``value`` as a float64 array; :class:`InputError` on NaN, Inf or non-numbers."""
    import numpy as np

    if isinstance(value, str | bytes):  # numpy would parse "1.5" as a number
        raise InputError("must be a number, not text", file=file, field=field, value=value)
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as error:
        raise InputError("must be a number or an array of numbers", file=file, field=field,
                         value=value) from error
    if not np.all(np.isfinite(array)):
        raise InputError("must be finite (no NaN or Inf)", file=file, field=field, value=value)
    return array


def check_nonnegative(value, field: str, *, file=None):
    """Return ``value`` as a finite float64 array, raising :class:`InputError` if any entry < 0."""
    array = check_finite(value, field, file=file)
    if (array < 0).any():
        raise InputError("must be >= 0", file=file, field=field, value=value)
    return array


def check_count(value, field: str, minimum: int = 1, *, why: str = "", file=None) -> int:
    """Return ``value`` as an int; :class:`InputError` unless an integer >= ``minimum``.

    Booleans are refused (``True`` is not a count); ``why`` is appended to the message.
    """
    try:
        integral = not isinstance(value, bool) and int(value) == value
    except (TypeError, ValueError, OverflowError):
        integral = False
    if not integral or value < minimum:
        raise InputError(f"must be an integer >= {minimum}{why}", file=file, field=field,
                         value=value)
    return int(value)


def check_positive(value, field: str, *, file=None):
    """Return ``value`` as a finite float64 array, raising :class:`InputError` if any entry <= 0."""
    array = check_finite(value, field, file=file)
    if (array <= 0).any():
        raise InputError("must be > 0", file=file, field=field, value=value)
    return array
