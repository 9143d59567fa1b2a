"""Memory estimated before work: a job the machine cannot hold is refused, not started.

A render, a capture, a photon walk or a precomputation (translucent radiosity's scattering
samples, PRT's transfer) too large for the machine used to end in a ``MemoryError``
traceback after minutes of work, or in the kernel's OOM killer. :func:`check_memory`
compares an estimate (bytes per pixel, photon or patch pair, measured: see the constants
and docs/references.md; PRT's is a bound on its coefficients) with the memory the machine
has available and refuses, naming the option, the estimate and what is there.
"""

from __future__ import annotations

import os

from .errors import InputError

__all__ = ["RENDER_BYTES_PER_PIXEL", "CAPTURE_BYTES_PER_PIXEL", "WALK_BYTES_PER_PHOTON",
           "RADIOSITY_BYTES_PER_PAIR", "MEMORY_SHARE", "available_memory", "check_memory",
           "format_bytes", "check_npz_memory"]

#: A reference render holds per pixel Mitsuba's film and the float64 mean and spread of its
#: passes, for each channel render: 203 bytes a pixel measured (peak RSS, Skin1 sphere,
#: 96^2 against 1536^2 pixels, per-channel renders); 256 leaves room.
RENDER_BYTES_PER_PIXEL = 256

#: A synthetic capture (image, variance, noise model, profile tallies): 150 bytes a pixel
#: measured (dipole generator, 512^2 against 2048^2 pixels); 192 leaves room.
CAPTURE_BYTES_PER_PIXEL = 192

#: All photons of a channel walk together: 910 bytes a photon measured with the Dr.Jit
#: backend, 270 with numpy (2e4 against 2e5 photons); 1024 covers both.
WALK_BYTES_PER_PHOTON = 1024

#: Translucent radiosity's precomputation holds, per stored entry of its scattering matrix
#: (a patch pair within the cut-off max_d), the sample operators it keeps and their
#: intermediates: peak RSS above the interpreter's measured 191 bytes a pair on the sphere
#: (26.2 million pairs, all of them), 272 on the concave bowl (5.2 million); 320 leaves room.
RADIOSITY_BYTES_PER_PAIR = 320

#: The share of the available memory a job may plan to take.
MEMORY_SHARE = 0.8

#: Memory an ``.npz`` reader takes per byte its arrays declare: the arrays as stored, their
#: float64 copies (twice a float32's bytes) and one validated copy more.
NPZ_READ_FACTOR = 6


def available_memory() -> int | None:
    """Return the bytes the machine can give a new job now, or None where unknown.

    ``MemAvailable`` of ``/proc/meminfo`` (free memory plus what the kernel can reclaim);
    elsewhere the physical memory (``os.sysconf``).
    """
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def format_bytes(count: float) -> str:
    """Return ``count`` bytes in the largest binary unit under 1024 of it (``"54.0 GiB"``)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(count) < 1024 or unit == "PiB":
            return f"{count:.1f} {unit}" if unit != "B" else f"{int(count)} B"
        count /= 1024
    return f"{count:.1f} EiB"  # pragma: no cover - unreachable


def check_memory(nbytes: float, *, what: str, field: str, value, file=None,
                 available: int | None = None) -> None:
    """Refuse a job whose estimated memory exceeds :data:`MEMORY_SHARE` of what is available.

    Parameters
    ----------
    nbytes : float
        The estimate.
    what : str
        What takes it ("a 16384 x 16384 render").
    field, value, file
        The option (or file and field) that asked for it, for the message.
    available : int, optional
        Bytes available (default :func:`available_memory`; unknown: nothing is refused).

    Raises
    ------
    InputError
        Naming ``field`` and ``value``, the estimate and the memory available.

    Examples
    --------
    >>> check_memory(1e6, what="a small image", field="--size", value=16, available=2**30)
    >>> try:
    ...     check_memory(1e12, what="a huge image", field="--size", value=10**6,
    ...                  available=2**30)
    ... except InputError as error:
    ...     print(error.reason.split(";")[0])
    a huge image needs about 931.3 GiB of memory
    """
    available = available_memory() if available is None else available
    if available is None or nbytes <= MEMORY_SHARE * available:
        return
    raise InputError(f"{what} needs about {format_bytes(nbytes)} of memory; this machine has "
                     f"{format_bytes(available)} available (a job may plan on "
                     f"{MEMORY_SHARE:.0%} of it)", file=file, field=field, value=value)


def npz_declared_bytes(path) -> int | None:
    """Return the bytes the arrays of the ``.npz`` ``path`` declare in their headers.

    Read from the headers alone, without loading an array; None where the file is no
    readable archive of ``.npy`` members (its reader then says why).
    """
    import zipfile

    import numpy as np

    total = 0
    try:
        with zipfile.ZipFile(path) as archive:
            for info in archive.infolist():
                if not info.filename.endswith(".npy"):
                    continue
                with archive.open(info) as member:
                    version = np.lib.format.read_magic(member)
                    read = np.lib.format.read_array_header_1_0 if version == (1, 0) \
                        else np.lib.format.read_array_header_2_0
                    shape, _, dtype = read(member)
                total += int(np.prod(shape, dtype=object)) * dtype.itemsize
    except Exception:  # noqa: BLE001 - zipfile and numpy raise many types on bad files
        return None
    return total


def check_npz_memory(path, *, field: str, file=None, what: str = "reading") -> None:
    """Refuse, from its headers, an ``.npz`` whose arrays the machine cannot hold.

    Raises
    ------
    InputError
        Naming ``file`` (default ``path``), ``field``, the declared size and what is there.
    """
    declared = npz_declared_bytes(path)
    if declared is not None:
        check_memory(declared * NPZ_READ_FACTOR, what=f"{what} arrays that declare "
                     f"{format_bytes(declared)}", file=path if file is None else file,
                     field=field, value=format_bytes(declared))
