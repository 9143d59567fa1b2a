"""Running the installed ``translucent`` console script, as a user types it.

The smoke tests of every command and every benchmark run the real entry point in a
subprocess (not ``main()`` in the test's process): the script pip installed, its imports,
its exit code and its standard streams are what is checked.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from translucent.materials.profiles import HETEROGENEOUS_RULES

#: Seconds after which a smoke run is a failure (a hang, not a slow machine).
TIMEOUT_SECONDS = 300


def console_script() -> Path:
    """Return the installed ``translucent`` script of the Python running the tests."""
    beside = Path(sys.executable).with_name("translucent")
    found = beside if beside.is_file() else shutil.which("translucent")
    assert found, "the translucent console script is not installed beside " + sys.executable
    return Path(found)


def run_command(*arguments, cwd, env=None, timeout=TIMEOUT_SECONDS):
    """Run ``translucent ARGUMENTS`` in ``cwd``; return the CompletedProcess (text).

    The cache is the test session's (``TRANSLUCENT_CACHE``), shared by every smoke run;
    numba keeps the test processes' thread count, so that the runs load the kernels those
    compiled (a one-thread process compiles serial kernels of its own, seconds each).
    """
    environment = {**os.environ, **(env or {})}
    environment.pop("TRANSLUCENT_OPTIONS", None)
    # each run would compile every module it imports again where bytecode is not written
    environment.pop("PYTHONDONTWRITEBYTECODE", None)
    return subprocess.run([str(console_script()), *map(str, arguments)], cwd=cwd,
                          env=environment, capture_output=True, text=True, timeout=timeout)


def run_ok(*arguments, cwd, codes=(0,), env=None):
    """Run a command; check its exit code is one of ``codes`` and that nothing crashed."""
    result = run_command(*arguments, cwd=cwd, env=env)
    assert result.returncode in codes, explain(result)
    assert "Traceback" not in result.stderr + result.stdout, explain(result)
    return result


def listed(*arguments) -> list[str]:
    """Return the sub-commands ``translucent ARGUMENTS --help`` lists."""
    shown = subprocess.run([str(console_script()), *arguments, "--help"], capture_output=True,
                           text=True, check=True, timeout=TIMEOUT_SECONDS).stdout
    block = shown.split("positional arguments:", 1)[1].split("options:", 1)[0]
    return re.findall(r"^    ([a-z][a-z0-9_-]*)(?:\s|$)", block, flags=re.MULTILINE)


def explain(result) -> str:
    """The end of a run's streams, for an assertion's message."""
    return f"exit {result.returncode}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}"


# ------------------------------------------------------------------ benchmarks


def finite_number(value) -> bool:
    """Whether ``value`` is a real, finite number (not a bool)."""
    import math

    return isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value)


def _area_lights(figures):
    scene = figures["scenes"][0]
    assert scene["scene"] == "cornell_block" and scene["objects"] == ["block"]
    assert [row["points"] for row in scene["rows"]] == [1, 4]
    assert scene["rows"][0]["time_ratio"] == 1.0
    # one point per area light is not the area light: resolved against the reference
    assert all(row["relative_mse"] > scene["noise_floor"]["relative_mse"]
               for row in scene["rows"])
    return scene["rows"], ("relative_mse", "hdr_flip", "frame_seconds")


def _scaling(figures):
    scene = figures["scenes"][0]
    assert scene["scene"] == "sphere" and figures["sizes"] == [96, 192]
    rows = scene["rows"]
    assert [(row["method"], row["size"]) for row in rows] == [("splatting", 96),
                                                             ("splatting", 192)]
    assert all(row["status"] == "ok" for row in rows)
    # the 192 px image, box-filtered to 96 px, is scored against the same reference: no
    # worse than the 96 px one (an image out of register would be far worse), and closer
    # by about the half of the error that sampling pixel centres leaves (docs/scaling.md)
    assert 0.25 * rows[0]["relative_mse"] < rows[1]["relative_mse"] < rows[0]["relative_mse"]
    # path tracing at 192 px costs more than at 96 px for the same samples
    assert rows[1]["path_tracing_spp_seconds"]["4"] > rows[0]["path_tracing_spp_seconds"]["4"]
    assert [row["vertices"] for row in figures["meshes"]["rows"]] == [642]
    return rows + figures["meshes"]["rows"], ("speedup", "relative_mse", "frame_seconds")


def _brdf_pca(figures):
    return [figures["performance"]], ("precompute_seconds", "edit_fps", "relight_fps")


def _fitting(figures):
    rows = [figures["dipole"], figures["walk"], figures["subedit"]]
    assert all(chain["steps"] <= 200 for chain in (figures["dipole"], figures["walk"],
                                                  *figures["subedit"]["chains"]))
    return rows, ("seconds",)


def _method_rows(figures):
    return [row["methods"][name] for row in figures["rows"] for name in figures["methods"]], \
        ("relative_mse", "hdr_flip", "frame_seconds")


def _heterogeneous(figures):
    assert [row["sweep"] for row in figures["rows"]] == ["contrast", "cell size"]
    assert all(row["methods"][name]["status"] == "ok" for row in figures["rows"]
               for name in figures["methods"])
    # each rule rendered exactly beside the reference, each method split against its own
    assert all(set(row["rules"]) == set(HETEROGENEOUS_RULES) for row in figures["rows"])
    # noise-discounted: may fall below 0 at a quick run's few samples, never NaN
    assert all(math.isfinite(row["methods"][name]["approximation"]["relative_mse"])
               for row in figures["rows"] for name in figures["methods"])
    return _method_rows(figures)


def _model_error(figures):
    assert figures["media"] == ["Skin1"] and figures["complete"] is True
    assert all(row["methods"][name]["status"] == "ok" for row in figures["rows"]
               for name in figures["methods"])
    return _method_rows(figures)


def _profiles(figures):
    rows = [result for row in figures["rows"] for result in row["profiles"].values()
            if isinstance(result, dict) and "total" in result]
    return rows, ("total",)


def _prt(figures):
    return figures["configurations"], ("relight_fps", "edit_fps", "bandwidth_fraction",
                                       "edit_over_relight_speed", "storage_mb")


def _radiosity(figures):
    rows = [figures["precomputation"], figures["relighting"], figures["translucency change"],
            figures["transfer"], *figures["sampling"].values()]
    return rows, ("seconds", "frame fps", "with solve fps", "relight fps")


def _reference(figures):
    assert figures["spp"] == 1 and figures["passes"] == 2
    assert len(figures["ratios"]) == 1 and figures["median_ratio"] > 0
    assert len(figures["cpu_ratios"]) == 1 and figures["median_cpu_ratio"] > 0
    return [figures], ("median_ratio", "median_cpu_ratio", "load_seconds")


def _splatting(figures):
    return list(figures["results"].values()), ("fps", "relative error",
                                               "speed-up over no acceleration")


def _tradeoff(figures):
    scene = figures["scenes"]["sphere"]
    points = [point for entry in scene["methods"].values() if entry["status"] == "ok"
              for ladder in entry["ladders"].values() for point in ladder]
    assert {name for name, entry in scene["methods"].items() if entry["status"] == "ok"} \
        == {"radiosity", "splatting"}
    return scene["path_tracing"] + points, ("relative_mse",)


#: Each benchmark's check of its quick JSON: top-level keys, and a function returning the
#: rows (after its own checks) and the figures of which each row must hold at least one,
#: finite. A benchmark ``translucent bench --help`` lists and this does not name fails.
BENCHMARKS = {
    "area_lights": ({"scenes"}, _area_lights),
    "brdf_pca": ({"performance"}, _brdf_pca),
    "fitting": ({"material", "size", "baseline_seconds", "dipole", "walk", "subedit"},
                _fitting),
    "heterogeneous": ({"pair", "reference", "methods", "rows", "complete"}, _heterogeneous),
    "model_error": ({"reference", "methods", "media", "rows", "complete"}, _model_error),
    "profiles": ({"settings", "profiles", "rows", "summary", "timing"}, _profiles),
    "prt": ({"bandwidth", "configurations", "shadow_rays", "targets"}, _prt),
    "radiosity": ({"baseline seconds", "precomputation", "relighting", "translucency change",
                   "transfer", "sampling"}, _radiosity),
    "reference": ({"suite_seconds", "plain_seconds", "ratios", "median_ratio"}, _reference),
    "scaling": ({"scenes", "meshes", "sizes", "spp"}, _scaling),
    "splatting": ({"results", "validation", "materials"}, _splatting),
    "tradeoff": ({"scenes"}, _tradeoff),
}


#: What a benchmark's quick run prints, beside its JSON.
PRINTED = {"reference": ("median wall-clock ratio", "median CPU-time ratio"),
           "area_lights": ("cornell_block: splatting on block",)}


def check_quick_bench(name, folder):
    """Run ``translucent bench NAME --quick`` in ``folder``; check its exit and its JSON."""
    import json

    out = Path(folder) / f"{name}.json"
    result = run_command("bench", name, "--quick", "--no-progress", "--json", out, cwd=folder)
    assert result.returncode == 0, explain(result)
    assert "Traceback" not in result.stderr, explain(result)
    assert f"quick run of bench {name}" in result.stdout
    for words in PRINTED.get(name, ()):
        assert words in result.stdout, explain(result)
    figures = json.loads(out.read_text())
    keys, rows_of = BENCHMARKS[name]
    assert figures["quick"] is True
    assert keys <= set(figures), f"{name}: {sorted(keys - set(figures))} missing"
    rows, wanted = rows_of(figures)
    assert rows, f"{name}: no rows"
    for row in rows:
        assert any(finite_number(row.get(key)) for key in wanted), \
            f"{name}: a row without any of {wanted}: {sorted(row)}"
    return figures


#: The benchmarks in two test files, so that the two test processes share them (the tests
#: run ``--dist loadfile``): those that render references, and the others.
QUICK_RENDERING = ("reference", "tradeoff", "model_error", "heterogeneous", "area_lights",
                   "scaling")
#: Benchmarks whose quick run is the fixture of their own test file, which reads its output.
QUICK_ELSEWHERE = {"profiles": "test_bench_profiles.py"}
QUICK_OTHERS = tuple(sorted(set(BENCHMARKS) - set(QUICK_RENDERING) - set(QUICK_ELSEWHERE)))
