"""PRT of Wang et al. 2008: precomputation, storage, relighting and editing rates, error.

``translucent bench prt`` precomputes a translucent sphere of about 20k vertices (10 mm
radius, Skin1, one point light) with about 16k and 64k illumination samples, then runs a
scripted session: a sweep of point-light positions (relighting) and a sweep of materials
(editing). It prints and writes as JSON:

* precomputation time (first pass, spatial pass) and storage in MB;
* relighting frames per second (whole frame: shadowed irradiance at the samples, Haar
  transform, sparse product, editing step, image) and the product alone;
* editing frames per second (projection onto the basis, weighted sum, image);
* the bytes a relighting frame reads, against this machine's memory bandwidth measured in
  the same run (a large numpy copy and a large numpy sum): the product's rate as a ratio to
  the bandwidth bound;
* the error against Eq. 1 evaluated directly (exact R_d, same samples) on a random subset
  of vertices;
* the cost of the shadow rays of one relighting frame: milliseconds per batch of 16k and
  64k shadow rays (illumination samples towards the light) through each ray engine of
  :mod:`translucent.scenes.raycast` (Embree through ``embreex``, and Mitsuba);
* the load average of the machine beside every figure (the machine is shared).

Wall-clock figures are shared-machine figures; each is printed beside the process CPU time,
which other jobs on the machine disturb less. ``--sweep`` adds the error against the number
of basis terms K and against the wavelet terms kept (small sphere, both parameterisations of
the basis), written as JSON and a PNG. The model error against Mitsuba volumetric path
tracing for the 12 measured media is ``translucent bench model_error``
(:mod:`translucent.reports.bench.model_error`).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from ...atomic import atomic_save_figure, check_output_file
from ...cache import environment_variable, private_cache
from ...errors import check_count
from ...fast import prt
from ...materials import Dipole, measured_medium
from ...scenes import Camera, PointLight, Scene, SceneObject, geometry_image, icosphere
from . import count_list, is_quick, steps_bar, write_figures

#: Targets of the task on this 2-core machine.
TARGET_EDIT_FPS = 500.0
TARGET_RELIGHT_FPS = 30.0
TARGET_BANDWIDTH_FRACTION = 0.5

#: The bench object: a sphere of this radius (mm), lit from the upper right.
RADIUS_MM = 10.0
LIGHT_DISTANCE = 6.4


#: ``--quick``: a 642-vertex sphere, 256 samples, a 17 x 17 geometry image, a few frames.
QUICK_ARGUMENTS = {"vertices": 642, "samples": "256", "spatial_rows": 17, "frames": 2,
                   "edits": 3, "error_vertices": 16, "size": 16}


def add_arguments(parser):
    """Options of ``translucent bench prt``.

    ``--quick`` also measures the bandwidth on 8 MB and shadow rays in one batch of 1024.
    """
    parser.add_argument("--vertices", type=int, default=20000,
                        help="vertex count of the icosphere (default 20000: 20252 vertices)")
    parser.add_argument("--samples", default="16384,65536",
                        help="comma-separated illumination sample counts (4 x 4^n)")
    parser.add_argument("--spatial-rows", type=int, default=145,
                        help="side of the geometry-image sphere benchmarked with spatial "
                             "compression at the first sample count (0: skip; default 145, "
                             "21025 vertices)")
    parser.add_argument("--frames", type=int, default=12,
                        help="relighting frames per configuration (default 12)")
    parser.add_argument("--edits", type=int, default=300,
                        help="editing frames per configuration (default 300)")
    parser.add_argument("--error-vertices", type=int, default=400,
                        help="vertices checked against the brute force (default 400)")
    parser.add_argument("--size", type=int, default=128, help="image side (default 128)")
    parser.add_argument("--sweep", action="store_true",
                        help="error against K and against the wavelet terms kept")
    parser.add_argument("--png", default=None,
                        help="error-sweep figure (default bench_prt_sweep.png)")


# ---------------------------------------------------------------------- measurements


def _timed(function, repeats: int) -> tuple[float, float]:
    """Best wall-clock and process-CPU seconds of ``repeats`` calls."""
    wall, cpu = [], []
    for _ in range(repeats):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        function()
        wall.append(time.perf_counter() - start_wall)
        cpu.append(time.process_time() - start_cpu)
    return min(wall), min(cpu)


def memory_bandwidth(megabytes: int = 256, repeats: int = 5) -> dict:
    """Measure the memory bandwidth, GB/s: a numpy copy (read + write) and a numpy sum (read).

    Measured with wall-clock and with process CPU time; best of ``repeats``.
    """
    source = np.ones(megabytes * 2**20 // 8)
    target = np.empty_like(source)
    copy_wall, copy_cpu = _timed(lambda: np.copyto(target, source), repeats)
    read_wall, read_cpu = _timed(source.sum, repeats)
    size = source.nbytes / 1e9
    return {"copy_gb_per_s": 2 * size / copy_wall, "copy_gb_per_s_cpu": 2 * size / copy_cpu,
            "read_gb_per_s": size / read_wall, "read_gb_per_s_cpu": size / read_cpu,
            "megabytes": megabytes, "load_average": os.getloadavg()[0]}


def bench_scene(mesh, size: int, material=None) -> Scene:
    """Return the bench sphere: ``mesh`` of radius 1 scaled to 10 mm, Skin1, one point light."""
    material = measured_medium("Skin1") if material is None else material
    return Scene([SceneObject("sphere", mesh, material)],
                 [PointLight([3.0, 4.0, 4.0], 100.0)],
                 Camera([0, 0, 5], [0, 0, 0], fov=30, width=size, height=size),
                 mm_per_unit=RADIUS_MM, name="bench_prt")


def _light_sweep(frames: int) -> list:
    angles = np.linspace(0.0, 2.0 * np.pi, frames, endpoint=False)
    return [[PointLight([LIGHT_DISTANCE * np.cos(a), 4.0, LIGHT_DISTANCE * np.sin(a)], 100.0)]
            for a in angles]


def _material_sweep(edits: int) -> list:
    base = measured_medium("Skin1")
    scales = np.geomspace(0.25, 4.0, edits)
    return [Dipole(base.sigma_a * s, base.sigma_s_prime * (1.5 - 0.25 * np.log2(s)), base.eta)
            for s in scales]


def brute_force_error(state, material, vertex_count: int, seed: int = 0) -> float:
    """Relative L2 of the PRT vertex radiance against Eq. 1 (exact R_d) on random vertices."""
    transfer = state.transfers[0]
    mesh = state.scene.objects[0].mesh
    lights = tuple(state.scene.lights)
    state.relight(transfer, lights, material.eta)
    approximation = state.vertex_radiance(transfer, material)
    chosen = np.random.default_rng(seed).choice(len(mesh.vertices),
                                                min(vertex_count, len(mesh.vertices)),
                                                replace=False)
    irradiance = state.irradiance(transfer, lights, material.eta)
    reference = prt.brute_force_radiance(transfer, mesh.vertices, irradiance, material,
                                         mm_per_unit=state.scene.mm_per_unit,
                                         vertex_indices=chosen)
    return float(np.linalg.norm(approximation[chosen] - reference)
                 / np.linalg.norm(reference))


def _ray_engine(name: str):
    """Route the scene's ray queries through the engine ``name`` for the block."""
    return environment_variable("TRANSLUCENT_RAY_ENGINE", name)


