import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import total_diffuse_reflectance
from translucent.reports.distributed import dask_client, run_tasks

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


def test_bad_scheduler_address():
    with pytest.raises(InputError, match="--scheduler"):
        run_tasks(_sweep_point, ARGUMENTS, scheduler="not an address", progress=False)
