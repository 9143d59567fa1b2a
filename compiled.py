"""The suite's compiled kernels: numba's ``njit`` for loops that may run in parallel.

A kernel with ``numba.prange`` loops is compiled with ``parallel=True`` where the process
has more than one numba thread, and as a serial kernel (``prange`` is then ``range``)
where it has one: the report's and the benchmarks' worker processes run with one thread
each (:func:`translucent.reports.report.distributed.worker_environment`), and there the
parallel
kernel gains nothing at run time while its compilation takes about twice as long (the
parallel lowering; docs/report.md, "The workers' compiled kernels").

The serial kernel is cached by numba under a name of its own (the function's qualified
name with ``.serial`` added), so that a process with many threads never loads a serial
kernel compiled by a one-thread process, nor the other way round.
"""

from __future__ import annotations

import types

__all__ = ["SERIAL_SUFFIX", "parallel_njit", "parallel_compiles"]

#: Added to a kernel's qualified name where it is compiled serially.
SERIAL_SUFFIX = ".serial"


def parallel_compiles() -> bool:
    """Return True where numba has more than one thread (``NUMBA_NUM_THREADS``)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS) > 1


def parallel_njit(function=None, **options):
    """``numba.njit(parallel=True, **options)``, or serial in a one-thread process.

    Parameters
    ----------
    function : callable, optional
        The kernel; without it, a decorator is returned (``@parallel_njit(cache=True)``).
    **options
        numba's ``njit`` options (``cache``, ``fastmath``, ...), ``parallel`` excluded.

    Returns
    -------
    numba dispatcher, or a decorator that makes one

    Examples
    --------
    >>> import numba
    >>> from translucent.compiled import parallel_njit
    >>> @parallel_njit(cache=False)
    ... def total(values):
    ...     out = 0.0
    ...     for i in numba.prange(len(values)):
    ...         out += values[i]
    ...     return out
    """
    if "parallel" in options:
        raise TypeError("parallel_njit decides `parallel` itself (by the thread count)")

    def decorate(kernel):
        import numba

        if parallel_compiles():
            return numba.njit(parallel=True, **options)(kernel)
        # load numba's threading layer, as a parallel kernel would: it registers the
        # symbols (``get_thread_id``) that a serial kernel loaded from the cache links to
        # (unregistered, the call jumps to address 0)
        numba.get_num_threads()
        # a copy under another name: numba's cache files are named by the qualified name
        serial = types.FunctionType(kernel.__code__, kernel.__globals__, kernel.__name__,
                                    kernel.__defaults__, kernel.__closure__)
        serial.__kwdefaults__ = kernel.__kwdefaults__
        serial.__qualname__ = kernel.__qualname__ + SERIAL_SUFFIX
        serial.__module__ = kernel.__module__
        serial.__doc__ = kernel.__doc__
        return numba.njit(**options)(serial)

    return decorate if function is None else decorate(function)