def shadow_ray_timings(mesh, counts=(16384, 65536), repeats: int = 5) -> list[dict]:
    """Milliseconds per batch of shadow rays through each available ray engine.

    The rays of a relighting frame: from ``count`` illumination samples on the bench sphere
    towards its point light (:func:`translucent.scenes.visible`'s rays, any-hit queries).
    Best wall-clock and process-CPU time of ``repeats`` batches after one warm-up, and the
    wall-clock time of that first batch (Mitsuba traces and compiles its kernel then, or
    finds it in Dr.Jit's kernel cache).
    """
    from ...scenes.raycast import embree_available, ray_engine, visible

    scene = bench_scene(mesh, 8)
    light = scene.lights[0].position
    rows = []
    for count in counts:
        samples = prt.illumination_samples(mesh, count, 4, mm_per_unit=RADIUS_MM)
        for name in ("embree", "mitsuba") if embree_available() else ("mitsuba",):
            engine = ray_engine(scene, name)
            with _ray_engine(name):
                start = time.perf_counter()
                seen = visible(scene, samples.positions, light, normals_a=samples.normals)
                first = time.perf_counter() - start
                wall, cpu = _timed(lambda samples=samples: visible(
                    scene, samples.positions, light, normals_a=samples.normals), repeats)
            rows.append({"engine": engine.engine, "rays": count, "ms": 1e3 * wall,
                         "cpu_ms": 1e3 * cpu, "first_call_ms": 1e3 * first,
                         "visible_fraction": float(seen.mean()),
                         "load_average": os.getloadavg()[0]})
    return rows


