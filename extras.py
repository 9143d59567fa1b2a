"""What each optional part of the suite needs, and the error that says which extra to install.

The base install (``pip install translucent``) reads and writes images, compares them
(``translucent compare``, the pytest plugin), lists the committed references and the
built-in scenes' files. The rest comes with extras: ``render`` (Mitsuba 3, Dr.Jit and the
mesh libraries: references, scenes' ray queries), ``fast`` (the fast methods: numba,
PyWavelets, and ``render``), ``fit`` (emcee, corner, RAW and TIFF readers, numba for the
random walk), ``distributed`` (Dask, for the report's workers) and ``all``. A command that
needs a package the install lacks ends with :class:`MissingExtra` (an
:class:`~translucent.errors.InputError`: exit 2, one line naming the extra), never an
ImportError.

Examples
--------
>>> extra_for("mitsuba"), extra_for("numba.core"), extra_for("numpy")
('render', 'fast', None)
"""

from __future__ import annotations

from .errors import InputError

__all__ = ["EXTRAS", "MissingExtra", "extra_for", "missing_extra"]

#: The top-level module of each optional package -> the extra that brings it.
EXTRAS: dict[str, str] = {
    "mitsuba": "render",
    "drjit": "render",
    "trimesh": "render",
    "embreex": "render",
    "numba": "fast",
    "llvmlite": "fast",
    "pywt": "fast",
    "emcee": "fit",
    "corner": "fit",
    "rawpy": "fit",
    "tifffile": "fit",
    "mpmath": "fit",
    "dask": "distributed",
    "distributed": "distributed",
}


class MissingExtra(InputError):
    """A command needs a package of an extra this install lacks."""


def extra_for(module_name: str | None) -> str | None:
    """Return the extra that brings module ``module_name`` (None: not an optional one)."""
    if not module_name:
        return None
    return EXTRAS.get(module_name.split(".")[0])


def missing_extra(error: BaseException) -> MissingExtra | None:
    """Return the :class:`MissingExtra` behind ``error`` (or its causes), or None.

    Parameters
    ----------
    error : BaseException
        Typically a :class:`ModuleNotFoundError` raised while importing or running a
        command.
    """
    seen = set()
    while error is not None and id(error) not in seen:
        seen.add(id(error))
        if isinstance(error, ModuleNotFoundError):
            extra = extra_for(error.name)
            if extra is not None:
                return MissingExtra(
                    f"this needs the optional package {error.name.split('.')[0]!r}: install "
                    f"the suite's '{extra}' extra (pip install 'translucent[{extra}]', or "
                    "'translucent[all]')", field="extra", value=extra)
        error = error.__cause__ or error.__context__
    return None
