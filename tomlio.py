"""Reading and writing the TOML the suite's files use (scene files, material files)."""

from __future__ import annotations

import json
import math
import sys

import numpy as np

from .errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["tomllib", "toml_value", "parse_toml"]


def parse_toml(text: str, *, file=None) -> dict:
    """Parse TOML ``text``; :class:`InputError` naming ``file`` where it cannot be used.

    Refused: text that is not TOML, and tables or arrays nested deeper than
    :data:`~translucent.errors.MAX_NESTING` (the suite's own files go 3 levels deep).
    """
    from .errors import MAX_NESTING, check_nesting

    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"not valid TOML ({error})", file=file) from error
    except RecursionError:
        raise InputError(f"not readable TOML: nested too deeply (at most {MAX_NESTING} levels "
                         "are read)", file=file) from None
    return check_nesting(table, file=file)


def toml_value(value) -> str:
    """``value`` as a TOML value: numbers (nan/inf included), strings, arrays, inline tables.

    Raises
    ------
    InputError
        For a type TOML cannot hold (the field is named ``value`` with the type's name).
    """
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        number = float(value)
        if math.isnan(number):
            return "nan"
        if math.isinf(number):
            return "inf" if number > 0 else "-inf"
        return repr(number)
    if isinstance(value, str):
        return json.dumps(value)  # JSON string escapes are valid TOML basic strings
    if isinstance(value, np.ndarray):
        return toml_value(value.tolist())
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(item) for item in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{key} = {toml_value(item)}" for key, item in value.items()) \
            + " }"
    raise InputError("cannot be written to TOML", field="value", value=type(value).__name__)