def bench_configuration(mesh, samples: int, args, bandwidth: dict, label: str) -> dict:
    """Precompute, relight and edit one mesh at one sample count; every figure as a dict."""
    scene = bench_scene(mesh, args.size)
    start_wall, start_cpu = time.perf_counter(), time.process_time()
    with private_cache(prefix="bench_prt_"):
        state = prt.precompute(scene, samples=samples, geometry="half_space")
    precompute_wall = time.perf_counter() - start_wall
    precompute_cpu = time.process_time() - start_cpu
    transfer = state.transfers[0]
    statistics = transfer.statistics
    state.render()  # warm-up: G-buffer, compiled kernels, ray engine
    load_before = os.getloadavg()[0]
    relight_times, relight_cpu_times, stages = [], [], []
    for lights in _light_sweep(args.frames):
        start_wall, start_cpu = time.perf_counter(), time.process_time()
        state.render(lights=lights)
        relight_times.append(time.perf_counter() - start_wall)
        relight_cpu_times.append(time.process_time() - start_cpu)
        stages.append([state.log.seconds["irradiance"], state.log.seconds["transfer product"]])
    relight_wall = float(np.median(relight_times))
    relight_cpu = float(np.median(relight_cpu_times))
    stage = dict(zip(("irradiance", "transfer product"), np.median(stages, axis=0).tolist(),
                     strict=True))
    lights = _light_sweep(1)[0]
    irradiance = state.irradiance(transfer, lights, transfer_eta(state))
    product_wall, product_cpu = _timed(lambda: state.basis_vectors(transfer, irradiance), 5)
    materials = _material_sweep(args.edits)
    edit_times = []
    for material in materials:
        start = time.perf_counter()
        state.render(material=material)
        edit_times.append(time.perf_counter() - start)
    start_cpu = time.process_time()
    for material in materials[: min(50, len(materials))]:
        state.render(material=material)
    edit_cpu = (time.process_time() - start_cpu) / min(50, len(materials))
    edit_wall = float(np.median(edit_times))
    # what the product reads and writes: the stored matrix, E^w (one channel for one-colour
    # lights, as the bench's, else three) and the per-basis vectors, float32
    channels = 1 if prt.single_colour(transfer.samples.to_wavelets(irradiance)) is not None \
        else 3
    frame_bytes = transfer.transfer.nbytes + 4 * channels * (len(transfer.samples)
                                                             + transfer.transfer.rows)
    bound_seconds = frame_bytes / (bandwidth["read_gb_per_s"] * 1e9)
    errors = {name: brute_force_error(state, measured_medium(name), args.error_vertices)
              for name in ("Skin1", "Marble")}
    geometry = _geometry_costs(scene, samples, materials[:2])
    return {
        "label": label, "vertices": statistics["vertices"], "samples": samples,
        "spatial": transfer.spatial_shape is not None,
        "spatial_note": state.log.notes["spatial"]["sphere"],
        "precompute_seconds": precompute_wall, "precompute_cpu_seconds": precompute_cpu,
        "pass1_seconds": statistics["pass1_seconds"],
        "pass2_seconds": statistics.get("pass2_seconds"),
        "pass2_energy_kept": statistics.get("pass2_energy_kept"),
        "storage_mb": statistics["megabytes"], "nnz": statistics["nnz"],
        "dense_mb": statistics["dense_entries"] * 4 / 2**20,
        "relight_fps": 1.0 / relight_wall, "relight_fps_cpu": 1.0 / relight_cpu,
        "relight_stage_seconds": stage,
        "product_fps": 1.0 / product_wall, "product_fps_cpu": 1.0 / product_cpu,
        "edit_fps": 1.0 / edit_wall, "edit_fps_cpu": 1.0 / edit_cpu,
        "bytes_per_relight_frame": frame_bytes,
        "bandwidth_bound_fps": 1.0 / bound_seconds,
        "bandwidth_fraction": bound_seconds / product_wall,
        "bandwidth_fraction_cpu": frame_bytes / (bandwidth["read_gb_per_s_cpu"] * 1e9)
        / product_cpu,
        "edit_over_relight_speed": relight_wall / edit_wall,
        "relative_l2_vs_brute_force": errors,
        "layout": statistics.get("layout", "rows"), "product_channels": channels,
        "load_average": [load_before, os.getloadavg()[0]],
        "geometry": geometry,
    }


