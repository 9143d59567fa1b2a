"""BRDF editing by PCA (Nguyen et al. 2010): precomputation, storage, editing and relighting fps.

``translucent bench brdf_pca`` precomputes the glossy Cornell box (Table 5: 400 x 400,
16k gather samples, K = 6) and reports

* the precomputation time per stage;
* the storage of :math:`T^w` before and after freezing (Sect. 6.2: every object but the
  edited floor frozen; every object frozen for light editing), with :math:`D^w` and
  :math:`M_s^w`, and the freezing time;
* editing frames per second (a new gamma of the floor per frame) and relighting frames
  per second (a moving point light, every object frozen), with the bytes each frame
  reads against this machine's memory bandwidth (a large array copy, measured in the
  same run);
* as the baseline measured in the same run: one pass of the exact path-traced reference
  (Mitsuba, the analytic BRDF plugin) at the same size with ``--baseline-spp`` samples.

Targets of the task on this machine: editing >= 20 fps, relighting >= 10 fps.

``--analysis`` adds the PCA analysis of Fig. 5 for every model (RMS error against K, the
first basis vectors, the error along gamma with K = 6) and a figure; ``--validate`` adds
the comparison with exact-BRDF references (FLIP and relative MSE for three gammas per
model, error maps) and with the path-traced limit of the method's own transport, and the
effect of sub-area sampling; ``--split`` the split of the error on ``glossy`` into its
parts (:mod:`._brdf_pca_split`).
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from ...atomic import atomic_save_figure, check_output_folder
from ...errors import InputError
from ...fast import brdf_pca
from ...materials.brdf_pca import pca_analysis
from ...materials.brdfs import GAMMA_RANGES, MODELS, AnalyticBRDF
from ...scenes import PointLight, load_scene
from ...scenes.gbuffer import interior_pixels
from . import steps_bar, with_size, write_figures

#: Targets of the task (frames per second on this machine).
TARGET_EDIT_FPS = 20.0
TARGET_RELIGHT_FPS = 10.0

#: Fig. 5 of the paper: 6 basis vectors reach an RMS error of 1e-5 for Blinn-Phong.
PAPER_RMS = 1e-5

#: A run with at most this many gather samples (``--quick``) measures the split with few.
QUICK_GATHERS_LIMIT = 256

#: Floor materials of the validation scene, one per model (gamma set per run).
VALIDATION_FLOORS = {
    "blinn_phong": dict(rho_s=0.25, rho_d=[0.45, 0.42, 0.38]),
    "ward": dict(rho_s=0.25, rho_d=[0.45, 0.42, 0.38]),
    "ward_duer": dict(rho_s=0.15, rho_d=[0.45, 0.42, 0.38]),
    "lafortune": dict(rho_s=0.4, rho_d=[0.45, 0.42, 0.38]),
    "cook_torrance": dict(rho_s=0.2, rho_d=[0.45, 0.42, 0.38], f0=0.5),
    "ashikhmin_shirley": dict(rho_s=0.5, rho_d=[0.45, 0.42, 0.38], f0=0.5),
}


#: ``--quick``: a 24 x 24 frame, 256 gather samples, two frames, a one-sample baseline.
QUICK_ARGUMENTS: dict = {"width": 24, "height": 24, "gather_samples": 256, "frames": 2,
                         "baseline_spp": 1, "validation_width": 16,
                         "validation_gather_samples": 256, "validation_spp": 4}


def add_arguments(parser):
    """Add the options of ``translucent bench brdf_pca``."""
    parser.add_argument("--scene", default="glossy_cornell",
                        help="built-in scene name or scene TOML (default glossy_cornell)")
    parser.add_argument("--width", type=int, default=400, help="image width (default 400)")
    parser.add_argument("--height", type=int, default=400, help="image height (default 400)")
    parser.add_argument("--gather-samples", type=int, default=16384,
                        help="gather samples (default 16384, Table 5)")
    parser.add_argument("--object", default="floor", help="object edited (default floor)")
    parser.add_argument("--frames", type=int, default=20,
                        help="timed frames of editing and of relighting (default 20)")
    parser.add_argument("--baseline-spp", type=int, default=16,
                        help="samples per pixel of the path-traced baseline pass (default 16)")
    parser.add_argument("--analysis", action="store_true",
                        help="add the Fig. 5 PCA analysis of every model")
    parser.add_argument("--validate", action="store_true",
                        help="add the comparison with exact-BRDF references")
    parser.add_argument("--validation-width", type=int, default=96,
                        help="image width of the validation renders (default 96)")
    parser.add_argument("--validation-gather-samples", type=int, default=4096)
    parser.add_argument("--validation-spp", type=int, default=256,
                        help="samples per pixel per reference pass (default 256)")
    parser.add_argument("--split", action="store_true",
                        help="add the split of the error on 'glossy' into its parts (the "
                             "PCA, the gather transport, the method's own, by part)")
    parser.add_argument("--out", default="bench_brdf_pca",
                        help="folder for figures and error maps (default bench_brdf_pca)")


def _memory_bandwidth() -> float:
    """Bytes per second of a 256 MB array copy (read + write), the best of three."""
    source = np.ones(1 << 25, dtype=np.float64)
    target = np.empty_like(source)
    best = math.inf
    for _ in range(3):
        started = time.perf_counter()
        np.copyto(target, source)
        best = min(best, time.perf_counter() - started)
    return 2 * source.nbytes / best


def _median_seconds(function, frames: int) -> float:
    seconds = []
    for frame in range(frames):
        started = time.perf_counter()
        function(frame)
        seconds.append(time.perf_counter() - started)
    return float(np.median(seconds))


def _baseline(scene, spp: int) -> float:
    from ...reference import render

    render(scene, spp=1, passes=1, cache=False, progress=False)  # compile the kernels
    started = time.perf_counter()
    render(scene, spp=spp, passes=1, cache=False, progress=False)
    return time.perf_counter() - started


def _performance(args) -> dict:
    scene = with_size(load_scene(args.scene), args.width, args.height)
    name = args.object
    material = scene.object(name).material
    if not isinstance(material, AnalyticBRDF):
        raise InputError("the edited object must have an analytic BRDF", field="--object",
                         value=name)
    started = time.perf_counter()
    state = brdf_pca.precompute(scene, gather_samples=args.gather_samples)
    precompute_seconds = time.perf_counter() - started
    print(f"precomputation: {precompute_seconds:.1f} s (cache {state.log.notes['cache']}); "
          f"stages {', '.join(f'{k} {v:.1f} s' for k, v in state.log.seconds.items())}",
          flush=True)
    state.render()
    full = state.storage_bytes()
    editing_freeze = state.freeze(editing=name)
    editing_storage = state.storage_bytes()
    low, high = GAMMA_RANGES[material.model]
    gammas = np.geomspace(low, high, max(2, args.frames))
    state.edit(name, gammas[-1])  # warm-up: the products T_j^w L^w of this lighting
    edit_seconds = _median_seconds(lambda k: state.edit(name, gammas[k % len(gammas)]),
                                   args.frames)
    rows = len(state._members[name])
    edit_bytes = rows * (state.data.bases[scene.objects.index(scene.object(name))].size + 1
                         ) * 3 * 4 * 2
    light = scene.lights[0]
    position = np.asarray(light.position, dtype=np.float64)
    intensity = light.intensity

    def relight(k):
        angle = 2 * math.pi * k / max(args.frames, 1)
        offset = 0.3 * np.array([math.cos(angle), 0.0, math.sin(angle)])
        state.relight([PointLight(position + offset, intensity)])

    light_freeze = state.freeze()
    light_storage = state.storage_bytes()
    relight(0)
    relight_seconds = _median_seconds(relight, args.frames)
    bandwidth = _memory_bandwidth()
    baseline = _baseline(scene, args.baseline_spp)
    result = {
        "scene": scene.name, "width": args.width, "height": args.height,
        "gather_samples": state.log.notes["gather_samples"],
        "view_samples": state.log.notes["view_samples"], "knobs": state.knobs,
        "precompute_seconds": precompute_seconds, "stage_seconds": state.log.seconds,
        "cache": state.log.notes["cache"], "subarea_points": state.log.notes.get(
            "subarea_points"), "budgets": state.log.notes["budgets"],
        "storage_bytes": {"all rows": full, f"frozen but {name}": editing_storage,
                          "all frozen": light_storage},
        "freeze_seconds": {f"all but {name}": editing_freeze, "all": light_freeze},
        "edit_seconds": edit_seconds, "edit_fps": 1.0 / edit_seconds,
        "edit_bytes_per_frame": edit_bytes,
        "relight_seconds": relight_seconds, "relight_fps": 1.0 / relight_seconds,
        "relight_bytes_per_frame": light_storage["total"],
        "memory_bandwidth_bytes_per_second": bandwidth,
        "baseline": {"what": f"one path-traced reference pass, {args.baseline_spp} spp",
                     "seconds": baseline},
        "skipped": list(state.log.skipped)}
    megabytes = {k: {n: v / 2**20 for n, v in s.items()} for k, s in
                 result["storage_bytes"].items()}
    print(f"\n{args.scene}: {args.width} x {args.height}, {result['gather_samples']} gather "
          f"samples, {result['view_samples']} view samples, K = {state.knobs['n_basis']}")
    print(f"{'storage (MB)':28s} {'T^w':>9s} {'D^w':>9s} {'M_s^w':>9s} {'total':>9s}")
    for key, sizes in megabytes.items():
        print(f"{key:28s} {sizes['transfer']:9.1f} {sizes['diffuse']:9.1f} "
              f"{sizes['gather']:9.1f} {sizes['total']:9.1f}")
    print(f"freezing: {editing_freeze:.2f} s (all but {name}), {light_freeze:.2f} s (all)")
    for label, seconds, moved, target in (
            ("editing", edit_seconds, edit_bytes, TARGET_EDIT_FPS),
            ("relighting", relight_seconds, light_storage["total"], TARGET_RELIGHT_FPS)):
        verdict = "reached" if 1.0 / seconds >= target else "NOT reached"
        print(f"{label:11s} {1.0 / seconds:8.2f} fps ({1000 * seconds:.1f} ms; "
              f"{baseline / seconds:.0f}x faster than the baseline); reads "
              f"{moved / 2**20:.1f} MB per frame = {moved / seconds / 1e9:.2f} GB/s of "
              f"{bandwidth / 1e9:.1f} GB/s; target >= {target:g} fps {verdict}")
    print(f"baseline: {result['baseline']['what']} in {baseline:.2f} s")
    return result


def _analysis(folder: Path) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = {}
    figure, axes = plt.subplots(len(MODELS), 3, figsize=(12, 2.6 * len(MODELS)))
    print(f"\nPCA analysis (Fig. 5): RMS error (sr^-1) of the linearised edited term; the "
          f"paper reaches {PAPER_RMS:g} with K = 6 for Blinn-Phong over [3, 300]")
    print(f"{'model':18s} {'range':>14s} {'peak':>8s} {'K=1':>9s} {'K=4':>9s} {'K=6':>9s} "
          f"{'K=8':>9s} {'K=12':>9s} {'rel. K=6':>9s} {'K for 1e-5':>10s}")
    for row, model in enumerate(MODELS):
        analysis = pca_analysis(model)
        summary = analysis.to_dict()
        results[model] = summary
        rms = dict(zip(analysis.basis_sizes.tolist(), analysis.rms_max.tolist(), strict=True))
        relative = dict(zip(analysis.basis_sizes.tolist(), analysis.relative_rms_max.tolist(),
                            strict=True))
        low, high = GAMMA_RANGES[model]
        print(f"{model:18s} {f'[{low:g}, {high:g}]':>14s} {analysis.peak:8.2f} "
              + " ".join(f"{rms[k]:9.2e}" for k in (1, 4, 6, 8, 12))
              + f" {relative[6]:9.2e} {str(summary['k_for_1e-5']):>10s}")
        axes[row, 0].semilogy(analysis.basis_sizes, analysis.rms_max, "o-", label="max")
        axes[row, 0].semilogy(analysis.basis_sizes, analysis.rms_mean, "s--", label="mean")
        axes[row, 0].axhline(PAPER_RMS, color="grey", lw=0.8)
        axes[row, 0].set_ylabel(model)
        axes[row, 0].legend(fontsize=7)
        for j, vector in enumerate(analysis.first_basis):
            axes[row, 1].plot(analysis.delta, vector, lw=0.8, label=f"b{j + 1}")
        axes[row, 2].semilogy(analysis.gammas, analysis.rms_along_gamma)
    axes[0, 0].set_title("(a) RMS error against K")
    axes[0, 1].set_title("(b) first 7 basis vectors")
    axes[0, 2].set_title("(c) RMS error along gamma, K = 6")
    figure.tight_layout()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "fig5_pca_analysis.png"
    atomic_save_figure(path, figure)
    print(f"wrote {path}")
    return results


def _validate(args, folder: Path) -> dict:
    from ...image import Image
    from ...reference import render
    from ...reference.brdf_plugins import render_lambertian_gather
    from ..metrics.compute import evaluate, relative_mse
    from ..metrics.maps import write_error_maps

    base = load_scene("glossy")
    aspect = base.camera.height / base.camera.width
    base = with_size(base, args.validation_width, max(1, round(args.validation_width * aspect)))
    spp, gathers = args.validation_spp, args.validation_gather_samples
    rows = []
    print(f"\nvalidation on 'glossy' at {base.camera.width} x {base.camera.height}, {gathers} "
          f"gather samples; references {spp} spp x 4 passes. Floor: each model in turn. "
          "'exact' = path-traced exact BRDFs; 'limit' = path-traced transport of the method "
          "(full BRDF at the first surface, diffuse after); interior pixels only for relMSE")
    print(f"{'model':18s} {'gamma':>8s} {'FLIP exact':>10s} {'relMSE exact':>12s} "
          f"{'relMSE limit':>12s} {'limit vs exact':>14s}")
    for model in MODELS:
        low, high = GAMMA_RANGES[model]
        floor = AnalyticBRDF(model, low, **VALIDATION_FLOORS[model])
        scene = base.with_material("floor", floor)
        state = brdf_pca.precompute(scene, gather_samples=gathers)
        mask = interior_pixels(scene)
        for gamma in (low, math.sqrt(low * high), high):
            edited = scene.with_material("floor", floor.with_gamma(gamma))
            test = state.edit("floor", gamma)
            exact = render(edited, spp=spp, passes=4, progress=False)
            limit = render_lambertian_gather(edited, bounces=state.knobs["bounces"], spp=spp,
                                             passes=4)
            comparison = evaluate(exact, test)
            stem = f"{model}_gamma{gamma:g}_"
            write_error_maps(exact, test, folder / "validation", prefix=stem,
                             comparison=comparison)
            test.write(folder / "validation" / f"{stem}fast.exr")
            exact.write(folder / "validation" / f"{stem}exact.exr")
            row = {"model": model, "gamma": gamma, "hdr_flip": comparison.metrics.hdr_flip,
                   "relative_mse_exact": relative_mse(exact.rgb[mask], test.rgb[mask],
                                                      reference_variance=exact.variance[mask]),
                   "relative_mse_limit": relative_mse(limit.rgb[mask], test.rgb[mask],
                                                      reference_variance=limit.variance[mask]),
                   "limit_vs_exact": relative_mse(exact.rgb[mask], limit.rgb[mask],
                                                  reference_variance=exact.variance[mask])}
            rows.append(row)
            print(f"{model:18s} {gamma:8.3g} {row['hdr_flip']:10.4f} "
                  f"{row['relative_mse_exact']:12.4f} {row['relative_mse_limit']:12.4f} "
                  f"{row['limit_vs_exact']:14.4f}", flush=True)
    # sub-area sampling on and off (Fig. 2): Blinn-Phong floor at gamma 300
    floor = AnalyticBRDF("blinn_phong", 300.0, **VALIDATION_FLOORS["blinn_phong"])
    scene = base.with_material("floor", floor)
    limit = render_lambertian_gather(scene, bounces=2, spp=spp, passes=4)
    mask = interior_pixels(scene)
    subarea = {}
    for enabled in (False, True):
        image = brdf_pca.precompute(scene, gather_samples=gathers, subarea=enabled).render()
        subarea["on" if enabled else "off"] = relative_mse(
            limit.rgb[mask], image.rgb[mask], reference_variance=limit.variance[mask])
        Image(image.rgb).write(folder / "validation" / f"subarea_{int(enabled)}.exr")
    print(f"sub-area sampling (BP floor, gamma 300): relMSE against the limit "
          f"{subarea['off']:.5f} off, {subarea['on']:.5f} on")
    return {"rows": rows, "subarea": subarea}


def run(args) -> int:
    """Run the benchmark (and the optional analysis and validation); write the JSON."""
    for name in ("width", "height", "gather_samples", "frames", "baseline_spp",
                 "validation_width", "validation_gather_samples", "validation_spp"):
        value = getattr(args, name)
        if value < 1:
            raise InputError("must be >= 1", field=f"--{name.replace('_', '-')}", value=value)
    folder = Path(args.out)
    if args.analysis or args.validate:
        check_output_folder(folder, "--out")
    sections = {"performance": lambda: _performance(args)}
    if args.analysis:
        sections["analysis"] = lambda: _analysis(folder)
    if args.validate:
        sections["validation"] = lambda: _validate(args, folder)
    if args.split:
        from ._brdf_pca_split import split

        sections["split"] = lambda: split(quick=args.gather_samples <= QUICK_GATHERS_LIMIT)
    out = {}
    with steps_bar("bench brdf_pca", len(sections), unit="section") as bar:
        for section, measure in sections.items():
            bar.set_postfix_str(section)
            out[section] = measure()
            bar.update()
    path = write_figures(args.json, "brdf_pca", out)
    print(f"wrote {path}")
    return 0
