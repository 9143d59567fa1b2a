"""Two processes asking for one cache entry: the first makes it, the second waits and reads it."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from translucent.cache import Cache

#: Each pass is slowed by this much, so that the two processes surely overlap.
PASS_DELAY_SECONDS = 0.5

WORKER = textwrap.dedent(f"""
    import importlib, os, sys, time, pathlib
    render_module = importlib.import_module("translucent.reference.render")
    from translucent.fast.conformance import tiny_sphere_text
    from translucent.scenes import loads_scene

    log, go = pathlib.Path(sys.argv[1]), pathlib.Path(sys.argv[2])
    scene = loads_scene(tiny_sphere_text(size=8))
    original = render_module.render_sample

    def counted(*args, **kwargs):
        with open(log, "a") as handle:
            handle.write(f"{{os.getpid()}}\\n")
        time.sleep({PASS_DELAY_SECONDS})
        return original(*args, **kwargs)

    render_module.render_sample = counted
    while not go.exists():
        time.sleep(0.01)
    image = render_module.{{call}}
    print(repr(float(image.rgb.mean())))
""")

CALLS = {
    "render": "render(scene, spp=2, passes=2, progress=False)",
    "render_to_target": "render_to_target(scene, target_rse=1e-6, spp=2, min_passes=2, "
                        "max_passes=2, progress=False)",
}


def _environment(tmp_path):
    return {**os.environ, "TRANSLUCENT_CACHE": str(tmp_path / "cache")}


@pytest.mark.parametrize("call", sorted(CALLS))
def test_two_concurrent_renders_of_one_reference_render_it_once(tmp_path, call):
    script = tmp_path / "worker.py"
    script.write_text(WORKER.replace("{call}", CALLS[call]))
    log, go = tmp_path / "passes.log", tmp_path / "go"
    workers = [subprocess.Popen([sys.executable, str(script), str(log), str(go)],
                                env=_environment(tmp_path), stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True) for _ in range(2)]
    time.sleep(3.0)  # both imported and waiting
    go.touch()
    outputs = [worker.communicate(timeout=300) for worker in workers]
    assert all(worker.returncode == 0 for worker in workers), outputs
    renderers = set(log.read_text().split())
    assert len(renderers) == 1, "both processes rendered the reference"
    means = {out for out, _ in outputs}
    assert len(means) == 1  # the waiting one read the same image
    assert sum("waiting for another process" in err for _, err in outputs) <= 1


def test_a_killed_holder_releases_the_lock(tmp_path):
    holder = subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(f"""
            import time
            from translucent.cache import Cache
            with Cache("reference", root={str(tmp_path)!r}).locked("ab" * 32):
                print("held", flush=True)
                time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "held"
    os.kill(holder.pid, signal.SIGKILL)
    holder.wait(timeout=30)
    started = time.perf_counter()
    with Cache("reference", root=tmp_path).locked("ab" * 32):
        pass
    assert time.perf_counter() - started < 5.0
