"""The CUDA splatting kernels (numba.cuda): run in numba's CUDA simulator on machines
without a GPU, in a separate process (the simulator is chosen when numba.cuda is first
imported), against the CPU kernels on the same inputs. The frame (64 x 48, 16^2
irradiance) is the smallest of the heterogeneous scene that splats at all three levels."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.fast import splatting
from translucent.fast.splatting import backend_cuda as splatting_cuda
from translucent.scenes import load_scene

#: The CUDA kernels evaluate the CPU kernel's float32 terms and differ by the exponential
#: (the simulator's float64 exp or a GPU's __expf, a few 1e-6 relative, against the CPU's
#: float32 polynomial, below 1e-7), by fused multiply-adds and by the sums (float64 in the
#: order the binning threads arrive, against float32 in sample order, about 1e-7 relative
#: over a few hundred terms): 1e-5 of the frame's largest value bounds all of them.
FRAME_RTOL = 1e-5

_COMPARE = textwrap.dedent("""
    import json
    import numpy as np
    from translucent.fast import splatting
    from translucent.scenes import load_scene
    from translucent.reports.bench.splatting import with_size

    scene = with_size(load_scene("heterogeneous"), 64, 48)
    out = {}
    for knobs in ({}, {"multiresolution": False}):
        images = [splatting.precompute(scene, irradiance_resolution=16, backend=backend,
                                       **knobs).render() for backend in ("numba", "cuda")]
        out[str(knobs)] = {
            "largest": float(np.abs(images[0].rgb).max()),
            "difference": float(np.abs(images[0].rgb - images[1].rgb).max()),
            "pairs": [image.metadata["notes"]["pairs in range per level"]
                      for image in images]}
    camera_buffer, model, views, material, _ = splatting.precompute(
        scene, irradiance_resolution=16).buffers()
    samples = splatting.IrradianceSamples.concatenate(
        splatting.select_irradiance_samples(
            [splatting.irradiance_mipmap(view.buffer, view.flux, view.cosine, 1)
             for view in views][0], material, mm_per_unit=scene.mm_per_unit, z0=1.0,
            alpha=1.0, adaptive=False) for _ in range(1))
    gathered = [splatting.brute_force_exitance(samples, camera_buffer, material,
                                               mm_per_unit=scene.mm_per_unit, backend=b)
                for b in ("numba", "cuda")]
    out["gather"] = {"largest": float(np.abs(gathered[0]).max()),
                     "difference": float(np.abs(gathered[0] - gathered[1]).max())}
    print(json.dumps(out))
""")


@pytest.fixture(scope="module")
def simulated():
    """CPU and CUDA (simulated) results on the same tiny heterogeneous frames."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    result = subprocess.run([sys.executable, "-c", _COMPARE], env=env, capture_output=True,
                            text=True, timeout=600, check=False)
    assert result.returncode == 0, result.stderr[-3000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


# the simulator takes about 25 s: slow tier (the refusals below stay in the fast tier)
@pytest.mark.slow
@pytest.mark.parametrize("setting", ["{}", "{'multiresolution': False}"])
def test_cuda_frame_equals_the_cpu_kernel(simulated, setting):
    frame = simulated[setting]
    assert frame["largest"] > 0
    assert frame["difference"] <= FRAME_RTOL * frame["largest"]
    # both evaluate the same pairs, at every level the setting splats
    assert all(count > 0 for count in frame["pairs"][0])
    assert frame["pairs"][0] == frame["pairs"][1]


@pytest.mark.slow
def test_cuda_brute_force_equals_the_cpu_gather(simulated):
    gather = simulated["gather"]
    assert gather["largest"] > 0
    assert gather["difference"] <= FRAME_RTOL * gather["largest"]


@pytest.mark.skipif(splatting_cuda.available(), reason="a CUDA device is present")
def test_cuda_backend_without_a_gpu_says_so():
    scene = load_scene("heterogeneous")
    state = splatting.precompute(scene, irradiance_resolution=8, backend="cuda")
    with pytest.raises(InputError, match="backend = 'cuda'.*needs a CUDA GPU"):
        state.render()
    assert np.isfinite(splatting.precompute(scene, irradiance_resolution=8).render().rgb).all()


def test_cuda_backend_that_cannot_compile_says_why(monkeypatch):
    # a GPU that numba.cuda sees but whose toolchain fails (numba-cuda against a numpy it
    # predates, say): the message names the cause instead of a traceback deep in numba
    monkeypatch.setattr(splatting_cuda, "available", lambda: True)
    monkeypatch.setattr(splatting_cuda, "_compile_problem",
                        lambda: "AttributeError: module 'numpy' has no attribute 'row_stack'")
    with pytest.raises(InputError, match="cannot compile a kernel.*row_stack"):
        splatting_cuda.gather_samples(np.zeros((1, 3)), np.zeros((3, 1), np.float32),
                                      np.zeros(1, np.int32), np.zeros((1, 1, 6), np.float32),
                                      np.float32(1.0), np.zeros((3, 1), np.float32),
                                      np.zeros(1, np.int32), np.zeros((3, 1), np.float32))
