"""``parallel_njit``: parallel kernels with several numba threads, serial ones with one."""

import json
import os
import subprocess
import sys

import numba
import numpy as np
import pytest
from translucent.compiled import SERIAL_SUFFIX, parallel_compiles, parallel_njit

# run in a fresh process with a given thread count: the kernel's options and name, a
# prange reduction and a real kernel's output
_PROBE = """
import json, numba, numpy as np
from translucent.compiled import parallel_njit
from translucent.fast.radiosity.kernels import compiled_scatter_product, scatter_product
from scipy import sparse

@parallel_njit(cache=False)
def total(values):
    out = 0.0
    for i in numba.prange(len(values)):
        out += values[i] * values[i]
    return out

# a kernel that asks numba for its thread, run off the main thread (as a Dask worker's
# task): loaded from numba's cache in a one-thread process, it needs the threading layer
import threading
from translucent.fast.sparse_transport import _blocks_product_scalar
product = np.zeros((1, 1), np.float32)
worker = threading.Thread(target=_blocks_product_scalar, args=(
    np.array([0, 2]), np.array([0, 1], np.int32), np.ones(2, np.int16),
    np.ones((1, 1), np.float32), np.array([2.0, 3.0], np.float32),
    np.zeros((1, 1, 2), np.float32), product))
worker.start()
worker.join()

rng = np.random.default_rng(7)
operator = sparse.random(50, 9, density=0.3, random_state=3, format="csr")
out = np.zeros((80, 3))
scatter_product(operator, rng.normal(size=(9, 3)), rng.permutation(80)[:50], out)
print(json.dumps({"parallel": total.targetoptions.get("parallel", False),
                  "name": total.py_func.__qualname__,
                  "scatter_name": compiled_scatter_product().py_func.__qualname__,
                  "total": total(np.arange(1000.0)), "scatter": out.tolist(),
                  "thread_product": float(product[0, 0])}))
"""


def _probe(threads: int, numba_cache) -> dict:
    environment = {**os.environ, "NUMBA_NUM_THREADS": str(threads),
                   "NUMBA_CACHE_DIR": str(numba_cache)}
    found = subprocess.run([sys.executable, "-c", _PROBE], env=environment, check=True,
                           capture_output=True, text=True, timeout=300)
    return json.loads(found.stdout.strip().splitlines()[-1])


def test_the_choice_follows_this_process_thread_count():
    @parallel_njit(cache=False)
    def square(values):
        for i in numba.prange(len(values)):
            values[i] = values[i] * values[i]

    values = np.arange(5.0)
    square(values)
    assert values.tolist() == [0.0, 1.0, 4.0, 9.0, 16.0]
    assert parallel_compiles() == (numba.config.NUMBA_NUM_THREADS > 1)
    assert square.targetoptions.get("parallel", False) == parallel_compiles()
    assert square.py_func.__qualname__.endswith(SERIAL_SUFFIX) == (not parallel_compiles())


def test_one_thread_compiles_serial_kernels_under_their_own_name_with_the_same_results(
        tmp_path):
    # the second one-thread process loads the serial kernels from numba's cache
    serial, parallel, loaded = _probe(1, tmp_path), _probe(2, tmp_path), _probe(1, tmp_path)
    assert loaded == serial
    assert serial["thread_product"] == parallel["thread_product"] == 5.0
    assert serial["parallel"] is False and parallel["parallel"] is True
    # numba names its cache files by the qualified name: the two never load each other's
    assert serial["name"].endswith(SERIAL_SUFFIX) and not parallel["name"].endswith(
        SERIAL_SUFFIX)
    assert serial["scatter_name"] == parallel["scatter_name"] + SERIAL_SUFFIX
    assert serial["total"] == parallel["total"] == float(np.sum(np.arange(1000.0) ** 2))
    assert serial["scatter"] == parallel["scatter"]


def test_parallel_is_not_an_option_it_takes():
    with pytest.raises(TypeError, match="decides `parallel` itself"):
        parallel_njit(parallel=False)
