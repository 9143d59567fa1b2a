import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import total_diffuse_reflectance
from translucent.reports.report.distributed import dask_client, run_tasks

# the workers import the task by name: it must live in the package, not in this file
_sweep_point = total_diffuse_reflectance

ARGUMENTS = [(sa, 1.0, eta) for sa in (0.001, 0.01, 0.1, 1.0) for eta in (1.0, 1.3, 1.5)]


def test_local_cluster_on_loopback_gives_the_numbers_of_the_local_run():
    serial = run_tasks(_sweep_point, ARGUMENTS, local=True, progress=False)
    with dask_client(workers=2) as client:
        address = client.scheduler.address
        assert address.startswith("tcp://127.0.0.1")
        assert len(client.scheduler_info()["workers"]) == 2
        distributed = run_tasks(_sweep_point, ARGUMENTS, scheduler=address, progress=False)
    assert [float(v) for v in distributed] == [float(v) for v in serial]
    assert np.all(np.diff([serial[i] for i in range(0, 12, 3)]) < 0)


def test_each_result_is_handed_over_as_it_arrives():
    import time

    serial_calls = []
    serial = run_tasks(_sweep_point, ARGUMENTS, local=True, progress=False,
                       on_result=lambda position, result: serial_calls.append((position, result)))
    assert serial_calls == list(enumerate(serial))  # serially: in order, each once
    # on workers: each position once, in whatever order the tasks finish
    calls = []
    with dask_client(workers=2) as client:
        results = run_tasks(time.sleep, [(0.01,)] * 5, scheduler=client.scheduler.address,
                            progress=False,
                            on_result=lambda position, result: calls.append(position))
    assert results == [None] * 5 and sorted(calls) == [0, 1, 2, 3, 4]


def test_a_local_cluster_leaves_this_process_environment_as_it_was(monkeypatch):
    import os

    # numba re-reads NUMBA_NUM_THREADS at every compilation and refuses a change once its
    # pool runs: the nanny must not leave the workers' value in this process
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")  # a user's own setting: kept, and passed on
    with dask_client(workers=1, threads_per_worker=1) as client:
        worker = client.run(lambda: {name: os.environ.get(name)
                                     for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS")})
        assert list(worker.values()) == [{"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "2"}]
    assert "NUMBA_NUM_THREADS" not in os.environ and os.environ["OMP_NUM_THREADS"] == "2"


def test_a_workers_freed_memory_is_reused_without_faulting_its_pages_again(monkeypatch):
    import platform

    from translucent.reports.report.distributed import WORKER_MALLOC_TUNABLES, worker_environment

    if platform.libc_ver()[0] != "glibc":
        pytest.skip("GLIBC_TUNABLES is glibc's")
    # a setting of the user's own is kept, ours are added
    monkeypatch.setenv("GLIBC_TUNABLES", "glibc.malloc.arena_max=2")
    tunables = worker_environment(1)["GLIBC_TUNABLES"].split(":")
    assert "glibc.malloc.arena_max=2" in tunables and "glibc.malloc.mmap_max=0" in tunables
    monkeypatch.delenv("GLIBC_TUNABLES")
    assert sorted(worker_environment(1)["GLIBC_TUNABLES"].split(":")) == sorted(
        f"{k}={v}" for k, v in WORKER_MALLOC_TUNABLES.items())
    def _refaulted_pages():
        # a local function: pickled by value for the worker
        import resource

        first = bytearray(1 << 28)
        del first
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        second = bytearray(1 << 28)
        del second
        return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before

    # 256 MiB freed and taken again, on the worker's task thread: 65536 pages faulted in
    # afresh under glibc's defaults (this process), none in a worker
    here = _refaulted_pages()
    with dask_client(workers=1) as client:
        there = client.submit(_refaulted_pages, pure=False).result()
    assert here > 60000 and there < 1000


def test_bad_scheduler_address():
    with pytest.raises(InputError, match="--scheduler"):
        run_tasks(_sweep_point, ARGUMENTS, scheduler="not an address", progress=False)


def test_workers_of_two_threads_each_set_the_variant_once_before_any_task():
    # eight tasks that each need Mitsuba, on fresh workers of two threads: none may see a
    # half-imported Mitsuba (the first import races between a worker's threads otherwise)
    from translucent.backend import variant

    with dask_client(workers=2, threads_per_worker=2) as client:
        infos = client.scheduler_info()["workers"].values()
        assert [info["nthreads"] for info in infos] == [2, 2]
        found = run_tasks(variant, [()] * 8, scheduler=client.scheduler.address,
                          progress=False)
    assert found == [variant()] * 8


def test_the_variant_is_chosen_once_under_concurrent_first_calls():
    import subprocess
    import sys

    program = (
        "import threading\n"
        "from translucent import backend\n"
        "found, errors = [], []\n"
        "def call():\n"
        "    try:\n"
        "        found.append(backend.variant())\n"
        "    except Exception as error:\n"
        "        errors.append(repr(error))\n"
        "threads = [threading.Thread(target=call) for _ in range(8)]\n"
        "[t.start() for t in threads]; [t.join() for t in threads]\n"
        "assert not errors, errors\n"
        "assert len(set(found)) == 1 and len(found) == 8, found\n"
        "print(found[0])\n")
    result = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() in ("llvm_ad_rgb", "cuda_ad_rgb", "scalar_rgb")


def test_a_groups_first_task_finishes_before_the_rest_of_its_group_starts():
    import time

    # two workers, two one-second tasks of one group and one of none: the group's second
    # task waits for its first, so the three take two seconds, not one
    arguments = [(1.0,), (1.0,), (0.1,)]
    with dask_client(workers=2) as client:
        address = client.scheduler.address
        started = time.perf_counter()
        timed = run_tasks(time.sleep, arguments, scheduler=address, progress=False,
                          timed=True, groups=["a", "a", None])
        grouped = time.perf_counter() - started
        started = time.perf_counter()
        run_tasks(time.sleep, arguments[:2], scheduler=address, progress=False)
        together = time.perf_counter() - started
    assert grouped >= 2.0 > together
    assert [result for result, _, _ in timed] == [None] * 3
    # each task's own time, taken on its worker: at least what it slept
    assert all(seconds >= asked for (_, seconds, _), (asked,) in zip(timed, arguments, strict=True))


def test_groups_must_match_the_tasks():
    with dask_client(workers=1) as client, pytest.raises(ValueError, match="2 groups for 3"):
        run_tasks(_sweep_point, ARGUMENTS[:3], scheduler=client.scheduler.address,
                  progress=False, groups=["a", "a"])
    with pytest.raises(ValueError, match="2 groups for 3"):  # serial runs check them too
        run_tasks(_sweep_point, ARGUMENTS[:3], local=True, progress=False, groups=["a", "a"])