def _print_geometry_costs(results) -> None:
    for r in results:
        cost = r["geometry"]
        print(f"{r['label']} / {r['samples']}: with geometry = {cost['model']} (the default; "
              f"the figures above are the paper's half_space): its correction "
              f"{cost['precompute_seconds']:.2f} s at precomputation, a frame "
              f"{1e3 * cost['frame_seconds']:.1f} ms, an edit to a new material "
              f"{cost['new_material_edit_seconds']:.2f} s (one correction), back to a made "
              f"one {1e3 * cost['cached_material_edit_seconds']:.1f} ms")


def _geometry_costs(scene, samples: int, materials) -> dict:
    """Measure what the default ``geometry`` adds: its precomputation, a frame, an edit.

    The rest of the bench measures the paper's method (``half_space``): its editing
    re-weights cached vectors, while the geometry correction is made once per new material
    (a solve or a set of walks, fast/object_geometry.py), kept for the next edits back to it.
    """
    from ...fast.object_geometry import QUICK_GEOMETRY_KNOBS

    knobs = QUICK_GEOMETRY_KNOBS if is_quick() else {}
    with private_cache(prefix="bench_prt_"):
        state = prt.precompute(scene, samples=samples, **knobs)
        state.render()
        start = time.perf_counter()
        state.render()
        frame = time.perf_counter() - start
        start = time.perf_counter()
        for material in materials:
            state.render(material=material)
        first_edit = (time.perf_counter() - start) / max(1, len(materials))
        start = time.perf_counter()
        for material in materials:
            state.render(material=material)
        again = (time.perf_counter() - start) / max(1, len(materials))
    return {"model": state.knobs["geometry"],
            "precompute_seconds": state.log.seconds.get("geometry"), "frame_seconds": frame,
            "new_material_edit_seconds": first_edit, "cached_material_edit_seconds": again,
            "notes": state.log.notes.get("geometry")}


def transfer_eta(state) -> float:
    """Index of refraction of the bench object's material."""
    return state.scene.objects[0].material.eta


# ---------------------------------------------------------------------- error sweeps


