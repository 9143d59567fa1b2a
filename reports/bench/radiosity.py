"""Translucent radiosity (Sheng et al. 2014): precomputation, relighting and translucency fps.

``translucent bench radiosity`` builds the Cornell box with the translucent block at about
25,000 patches (the paper's Table 1 scene has 24,640 polygons) and measures

* precomputation: seconds for the patches, the form factors, the optical distances with
  the scattering samples; the memory of F, of the cached scattering operators and of S,
  and the process's peak resident memory;
* relighting: frames per second of the solve alone (new irradiance, the paper's
  relighting step) for each solver from a cold start (Jacobi, GMRES, BiCGSTAB: products of
  SF and seconds), of Jacobi started from the earlier frames' solutions, and of a whole
  frame split into its parts (patch irradiance with shadow rays, solve, image with per-pixel
  direct light) for each ray engine of the shadow rays (knob ``shadow_ray_engine``) and
  with 16 or 4 shadow rays per diffuse patch (knob ``diffuse_light_samples``), with the load
  average at each; what fewer shadow rays on diffuse patches save and change in the image;
  each timed sequence slides the light along a path not used before;
* relighting with the precomputed T = (I - SF)^-1 S: at 25k patches T needs 3 P^2 float32
  (7.5 GB) and is skipped by the rule of ``transfer_budget_mb``; it is measured on the same
  scene cut coarser, at the largest patch count the budget allows (``--transfer-patches``);
* translucency change: frames per second of re-indexing the profiles (new S) and of
  re-indexing plus solving, over a sweep of the block's scattering coefficient;
* the form-factor threshold: entries, memory and the change of the solution it causes;
* a low-rank operator instead of T (``--low-rank``): randomized rank-k factors of the
  inter-reflection operator F (I - SF)^-1 S, their build time, frame time, error of B and
  the Jacobi products still needed when they give the starting guess;
* the scattering sampling knobs (polar versus 100-sample self term, sample fall-off) on a
  flat sheet: seconds and energy error against the profile's closed-form total.

Times are printed in seconds and as ratios to a baseline measured in the same run (one
copy of 256 MB, which also gives this machine's memory bandwidth); interactive paths
report the bytes a frame moves against that bandwidth. The paper's GPU figures (GTX 590):
14 fps relighting, 4 fps translucency change, 4 + 3 min precomputation, 800 MB.
"""

from __future__ import annotations

import itertools
import os
import re
import resource
import time

import numpy as np

from ...errors import check_count
from ...fast import radiosity
from ...materials import Dipole, measured_medium
from ...scenes import RectangularAreaLight, SceneObject
from ...scenes.raycast import embree_available, ray_engine
from ...scenes.scene_file import builtin_scene_path, loads_scene
from . import count_list, is_quick, steps_bar, write_figures

#: The paper's Table 1, Cornell box (24,640 polygons, GTX 590).
PAPER = {"relighting fps": 14.0, "translucency change fps": 4.0,
         "precomputation minutes": 7.0, "memory MB": 800.0}

#: Bytes copied for the bandwidth baseline.
BASELINE_BYTES = 256 * 2**20

#: The timed parts of a relighting frame (``RadiosityState.render`` metadata).
FRAME_PARTS = ("irradiance", "solve", "image")

#: Ray engines of the shadow rays a whole frame is measured with (knob shadow_ray_engine;
#: Embree where ``embreex`` is installed).
SHADOW_ENGINES = ("embree", "mitsuba")

#: Tolerance of the converged solutions the low-rank operators are judged against.
LOW_RANK_REFERENCE_TOLERANCE = 1e-6

#: Columns added to the rank of the randomized range finder (Halko et al. 2011, Sect. 4).
LOW_RANK_OVERSAMPLING = 10


