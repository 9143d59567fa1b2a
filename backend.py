"""Mitsuba 3 and Dr.Jit set-up: find a working libLLVM, pick a variant, import once.

Dr.Jit's LLVM backend needs a shared ``libLLVM`` of version 16 or newer. Debian's LLVM 14
is not found and LLVM 15 aborts in code generation, so the suite looks, in order, at
``DRJIT_LIBLLVM_PATH`` (if the user set it), the ``karellen-llvm-core`` wheel installed
with the suite (``<prefix>/lib/libLLVM.so.*``), then system ``libLLVM-{16..30}``, and
sets ``DRJIT_LIBLLVM_PATH`` *before* Mitsuba is imported, so a user never has to.

Variants are tried in the order ``cuda_ad_rgb`` (a GPU is there), ``llvm_ad_rgb``,
``scalar_rgb`` (slow: a warning says so); ``TRANSLUCENT_VARIANT`` overrides.
"""

from __future__ import annotations

import functools
import glob
import os
import re
import sys
import sysconfig
import threading
import warnings
from pathlib import Path

from .errors import InputError

__all__ = ["mitsuba", "variant", "find_libllvm", "configure_libllvm", "VARIANT_ORDER",
           "backend_facts"]

VARIANT_ORDER = ("cuda_ad_rgb", "llvm_ad_rgb", "scalar_rgb")


def _llvm_major(path: str) -> int | None:
    match = re.search(r"LLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(match.group(1)) if match else None


def find_libllvm() -> str | None:
    """Return the path of a shared libLLVM of version >= 16, or None.

    Looks at ``DRJIT_LIBLLVM_PATH``, then the ``lib`` folders of this Python's prefixes
    (where ``karellen-llvm-core`` puts ``libLLVM.so.<major>.<minor>``), then the usual
    system locations.
    """
    given = os.environ.get("DRJIT_LIBLLVM_PATH")
    if given and Path(given).is_file():
        return given
    prefixes = {sys.prefix, sys.base_prefix, sysconfig.get_config_var("prefix") or sys.prefix}
    candidates: list[str] = []
    for prefix in prefixes:
        candidates += sorted(glob.glob(os.path.join(prefix, "lib", "libLLVM.so.*")))
        candidates += sorted(glob.glob(os.path.join(prefix, "lib", "libLLVM-*.so")))
    for pattern in ("/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/lib/*-linux-gnu/libLLVM*.so*",
                    "/usr/lib/libLLVM*.so*", "/usr/local/lib/libLLVM*.so*"):
        candidates += sorted(glob.glob(pattern), reverse=True)
    for path in candidates:
        major = _llvm_major(path)
        if major is not None and major >= 16 and Path(path).is_file():
            return path
    return None


def _gpu_usable() -> bool:
    try:
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # no driver, no device: not usable
        return False


def configure_libllvm() -> str | None:
    """Point ``DRJIT_LIBLLVM_PATH`` at a libLLVM >= 16 unless the user already chose one.

    Called when :mod:`translucent` is imported, because Dr.Jit reads the variable once,
    when its LLVM backend starts: a module that imports ``drjit`` before
    :func:`mitsuba` runs would otherwise get the system's LLVM 14 and abort in code
    generation ("Cannot select fmaximum").
    """
    libllvm = find_libllvm()
    if libllvm and "DRJIT_LIBLLVM_PATH" not in os.environ:
        os.environ["DRJIT_LIBLLVM_PATH"] = libllvm
    return os.environ.get("DRJIT_LIBLLVM_PATH")


#: Held while Mitsuba is imported and its variant chosen: threads of one process (a Dask
#: worker's) that first need it together must not see a half-imported module.
_MITSUBA_LOCK = threading.RLock()


def mitsuba():
    """Import Mitsuba with a working variant set and return the module.

    Safe to call from several threads at once: the first import and the choice of the
    variant happen once, under a lock.

    Returns
    -------
    module
        ``mitsuba``, with ``mitsuba.variant()`` one of :data:`VARIANT_ORDER` (or the
        variant named by ``TRANSLUCENT_VARIANT``).

    Raises
    ------
    InputError
        When ``TRANSLUCENT_VARIANT`` names a variant this Mitsuba does not have, or one
        this machine cannot run (a CUDA variant without a usable GPU, an LLVM variant
        without a working libLLVM).
    """
    with _MITSUBA_LOCK:
        return _import_mitsuba()


@functools.lru_cache(maxsize=None)
def _import_mitsuba():
    """Do what :func:`mitsuba` says (once; its caller holds the lock)."""
    configure_libllvm()
    import mitsuba as mi

    requested = os.environ.get("TRANSLUCENT_VARIANT")
    if requested:
        if requested not in mi.variants():
            raise InputError(f"not a Mitsuba variant here; available: {', '.join(mi.variants())}",
                             field="TRANSLUCENT_VARIANT", value=requested)
        if requested.startswith("cuda") and not _gpu_usable():
            raise InputError("this machine has no usable CUDA GPU; unset it to let the suite "
                             "choose (llvm_ad_rgb on the CPU)", field="TRANSLUCENT_VARIANT",
                             value=requested)
        try:
            mi.set_variant(requested)
            if not requested.startswith("scalar"):
                mi.Float(1.0) + 1.0  # noqa: B018
                import drjit as dr

                dr.eval()
        except Exception as error:  # the backend's library missing or unable to compile
            raise InputError(f"Mitsuba cannot run this variant here ({error})",
                             field="TRANSLUCENT_VARIANT", value=requested) from error
        return mi
    for name in VARIANT_ORDER:
        if name not in mi.variants():
            continue
        if name.startswith("cuda") and not _gpu_usable():
            continue
        try:
            mi.set_variant(name)
        except Exception:  # e.g. the LLVM backend failing to load its library
            continue
        if name.startswith("llvm"):
            try:  # the library may load but fail to compile: prove it once
                mi.Float(1.0) + 1.0  # noqa: B018
                import drjit as dr

                dr.eval()
            except Exception:
                continue
        if name.startswith("scalar"):
            warnings.warn("Mitsuba runs in the scalar_rgb variant: renders will be slow "
                          "(no libLLVM >= 16 found; install karellen-llvm-core)", stacklevel=2)
        return mi
    raise RuntimeError(f"none of the Mitsuba variants {VARIANT_ORDER} could be set")


#: Forget the imported state (tests that change ``TRANSLUCENT_VARIANT``).
mitsuba.cache_clear = _import_mitsuba.cache_clear

def variant() -> str:
    """Return the Mitsuba variant in use (imports Mitsuba on first call)."""
    return mitsuba().variant()


def is_jit_variant() -> bool:
    """Tell whether the variant is vectorised (llvm_*, cuda_*) and takes wide arrays."""
    return not variant().startswith("scalar")


def backend_facts() -> dict[str, str]:
    """Versions and choices for ``translucent doctor`` and for image headers."""
    import drjit as dr

    mi = mitsuba()
    return {
        "python": sys.version.split()[0],
        "mitsuba": mi.__version__,
        "drjit": dr.__version__,
        "variant": mi.variant(),
        "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH") or "(none found)",
        "gpu": "usable" if _gpu_usable() else "not usable",
    }