def error_sweep(samples: int = 4096) -> dict:
    """Error against K and against the wavelet terms kept, on a 642-vertex sphere.

    For each parameterisation of the basis and K in 2..16, and for 32..1024 Haar terms per
    transfer row: the worst relative L2 against the brute force over Marble, Skin1 and
    Chicken1 (Eq. 1 with the exact R_d on the same samples).
    """
    mesh = icosphere(3)
    names = ("Marble", "Skin1", "Chicken1")
    result = {"samples": samples, "materials": list(names), "basis_terms": {}, "terms": {}}
    with private_cache(prefix="bench_prt_"):
        for basis in ("paper", "area_normalised"):
            rows = []
            for count in (2, 4, 6, 8, 10, 12, 14, 16):
                state = prt.precompute(bench_scene(mesh, 32), samples=samples, basis=basis,
                                       basis_terms=count, geometry="half_space")
                rows.append((count, max(brute_force_error(state, measured_medium(n), 642)
                                        for n in names)))
            result["basis_terms"][basis] = rows
        rows = []
        for terms in (32, 64, 128, 256, 512, 1024):
            state = prt.precompute(bench_scene(mesh, 32), samples=samples, terms=terms,
                                   geometry="half_space")
            rows.append((terms, max(brute_force_error(state, measured_medium(n), 642)
                                    for n in names),
                         state.transfers[0].statistics["megabytes"]))
        result["terms"]["area_normalised"] = rows
    return result