#: ``--quick``: a coarse box (6 wall, 4 block segments), 16 rays, one frame, rank 8, an 8 x 8
#: sheet for the sampling comparison.
QUICK_ARGUMENTS: dict = {"wall_subdivisions": 6, "block_subdivisions": 4, "rays": 16,
                         "frames": 1, "transfer_patches": 300, "low_rank": "8"}


def add_arguments(parser):
    """Options of ``translucent bench radiosity``."""
    parser.add_argument("--wall-subdivisions", type=int, default=46,
                        help="segments per Cornell-box wall edge (46: 21,160 wall patches)")
    parser.add_argument("--block-subdivisions", type=int, default=28,
                        help="segments along the block's long edge (28: 3,920 patches)")
    parser.add_argument("--mm-per-unit", type=float, default=275.0,
                        help="scale (default 275: the 550 mm Cornell box of the paper)")
    parser.add_argument("--material", default="Marble",
                        help="measured material of the block (default Marble, as the paper)")
    parser.add_argument("--rays", type=int, default=radiosity.DEFAULT_KNOBS["rays_per_patch"],
                        help="form-factor rays per patch")
    parser.add_argument("--frames", type=int, default=4, help="timed frames per measurement")
    parser.add_argument("--transfer-patches", type=int, default=6000,
                        help="about this many patches for the T measurement (budget 512 MB)")
    parser.add_argument("--low-rank", default="32,128",
                        help="ranks of the low-rank relighting operator to measure (comma "
                             "separated; empty: skip)")
    parser.add_argument("--skip-transfer", action="store_true",
                        help="skip the precomputed-T measurement on the coarser box")
    parser.add_argument("--skip-sampling", action="store_true",
                        help="skip the sampling-knob comparison on the flat sheet")


def _cornell(wall: int, block: int, mm_per_unit: float, material):
    """Build the Cornell box with the translucent block, re-meshed and rescaled."""
    path = builtin_scene_path("cornell_block")
    text = path.read_text()
    text = re.sub(r'(part = "[a-z_]+", size = 2\.0, subdivisions = )\d+', rf"\g<1>{wall}", text)
    text = re.sub(r'(type = "box".*?subdivisions = )\d+', rf"\g<1>{block}", text)
    text = re.sub(r"mm_per_unit = [0-9.]+", f"mm_per_unit = {mm_per_unit}", text)
    return loads_scene(text, file=str(path), base_dir=path.parent).with_material("block",
                                                                              material)


