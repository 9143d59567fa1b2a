"""Independent tasks (reference renders, benchmark sweeps, batches of fits) on Dask.

Local processes by default; ``scheduler="tcp://host:8786"`` (the ``--scheduler ADDRESS``
option of the commands) sends them to a running Dask cluster. Results come back in the
order the tasks were given, so a sweep run here and one run on a cluster are compared
element by element.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterable, Sequence
from typing import Any

from ...errors import InputError

__all__ = ["WORKER_MALLOC_TUNABLES", "run_tasks", "dask_client", "prepare_worker", "timed_call",
           "worker_environment"]


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, *, workers: int = 2, threads_per_worker: int = 1):
    """Yield a ``dask.distributed.Client``: to ``scheduler`` if given, else a local cluster.

    Parameters
    ----------
    scheduler : str, optional
        Address of a running scheduler (``tcp://127.0.0.1:8786``). None starts a
        :class:`~dask.distributed.LocalCluster` on loopback for the duration.
    workers, threads_per_worker : int
        Size of the local cluster (ignored with ``scheduler``).
    """
    import dask
    from dask.distributed import Client, LocalCluster

    if scheduler is not None:
        if not isinstance(scheduler, str) or "://" not in scheduler and ":" not in scheduler:
            raise InputError("expected a scheduler address such as tcp://127.0.0.1:8786",
                             field="--scheduler", value=scheduler)
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as error:
            raise InputError(f"no Dask scheduler answers there ({error})", field="--scheduler",
                             value=scheduler) from error
        try:
            yield client
        finally:
            client.close()
        return
    environment = worker_environment(threads_per_worker)
    # Dask's nanny writes the workers' variables into this process's own environment before
    # it spawns them, and leaves them there; numba re-reads NUMBA_NUM_THREADS at every
    # compilation and refuses a value other than its running pool's, so they are put back
    # when the cluster is gone (not before: a worker may still be spawning)
    touched = [*environment, "PYTHONHASHSEED"]
    saved = {name: os.environ.get(name) for name in touched}
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": environment}), \
                LocalCluster(n_workers=workers, threads_per_worker=threads_per_worker,
                             processes=True, host="127.0.0.1",
                             dashboard_address=None) as cluster, \
                Client(cluster) as client:
            yield client
    finally:
        _restore(saved)


def _restore(saved: dict) -> None:
    """Put environment variables back as ``saved`` holds them (None: unset)."""
    for name, value in saved.items():
        if value is None:
            os.environ.pop(name, None)
        else:
            os.environ[name] = value


def prepare_worker() -> str:
    """Import Mitsuba with its variant in this (worker) process; return the variant.

    Run on every worker by :func:`run_tasks` before its tasks. A variant the worker cannot
    run (``TRANSLUCENT_VARIANT`` naming a CUDA one on a machine without a GPU) raises the
    :class:`~translucent.errors.InputError` there, and the run stops before any task.
    """
    from ...backend import variant

    return variant()


#: glibc's malloc in a local worker: one arena, no mmap, no trimming. A worker runs its
#: tasks one after another on one thread; with these, the memory a task frees stays in the
#: heap for the next one, where by default every array over 32 MiB is mapped afresh and
#: its pages faulted in again (radiosity's 26 M-entry arrays: half its time was system
#: time, docs/references.md). A worker keeps its largest task's memory until it exits.
WORKER_MALLOC_TUNABLES = {"glibc.malloc.arena_max": "1", "glibc.malloc.mmap_max": "0",
                          "glibc.malloc.trim_threshold": str(1 << 40)}


def worker_environment(threads: int) -> dict[str, str]:
    """Environment of a local worker process: its thread pools sized to its ``threads``.

    Dask's own default keeps BLAS to one thread but leaves numba's pool at the machine's
    core count (every worker's ``parallel=True`` kernels then fight for the same cores)
    and sets ``MALLOC_TRIM_THRESHOLD_``, which turns off glibc's adaptive mmap threshold:
    every large temporary array is then mapped and faulted in afresh. Both showed as
    system time in the radiosity precomputation (docs/references.md, "The time of a
    fresh report"). ``GLIBC_TUNABLES`` adds :data:`WORKER_MALLOC_TUNABLES` to those this
    process has (its own settings of the same tunables win); other C libraries ignore it.

    Parameters
    ----------
    threads : int
        Threads per worker.

    Returns
    -------
    dict of str to str
        Variables set in each worker process before it starts.
    """
    count = str(max(1, int(threads)))
    environment = {name: count for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS",
                                            "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS")}
    own = [item for item in os.environ.get("GLIBC_TUNABLES", "").split(":") if "=" in item]
    named = {item.split("=", 1)[0] for item in own}
    added = [f"{name}={value}" for name, value in WORKER_MALLOC_TUNABLES.items()
             if name not in named]
    environment["GLIBC_TUNABLES"] = ":".join(own + added)
    return environment


def timed_call(function: Callable[..., Any], *args) -> tuple[Any, float, int]:
    """Run ``function(*args)``; return its result, its wall time in seconds and the process.

    The time is taken where the task runs (a worker), so it leaves out the scheduling and
    the transfer of the result.
    """
    import time

    started = time.perf_counter()
    result = function(*args)
    return result, time.perf_counter() - started, os.getpid()


def _finished(result: Any) -> None:
    """Return None once ``result`` exists: a marker that moves no data between workers."""
    return None


def _after(function: Callable[..., Any], marker: None, *args) -> Any:
    """Run ``function(*args)``; ``marker`` only orders the task after another one."""
    return function(*args)


def run_tasks(function: Callable[..., Any], arguments: Iterable[Sequence[Any]], *,
              scheduler: str | None = None, local: bool = False, progress: bool = True,
              workers: int = 2, timed: bool = False,
              groups: Sequence[Any] | None = None,
              on_result: Callable[[int, Any], None] | None = None) -> list[Any]:
    """Run ``function(*args)`` for each ``args`` in ``arguments``; results in the same order.

    Parameters
    ----------
    function : callable
        Must be importable by the workers (a module-level function).
    arguments : iterable of sequences
        One argument tuple per task.
    scheduler : str, optional
        Dask scheduler address; None runs a local process cluster.
    local : bool
        Run serially in this process (no Dask at all): the baseline the distributed run is
        checked against, and the fallback for a single task.
    progress : bool
        A progress bar over finished tasks.
    workers : int
        Local cluster size.
    timed : bool
        Return, for each task, ``(result, seconds, process id)`` of :func:`timed_call`.
    groups : sequence, optional
        A key per task (None: no group). The first task of each group runs before the rest
        of its group, which wait for it to finish; the first tasks of all groups go first.
        For tasks that compile the same numba kernels: the first compiles them into the
        on-disk cache and the others, on any local worker, load them (two workers that
        start one method at once each compile it, docs/references.md).
    on_result : callable, optional
        Called in this process as ``on_result(position, result)`` for each task as its
        result arrives (in order of completion; serially, in order), while the other
        tasks run on: work on finished results then fills the workers' idle time.
    """
    from ...progress import progress_bar

    arguments = [tuple(args) for args in arguments]
    if groups is not None and len(groups) != len(arguments):
        raise ValueError(f"{len(groups)} groups for {len(arguments)} tasks")
    if timed:
        arguments = [(function, *args) for args in arguments]
        function = timed_call
    if local or (scheduler is None and len(arguments) <= 1):
        results = []
        bar = progress_bar(arguments, enabled=progress, terminal_only=False)
        for position, args in enumerate(bar):
            results.append(function(*args))
            if on_result is not None:
                on_result(position, results[-1])
        return results
    from dask.distributed import as_completed

    # the bar starts with the cluster, whose workers take seconds to start
    with progress_bar(total=len(arguments), enabled=progress, terminal_only=False) as bar, \
            dask_client(scheduler, workers=workers) as client:
        bar.set_postfix_str("starting the workers")
        # each worker process imports Mitsuba and sets its variant once, before any task:
        # a worker's threads must not race through the first import
        client.run(prepare_worker)
        bar.set_postfix_str("")
        futures = _submit(client, function, arguments, groups)
        index = {future.key: position for position, future in enumerate(futures)}
        results: list[Any] = [None] * len(futures)
        for future in as_completed(futures):
            position = index[future.key]
            results[position] = future.result()
            bar.update()
            if on_result is not None:
                on_result(position, results[position])
    return results


def _submit(client, function, arguments: list[tuple], groups) -> list:
    """Submit the tasks, each group's first one ahead of everything and the rest after it."""
    if groups is None:
        return [client.submit(function, *args, pure=False) for args in arguments]
    firsts: dict[Any, int] = {}
    for position, group in enumerate(groups):
        if group is not None:
            firsts.setdefault(group, position)
    futures: list[Any] = [None] * len(arguments)
    markers = {}
    for group, position in firsts.items():
        futures[position] = client.submit(function, *arguments[position], pure=False)
        markers[group] = client.submit(_finished, futures[position], pure=False)
    for position, (args, group) in enumerate(zip(arguments, groups, strict=True)):
        if futures[position] is not None:
            continue
        if group is None:
            futures[position] = client.submit(function, *args, pure=False)
        else:
            futures[position] = client.submit(_after, function, markers[group], *args,
                                              pure=False)
    return futures