def write_sweep_figure(path, sweep: dict) -> Path:
    """Plot :func:`error_sweep` (two panels), PNG written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for basis, rows in sweep["basis_terms"].items():
        counts, errors = zip(*rows, strict=True)
        left.semilogy(counts, errors, "o-", label=basis)
    left.set(xlabel="K (basis functions of R_d)", ylabel="relative L2 vs brute force",
             title="error against K (256 Haar terms)")
    left.legend()
    for basis, rows in sweep["terms"].items():
        terms, errors, _ = zip(*rows, strict=True)
        right.loglog(terms, errors, "o-", label=basis)
    right.set(xlabel="Haar terms kept per transfer row", ylabel="relative L2 vs brute force",
              title="error against wavelet terms (K = 12)")
    right.legend()
    figure.tight_layout()
    return atomic_save_figure(path, figure)


# ------------------------------------------------------------------------ the command


def _status(value: float, target: float) -> str:
    return "meets" if value >= target else "MISSES"


def run(args) -> int:
    """Run the benchmark, print the figures, write the JSON (and the sweep figure)."""
    counts = count_list(args.samples, "--samples")
    for name in ("frames", "edits", "error_vertices"):
        check_count(getattr(args, name), f"--{name.replace('_', '-')}")
    check_count(args.spatial_rows, "--spatial-rows", minimum=0, why=" (0: skip)")
    if args.png is not None:
        check_output_file(args.png, "--png", what="a file name for the figure")
    bar = steps_bar("bench prt", 2 + len(counts) + bool(args.spatial_rows))
    bar.set_postfix_str("memory bandwidth")
    bandwidth = memory_bandwidth(8, 2) if is_quick() else memory_bandwidth()
    bar.update()
    print(f"memory bandwidth: copy {bandwidth['copy_gb_per_s']:.1f} GB/s, read "
          f"{bandwidth['read_gb_per_s']:.1f} GB/s (CPU time: "
          f"{bandwidth['read_gb_per_s_cpu']:.1f}); load average "
          f"{bandwidth['load_average']:.1f} on {os.cpu_count()} cores")
    from ...scenes import mesh_with_vertices

    mesh = mesh_with_vertices("icosphere", args.vertices)
    bar.set_postfix_str("shadow rays")
    rays = shadow_ray_timings(mesh, (1024,), 1) if is_quick() else shadow_ray_timings(mesh)
    bar.update()
    for row in rays:
        print(f"shadow rays: {row['engine']:<8} {row['rays']:>6} rays {row['ms']:8.1f} ms "
              f"(CPU {row['cpu_ms']:.1f} ms; first call {row['first_call_ms']:.1f} ms; load "
              f"average {row['load_average']:.1f})")
    results = []
    for samples in counts:
        bar.set_postfix_str(f"{samples} samples")
        results.append(bench_configuration(mesh, samples, args, bandwidth,
                                           f"icosphere {len(mesh.vertices)}"))
        bar.update()
    if args.spatial_rows:
        bar.set_postfix_str("geometry image")
        image_mesh = geometry_image(args.spatial_rows)
        results.append(bench_configuration(image_mesh, counts[0], args, bandwidth,
                                           f"geometry image {args.spatial_rows}^2"))
        bar.update()
    bar.close()
    header = (f"{'mesh':<24}{'samples':>8}{'spatial':>8}{'pre s':>8}{'MB':>8}{'relight':>9}"
              f"{'product':>9}{'edit':>8}{'bw frac':>8}{'err Skin1':>10}{'err Marble':>11}")
    print(header)
    for r in results:
        print(f"{r['label']:<24}{r['samples']:>8}{str(r['spatial']):>8}"
              f"{r['precompute_seconds']:>8.1f}{r['storage_mb']:>8.1f}{r['relight_fps']:>9.1f}"
              f"{r['product_fps']:>9.1f}{r['edit_fps']:>8.0f}{r['bandwidth_fraction']:>8.2f}"
              f"{r['relative_l2_vs_brute_force']['Skin1']:>10.4f}"
              f"{r['relative_l2_vs_brute_force']['Marble']:>11.4f}")
    print("fps: frames per second, wall clock on a shared machine (CPU-time figures in the "
          "JSON); bw frac: product rate / (bytes per frame / read bandwidth)")
    for r in results:
        stage = r["relight_stage_seconds"]
        print(f"{r['label']} / {r['samples']}: layout {r['layout']}, relight frame: irradiance "
              f"{1e3 * stage['irradiance']:.1f} ms, product {1e3 * stage['transfer product']:.1f}"
              f" ms; {r['bytes_per_relight_frame'] / 1e6:.0f} MB per frame; CPU-time relight "
              f"{r['relight_fps_cpu']:.1f} fps, product {r['product_fps_cpu']:.1f} fps, bw frac "
              f"{r['bandwidth_fraction_cpu']:.2f}; load average {r['load_average'][0]:.1f} -> "
              f"{r['load_average'][1]:.1f}")
    for r in results:
        print(f"{r['label']} / {r['samples']}: editing {r['edit_fps']:.0f} fps "
              f"({_status(r['edit_fps'], TARGET_EDIT_FPS)} {TARGET_EDIT_FPS:.0f}), "
              f"relighting {r['relight_fps']:.1f} fps "
              f"(editing {r['edit_over_relight_speed']:.0f}x faster) "
              f"({_status(r['relight_fps'], TARGET_RELIGHT_FPS)} {TARGET_RELIGHT_FPS:.0f}), "
              f"bandwidth fraction {r['bandwidth_fraction']:.2f} "
              f"({_status(r['bandwidth_fraction'], TARGET_BANDWIDTH_FRACTION)} "
              f"{TARGET_BANDWIDTH_FRACTION})")
    _print_geometry_costs(results)
    output = {"bandwidth": bandwidth, "configurations": results, "shadow_rays": rays,
              "targets": {"edit_fps": TARGET_EDIT_FPS, "relight_fps": TARGET_RELIGHT_FPS,
                          "bandwidth_fraction": TARGET_BANDWIDTH_FRACTION}}
    if args.sweep:
        sweep = error_sweep()
        output["sweep"] = sweep
        figure = write_sweep_figure(args.png or "bench_prt_sweep.png", sweep)
        print(f"error sweep: {json.dumps(sweep['basis_terms'])}; terms: "
              f"{json.dumps(sweep['terms'])}; figure {figure}")
    path = write_figures(args.json, "prt", output)
    print(f"wrote {path}")
    return 0