def _baseline() -> tuple[float, float]:
    """Seconds of one 256 MB copy (best of three) and the bandwidth in GB/s (read + write)."""
    source = np.ones(BASELINE_BYTES // 8)
    target = np.empty_like(source)
    best = np.inf
    for _ in range(3):
        started = time.perf_counter()
        np.copyto(target, source)
        best = min(best, time.perf_counter() - started)
    return best, 2 * BASELINE_BYTES / best / 1e9


def _timed(function, frames: int):
    """Run once to warm up, then ``frames`` times; return (seconds per frame, last result)."""
    result = function()
    started = time.perf_counter()
    for _ in range(frames):
        result = function()
    return (time.perf_counter() - started) / frames, result


def _moved_lights(scene, count: int, axis: int = 0):
    """Yield the scene's area light slid across the ceiling along ``axis`` (x: 0, z: 2).

    Every timed sequence slides the light along a path not used before, so that no frame
    repeats a light that an earlier frame's solution could answer exactly.
    """
    light = scene.lights[0]
    for k in range(count):
        offset = np.zeros(3)
        offset[axis] = 0.5 * (k / max(count - 1, 1) - 0.5)
        yield (RectangularAreaLight(light.center + offset, light.u_axis, light.v_axis,
                                    light.radiance),)


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _precomputation(scene, args, out):
    started = time.perf_counter()
    state = radiosity.precompute(scene, rays_per_patch=args.rays)
    total = time.perf_counter() - started
    log = state.log
    F = state.form_factors
    memory = {"form factors MB": (F.data.nbytes + F.indices.nbytes + F.indptr.nbytes) / 2**20,
              "scattering operators MB": state.geometry.bytes / 2**20,
              "S (3 channels) MB": state.S.bytes / 2**20,
              "peak resident MB": _peak_mb()}
    out["precomputation"] = {"patches": len(state.patches), "seconds": total,
                             "stages": dict(log.seconds), "cache": log.notes.get("cache"),
                             "form factor entries": int(F.nnz),
                             "scattering entries": int(state.geometry.nnz),
                             "max_distance_mm": state.knobs["max_distance_mm"],
                             "skipped": list(log.skipped), **memory,
                             "convergence": state.convergence}
    print(f"patches {len(state.patches)} (block {len(state.patches.of_object(5))}), "
          f"max_d {state.knobs['max_distance_mm']:.1f} mm, cache {log.notes.get('cache')}")
    for stage, seconds in log.seconds.items():
        print(f"  {stage:<24} {seconds:8.1f} s")
    print(f"  total precomputation     {total:8.1f} s   (paper: 4 + 3 min on a GTX 590)")
    for key, value in memory.items():
        print(f"  {key:<24} {value:8.1f}")
    print(f"  F entries {F.nnz:,}, S entries {state.geometry.nnz:,}; max column sum of S "
          f"{state.convergence['max_scattering_column_sum']:.3f}")
    return state


def _relighting(state, args, baseline, bandwidth, out):
    lights = list(_moved_lights(state.scene, args.frames + 1))
    state.patch_irradiance()  # compiles and sets up the shadow rays once, as every frame after
    started = time.perf_counter()
    irradiances = [state.patch_irradiance(light) for light in lights]
    irradiance_seconds = (time.perf_counter() - started) / len(lights)
    F = state.form_factors
    solvers = {}
    print(f"relighting (solve only, cold start; irradiance {irradiance_seconds:.2f} s per "
          "light set):")
    state.knobs["warm_start"] = False
    for solver in radiosity.SOLVERS:
        state.knobs["solver"] = solver
        frame = itertools.cycle(irradiances)

        def solve(state=state, frame=frame):
            return state.solve(next(frame))

        seconds, (_, info) = _timed(solve, args.frames)
        per_iteration = (F.data.nbytes + F.indices.nbytes + 3 * (state.S.data.nbytes / 3
                         + state.S.indices.nbytes))
        moved = per_iteration * max(info["iterations"], 1)
        solvers[solver] = {"seconds": seconds, "fps": 1.0 / seconds,
                           "iterations": info["iterations"],
                           "residual": max(info["residual"]),
                           "ratio to baseline": seconds / baseline,
                           "bytes per frame": moved,
                           "fraction of bandwidth": moved / seconds / 1e9 / bandwidth}
        print(f"  {solver:<9} {1 / seconds:7.2f} fps  {info['iterations']:4d} iterations  "
              f"residual {max(info['residual']):.4f}  {seconds / baseline:6.1f} x baseline  "
              f"{moved / 2**20:7.0f} MB/frame")
    fastest = min(solvers, key=lambda name: solvers[name]["seconds"])
    state.knobs["solver"] = fastest
    state.knobs["warm_start"] = True
    state.forget_frames()
    frame = itertools.cycle(irradiances)

    def warm(state=state, frame=frame):
        return state.solve(next(frame))

    warm_seconds, (_, info) = _timed(warm, args.frames)
    solvers[f"{fastest}, warm start"] = {"seconds": warm_seconds, "fps": 1.0 / warm_seconds,
                                         "iterations": info["iterations"],
                                         "residual": max(info["residual"]),
                                         "ratio to baseline": warm_seconds / baseline}
    print(f"  {fastest}, started from the earlier frames' solutions: "
          f"{1 / warm_seconds:.2f} fps, {info['iterations']} iterations")
    frames = {}
    axis = 2
    for engine in [e for e in SHADOW_ENGINES if e != "embree" or embree_available()]:
        state.knobs["shadow_ray_engine"] = engine
        for count in (None, 4):
            state.knobs["diffuse_light_samples"] = count
            # a path of the light not used before (the warm start gains nothing from repeats)
            lights = list(_moved_lights(state.scene, args.frames, axis=axis))
            axis = 2 - axis
            seconds, split, image = _whole_frame(state, lights, args.frames)
            label = (f"shadow rays {engine}, diffuse light samples "
                     f"{count or state.knobs['light_samples']}")
            frames[label] = {"frame seconds": seconds, "frame fps": 1.0 / seconds,
                             "frame parts seconds": split, "load average": os.getloadavg()[0]}
            print(f"  whole frame ({fastest}, {image.shape[1]} x {image.shape[0]}, {label}, "
                  f"load {os.getloadavg()[0]:.2f}): {1 / seconds:.2f} fps ({seconds:.3f} s: "
                  f"patch irradiance with shadow rays {split['irradiance']:.3f} s, solve "
                  f"{split['solve']:.3f} s, image with per-pixel direct light "
                  f"{split['image']:.3f} s)")
    state.knobs["shadow_ray_engine"] = radiosity.DEFAULT_KNOBS["shadow_ray_engine"]
    state.knobs["diffuse_light_samples"] = None
    default_engine = ray_engine(state.scene, state.knobs["shadow_ray_engine"]).engine
    default = frames[f"shadow rays {default_engine}, diffuse light samples "
                     f"{state.knobs['light_samples']}"]
    out_rows: dict = {}
    # the image change is measured against the default knobs' image of the same light
    fewer = _diffuse_light_samples(state, lights[-1], state.render(lights=lights[-1]), out_rows)
    out["relighting"] = {"solvers": solvers, "fastest": fastest,
                         "irradiance seconds": irradiance_seconds, **default,
                         "whole frames": frames, "image": list(image.shape),
                         "diffuse light samples": out_rows}
    print(fewer)


def _whole_frame(state, lights, frames: int):
    """Seconds per whole relighting frame, its split into FRAME_PARTS, the last image."""
    frame = itertools.cycle(lights)
    parts = []

    def whole(state=state, frame=frame, parts=parts):
        image = state.render(lights=next(frame))
        parts.append([image.metadata[f"{part}_seconds"] for part in FRAME_PARTS])
        return image

    seconds, image = _timed(whole, max(1, frames - 1))
    split = dict(zip(FRAME_PARTS, np.mean(parts[1:], axis=0).tolist(), strict=True))
    return seconds, split, image


def _diffuse_light_samples(state, light, image, rows, counts=(4, 1)) -> str:
    """Patch irradiance time and image change with fewer shadow rays on diffuse patches."""
    full = state.knobs["light_samples"]
    lines = []
    for count in (full,) + tuple(counts):
        state.knobs["diffuse_light_samples"] = count
        seconds, _ = _timed(lambda light=light: state.patch_irradiance(light), 2)
        change = np.abs(state.render(lights=light).rgb - image.rgb).mean() \
            / max(float(np.abs(image.rgb).mean()), 1e-300)
        rows[str(count)] = {"irradiance seconds": seconds, "relative image change": change}
        lines.append(f"{count} ({seconds:.3f} s, image change {change:.4f})")
    state.knobs["diffuse_light_samples"] = None
    return ("  shadow rays per diffuse patch and area light (patch irradiance seconds, mean "
            "absolute image change against " + str(full) + "): " + ", ".join(lines))


def _translucency(state, args, baseline, out):
    base = state.scene.object("block").material
    scales = np.geomspace(0.5, 2.0, args.frames + 1)
    materials = [Dipole(base.sigma_a, base.sigma_s_prime * s, base.eta, base.g) for s in scales]
    irradiance = state.patch_irradiance()
    frame = itertools.cycle(materials)

    def reindex(state=state, frame=frame):
        return state.set_material(next(frame))

    reindex_seconds, _ = _timed(reindex, args.frames)
    frame = itertools.cycle(materials)

    def change(state=state, frame=frame):
        state.set_material(next(frame))
        return state.solve(irradiance)

    seconds, (_, info) = _timed(change, args.frames)
    state.set_material(base)
    out["translucency change"] = {"re-index seconds": reindex_seconds,
                                  "re-index fps": 1 / reindex_seconds,
                                  "with solve seconds": seconds, "with solve fps": 1 / seconds,
                                  "iterations": info["iterations"],
                                  "ratio to baseline": seconds / baseline,
                                  "sigma_s_prime scales": scales.tolist()}
    print(f"translucency change: re-index {1 / reindex_seconds:.2f} fps "
          f"({reindex_seconds:.3f} s), with solve {1 / seconds:.2f} fps ({seconds:.3f} s, "
          f"{seconds / baseline:.1f} x baseline)")


def _thresholds(state, out):
    F_full = state.form_factors
    irradiance = state.patch_irradiance()
    reference, _ = radiosity.solve_radiosity(state.S, F_full, state.S.dot(irradiance),
                                             solver="gmres", tolerance=1e-8)
    rays = state.knobs["rays_per_patch"]
    rows = {}
    print("form-factor threshold (entries below it dropped):")
    for threshold in (0.0, 1.5 / rays, 2.5 / rays, 4.5 / rays, 0.02):
        F = F_full.copy()
        F.data[F.data < threshold] = 0.0
        F.eliminate_zeros()
        B, _ = radiosity.solve_radiosity(state.S, F, state.S.dot(irradiance), solver="gmres",
                                         tolerance=1e-8)
        change = float(np.abs(B - reference).sum() / np.abs(reference).sum())
        memory = (F.data.nbytes + F.indices.nbytes + F.indptr.nbytes) / 2**20
        rows[f"{threshold:.4g}"] = {"entries": int(F.nnz), "MB": memory,
                                    "relative change of B": change}
        print(f"  {threshold:7.4f}: {F.nnz:>11,} entries {memory:7.1f} MB  "
              f"change of B {change:.4f}")
    out["form factor threshold"] = rows


def _transfer(args, baseline, out):
    ratio = np.sqrt(args.transfer_patches / 25000.0)
    wall = max(2, int(round(args.wall_subdivisions * ratio)))
    block = max(2, int(round(args.block_subdivisions * ratio)))
    scene = _cornell(wall, block, args.mm_per_unit, measured_medium(args.material))
    state = radiosity.precompute(scene, rays_per_patch=args.rays)
    if not state.transfer_fits():
        print(f"T skipped at {len(state.patches)} patches: over transfer_budget_mb")
        return
    transfer_seconds = state.precompute_transfer()
    lights = list(_moved_lights(scene, args.frames + 1))
    irradiances = [state.patch_irradiance(light) for light in lights]
    frame = itertools.cycle(irradiances)

    def relight(state=state, frame=frame):
        return state.solve(next(frame))

    seconds, _ = _timed(relight, args.frames * 3)
    state.transfer = None
    iterative, (_, info) = _timed(relight, args.frames)
    out["transfer"] = {"patches": len(state.patches), "T seconds": transfer_seconds,
                       "T MB": 3 * len(state.patches) ** 2 * 4 / 2**20,
                       "relight seconds": seconds, "relight fps": 1 / seconds,
                       "iterative seconds": iterative, "iterative fps": 1 / iterative,
                       "iterations": info["iterations"], "ratio to baseline": seconds / baseline}
    print(f"precomputed T at {len(state.patches)} patches: {transfer_seconds:.1f} s, "
          f"{3 * len(state.patches) ** 2 * 4 / 2**20:.0f} MB; relight {1 / seconds:.1f} fps "
          f"(iterative {state.knobs['solver']} at that size: {1 / iterative:.1f} fps)")


def _block_jacobi(A, B, rhs, tolerance):
    """Solve X = rhs + A (B X) for a block of columns (both sparse factors given)."""
    X = rhs.copy()
    norm = np.linalg.norm(rhs)
    while True:
        updated = rhs + A @ (B @ X)
        change = np.linalg.norm(updated - X) / norm
        X = updated
        if change < tolerance:
            return X


def low_rank_global_operator(S_c, F, rank: int, rng) -> tuple[np.ndarray, np.ndarray]:
    r"""Randomized rank-``rank`` factors U, V of :math:`G = F(I - S_cF)^{-1}S_c` (one channel).

    G takes the patch irradiance E to the inter-reflected irradiance FB of Eq. 14 (Sheng et
    al. 2014); with it :math:`B = S_c(E + GE)`. Two passes of the randomized range finder
    (Halko, Martinsson, Tropp 2011, Alg. 4.1 and 5.1): :math:`Y = G\Omega`, Q = qr(Y),
    :math:`W = G^TQ = S_c^T(I - F^TS_c^T)^{-1}F^TQ`, G ~ Q W^T truncated by an SVD.
    """
    size = F.shape[0]
    columns = rank + LOW_RANK_OVERSAMPLING
    omega = rng.standard_normal((size, columns))
    Y = F @ _block_jacobi(S_c, F, S_c @ omega, 1e-3)
    Q, _ = np.linalg.qr(Y)
    F_T, S_T = F.T.tocsr(), S_c.T.tocsr()
    W = S_T @ _block_jacobi(F_T, S_T, F_T @ Q, 1e-3)
    left, singular, right = np.linalg.svd(W.T, full_matrices=False)
    return ((Q @ left[:, :rank]) * singular[:rank]).astype(np.float32), \
        right[:rank].T.astype(np.float32).copy()


def _low_rank(state, args, out):
    """Measure a low-rank relighting operator instead of T: error, speed, as a starting guess."""
    ranks = count_list(args.low_rank, "--low-rank", allow_empty=True)
    if not ranks:
        return
    F = state.form_factors.astype(np.float64)
    channels = [state.S.channel(c) for c in range(3)]
    lights = list(_moved_lights(state.scene, 3))
    irradiances = [state.patch_irradiance(light) for light in lights]
    tolerance = state.knobs["tolerance"]
    exact = [radiosity.solve_radiosity(state.S, state.form_factors, state.S.dot(E),
                                       tolerance=LOW_RANK_REFERENCE_TOLERANCE)
             for E in irradiances]
    rows = {}
    print(f"low-rank inter-reflection operator G = F (I - SF)^-1 S (instead of T; B = S(E + GE)), "
          f"against solutions to {LOW_RANK_REFERENCE_TOLERANCE:g}:")
    for rank in ranks:
        rng = np.random.default_rng(0)
        started = time.perf_counter()
        factors = [low_rank_global_operator(S_c, F, rank, rng) for S_c in channels]
        build = time.perf_counter() - started
        errors, guesses, seconds = [], [], []
        for E, (B_exact, _) in zip(irradiances, exact, strict=True):
            started = time.perf_counter()
            global_irradiance = np.stack([U @ (V.T @ E[:, c].astype(np.float32))
                                          for c, (U, V) in enumerate(factors)], axis=1)
            B = state.S.dot(E + global_irradiance)
            seconds.append(time.perf_counter() - started)
            errors.append(float((np.linalg.norm(B - B_exact, axis=0)
                                 / np.linalg.norm(B_exact, axis=0)).max()))
            _, guessed = radiosity.solve_radiosity(state.S, state.form_factors,
                                                   state.S.dot(E), tolerance=tolerance,
                                                   initial=B)
            guesses.append(guessed["iterations"])
        rows[str(rank)] = {"build seconds": build, "frame seconds": float(np.mean(seconds)),
                           "relative error of B": max(errors),
                           "MB": sum(U.nbytes + V.nbytes for U, V in factors) / 2**20,
                           "Jacobi products from it": guesses}
        print(f"  rank {rank:4d}: build {build:6.1f} s, {np.mean(seconds) * 1e3:6.1f} ms/frame, "
              f"{rows[str(rank)]['MB']:6.0f} MB, error of B {max(errors):.3f}; Jacobi from it "
              f"to {tolerance:g}: {guesses} products")
    out["low rank"] = rows


def _sampling(out):
    from ...fast.radiosity.form_factors import build_patches
    from ...materials.profiles import DipoleProfile
    from ...scenes import Camera, Scene, plane

    profile = DipoleProfile(measured_medium("Skin1"))
    max_d = profile.support_radius(1e-3)
    subdivisions = 8 if is_quick() else 24
    scene = Scene([SceneObject("sheet", plane(2.2 * max_d, 2.2 * max_d,
                                              subdivisions=subdivisions), profile)], [],
                  Camera([0, 1, 4], [0, 0, 0]))
    patches = build_patches(scene)
    middle = int(np.argmin(np.linalg.norm(patches.centroid, axis=1)))
    expected = profile.total(max_radius=max_d)
    rows = {}
    print(f"scattering sampling on a flat Skin1 sheet ({len(patches)} patches, patch radius "
          f"{patches.radius.mean():.2f} mm): energy error at the middle patch")
    for term, falloff, beyond in (("samples", 1, 4), ("polar", 1, 4), ("samples", 2, 8),
                                  ("polar", 2, 8), ("polar", 4, 16)):
        knobs = dict(radiosity.DEFAULT_KNOBS, self_term=term, sample_falloff=falloff,
                     centroid_beyond=beyond)
        started = time.perf_counter()
        geometry = radiosity.scattering_geometry(scene, patches, [0], max_distance_mm=max_d,
                                                 knobs=knobs)
        S = radiosity.scattering_matrix(geometry, scene, patches)
        seconds = time.perf_counter() - started
        error = S.power_column_sums(patches.area)[middle] / expected - 1.0
        key = f"{term}, fall-off {falloff}, centroid beyond {beyond}"
        rows[key] = {"seconds": seconds, "energy error": error.tolist(),
                     "samples": geometry.objects[0].facts["samples"]}
        print(f"  {key:<40} {seconds:6.2f} s  error {np.abs(error).max():.4f}")
    out["sampling"] = rows


def run(args) -> int:
    """Measure everything, print the tables, write the JSON."""
    check_count(args.frames, "--frames")
    count_list(args.low_rank, "--low-rank", allow_empty=True)
    baseline, bandwidth = _baseline()
    print(f"baseline: 256 MB copy {baseline * 1e3:.1f} ms ({bandwidth:.1f} GB/s read + write)")
    out = {"baseline seconds": baseline, "bandwidth GB/s": bandwidth, "paper": PAPER}
    scene = _cornell(args.wall_subdivisions, args.block_subdivisions, args.mm_per_unit,
                     measured_medium(args.material))
    sections = 5 + (not args.skip_transfer) + (not args.skip_sampling)
    with steps_bar("bench radiosity", sections, unit="section") as bar:
        state = _precomputation(scene, args, out)
        bar.update()
        for section in (_relighting, _translucency, _thresholds, _low_rank):
            arguments = {_relighting: (state, args, baseline, bandwidth, out),
                         _translucency: (state, args, baseline, out),
                         _thresholds: (state, out), _low_rank: (state, args, out)}[section]
            section(*arguments)
            bar.update()
        del state
        if not args.skip_transfer:
            _transfer(args, baseline, out)
            bar.update()
        if not args.skip_sampling:
            _sampling(out)
            bar.update()
    print("paper (GTX 590): 14 fps relighting, 4 fps translucency change, 4 + 3 min "
          "precomputation, 800 MB")
    path = write_figures(args.json, "radiosity", out)
    print(f"wrote {path}")
    return 0
