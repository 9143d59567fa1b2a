"""The one exception type for bad input, naming the file, field and value."""

from __future__ import annotations

from typing import Any

__all__ = ["InputError", "check_finite", "check_positive", "check_nonnegative", "json_object",
           "nesting_depth", "check_nesting", "MAX_NESTING"]

#: The deepest nesting of tables and arrays a file the suite reads may have (scene files,
#: capture sidecars, header metadata: the suite's own go 4 levels deep).
MAX_NESTING = 64


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
    except OverflowError as error:  # an integer of hundreds of digits
        raise InputError("is too large a number (beyond float64)", file=file, field=field,
                         value=value) from error
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


#: The integers a file may hold: TOML's own range (64-bit signed), which JSON files the
#: suite reads keep too; beyond it a number is no float and no array element.
INTEGER_RANGE = (-2**63, 2**63 - 1)


def nesting_depth(value) -> int:
    """Return how deeply ``value``'s dicts, lists and tuples nest (0 for a scalar).

    Counted without recursion, so that any depth can be measured.
    """
    deepest, stack = 0, [(value, 1)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, dict):
            children = item.values()
        elif isinstance(item, (list, tuple)):
            children = item
        else:
            continue
        deepest = max(deepest, level)
        stack.extend((child, level + 1) for child in children)
    return deepest


def check_nesting(value, *, file=None, field: str | None = None,
                  max_depth: int = MAX_NESTING, integers: bool = True):
    """Return a parsed file's ``value``; :class:`InputError` where it cannot be used.

    Refused: tables and arrays nested deeper than ``max_depth``, and with ``integers``
    integers outside :data:`INTEGER_RANGE` (the key holding the first is named). Walked
    without recursion.
    """
    depth = nesting_depth(value)
    if depth > max_depth:
        raise InputError(f"nests {depth} levels deep; at most {max_depth} are read", file=file,
                         field=field)
    stack = [(value, field or "")] if integers else []
    while stack:
        item, where = stack.pop()
        if isinstance(item, dict):
            stack.extend((child, f"{where}.{key}" if where else str(key))
                         for key, child in item.items())
        elif isinstance(item, (list, tuple)):
            stack.extend((child, f"{where}[{index}]") for index, child in enumerate(item))
        elif isinstance(item, int) and not isinstance(item, bool) and \
                not INTEGER_RANGE[0] <= item <= INTEGER_RANGE[1]:
            raise InputError(f"is an integer of {len(str(abs(item)))} digits; integers must lie "
                             "within 64 bits", file=file, field=where or None, value=item)
    return value


def json_object(text, *, file=None, field: str | None = None, max_depth: int = MAX_NESTING,
                what: str = "JSON", integers: bool = True) -> dict:
    """Parse ``text`` as a JSON object of at most ``max_depth`` levels.

    Raises
    ------
    InputError
        Naming ``file`` and ``field``: not JSON, nested too deep to parse or deeper than
        ``max_depth``, integers beyond 64 bits, or not an object (the type found is the
        value). ``what`` is what the message calls the text (``"JSON file"``); without
        ``integers`` large integers are left to the caller's own checks.
    """
    import json

    try:
        value = json.loads(text)
    except RecursionError:
        raise InputError(f"not a readable {what}: nested too deeply (at most {max_depth} "
                         "levels are read)", file=file, field=field) from None
    except (TypeError, ValueError) as error:
        raise InputError(f"not a readable {what} ({error})", file=file, field=field) from None
    if not isinstance(value, dict):
        raise InputError("must be a JSON object ({...})", file=file, field=field,
                         value=type(value).__name__)
    return check_nesting(value, file=file, field=field, max_depth=max_depth,
                         integers=integers)
