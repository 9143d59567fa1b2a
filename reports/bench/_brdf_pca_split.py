"""``translucent bench brdf_pca --split``: where BRDF editing's error comes from.

On each scene of :data:`SPLIT_SCENES` (``glossy``, and ``glossy_box``, a glossy sphere
and block in a Cornell box), the method's error against the exact-BRDF reference, split
along the chain of models it stands on, each rendered exactly by Mitsuba with the
scene's committed references (:data:`~translucent.reference.committed.MODEL_PLANS`):

* the PCA of its BRDFs (``brdf_pca_k6`` against the exact BRDFs);
* its transport: gather samples that reflect diffusely (``+lambertian_gather2`` against
  ``brdf_pca_k6``, Sect. 5.2), or by their BRDF for their direct light
  (``+glossy_gather2``, the knob ``gather_reflection="brdf"``);
* its own approximation of that transport (the method against it), in parts measured by
  removing each: the one-ray G-buffer (the pixels on objects' edges, which the
  reference's pixel filter anti-aliases, against the interior ones), the wavelet
  truncation (every Haar coefficient kept, at fewer gather samples so that the dense
  rows fit), the gather samples (4096 against the default 16384).

Each row also times the warm relit frame (a moved point light), since the knob that
removes the largest part costs frame time. Relative MSE over the pixels that see an
object, as the report's.
"""

from __future__ import annotations

import time

import numpy as np

from ...fast import brdf_pca

#: The configurations measured: (label, knobs). ``--quick`` runs them with fewer gather
#: samples (:data:`QUICK_GATHERS`).
CONFIGURATIONS = [
    ("defaults (gather_reflection lambertian)", {}),
    ("4096 gather samples", {"gather_samples": 4096}),
    # every basis gets at least a budget's 1 / (4 (K + 1)) (transfer._budgets): 28 x 4096
    # keeps all 4096 coefficients of each of the K + 1 = 7 rows
    ("4096 gather samples, every coefficient", {
        "gather_samples": 4096, "transfer_coefficients": 4096 * 28,
        "diffuse_coefficients": 4096, "gather_coefficients": 4096}),
    ("gather_reflection brdf", {"gather_reflection": "brdf"}),
    ("gather_reflection brdf, 1024 blocks", {"gather_reflection": "brdf",
                                             "reflection_blocks": 1024}),
]

#: The scenes split (their references and model references are committed); ``--quick``
#: splits the first alone.
SPLIT_SCENES = ("glossy", "glossy_box")

#: Gather samples of every configuration under ``--quick`` (a smoke run).
QUICK_GATHERS = 64

#: The ratio of two parts beyond which one is named the dominant one.
DOMINANT_RATIO = 2.0


def _errors(reference, image, masks) -> dict:
    from ..metrics.compute import relative_mse

    return {name: float(relative_mse(reference.rgb[mask], image.rgb[mask],
                                     reference_variance=reference.variance[mask]))
            for name, mask in masks.items()}


def _relit_frame_seconds(state, frames: int = 3) -> float:
    """Return the median relit frame (nudged lights, as the report times a frame)."""
    from ..report.runs import nudged_lights

    seconds = []
    for frame in range(frames):
        lights = nudged_lights(state.scene.lights, frame + 1)
        started = time.perf_counter()
        state.render(lights=lights)
        seconds.append(time.perf_counter() - started)
    state.render(lights=state.scene.lights)
    return float(np.median(seconds))


def split(quick: bool = False) -> dict:
    """Measure and print the split of every scene (see the module); return its figures."""
    return {"scenes": {name: split_scene(name, quick)
                       for name in (SPLIT_SCENES[:1] if quick else SPLIT_SCENES)}}


def split_scene(name: str, quick: bool = False) -> dict:
    """Measure and print the split on built-in scene ``name``; return its figures."""
    from ...reference.committed import committed_reference
    from ...scenes import load_scene
    from ...scenes.gbuffer import gbuffer, interior_pixels
    from ..report.split import model_steps, with_both_variances

    scene = load_scene(name)
    exact = committed_reference(name).require()
    hit = gbuffer(scene).hit
    interior = interior_pixels(scene)
    masks = {"all": hit, "interior": interior, "edges": hit & ~interior}
    models = {}
    print(f"\nerror split on {name!r} ({scene.camera.width} x {scene.camera.height}; relative "
          "MSE over the pixels that see an object, 'edges' those whose 3 x 3 neighbourhood "
          f"sees two objects: {int(masks['edges'].sum())} of {int(hit.sum())})")

    def model(key):
        if key not in models:
            models[key] = committed_reference(name, profile=key).require()
        return models[key]

    # the steps of the method's models with either gather reflection (report.split's)
    steps = {}
    for reflection in ("lambertian", "brdf"):
        keys = model_steps(brdf_pca.model_name({"gather_reflection": reflection}))
        steps.update(zip(keys, [None, *keys[:-1]], strict=True))
    chain = {}
    for key, against in steps.items():
        earlier = exact if against is None else model(against)
        both = with_both_variances(earlier, model(key))
        chain[key] = {"against": against or "exact",
                      "relative_mse": _errors(both, model(key), {"all": hit})["all"],
                      "to_exact": _errors(exact, model(key), {"all": hit})["all"]}
        print(f"  model {key:32s} against {against or 'exact BRDFs':32s} "
              f"{chain[key]['relative_mse']:9.5f}  (to exact {chain[key]['to_exact']:.5f})")
    if quick:
        print(f"  (--quick: every configuration with {QUICK_GATHERS} gather samples)")
    rows = []
    for label, knobs in CONFIGURATIONS:
        knobs = dict(knobs)
        if quick:
            knobs["gather_samples"] = QUICK_GATHERS
            for key in ("transfer_coefficients", "diffuse_coefficients", "gather_coefficients"):
                if key in knobs:
                    knobs[key] = QUICK_GATHERS * (28 if key == "transfer_coefficients" else 1)
        started = time.perf_counter()
        state = brdf_pca.precompute(scene, **knobs)
        image = state.render()
        seconds = time.perf_counter() - started
        key = brdf_pca.model_name(knobs)
        row = {"label": label, "knobs": knobs, "model": key,
               "to_exact": _errors(exact, image, {"all": hit})["all"],
               "to_model": _errors(model(key), image, masks),
               "first_frame_seconds": seconds,
               "relit_frame_seconds": _relit_frame_seconds(state)}
        rows.append(row)
        own = row["to_model"]
        print(f"  {label:44s} to exact {row['to_exact']:.5f} | to its model {own['all']:.5f} "
              f"(interior {own['interior']:.5f}, edges {own['edges']:.5f}) | relit frame "
              f"{1e3 * row['relit_frame_seconds']:.1f} ms", flush=True)
    parts = _parts(chain, rows, masks)
    print("  parts of the default's error against the exact BRDFs (relative MSE): " + ", ".join(
        f"{part} {value:.5f}" for part, value in parts["values"].items())
        + f"; dominant: {parts['dominant']}")
    return {"models": chain, "rows": rows, "parts": parts,
            "edge_pixels": int(masks["edges"].sum()), "pixels": int(hit.sum())}


def _parts(chain: dict, rows: list, masks: dict) -> dict:
    """Attribute the default's error: each part as the error it adds, in relative MSE."""
    default, coarse, every = rows[0], rows[1], rows[2]
    share = masks["edges"].sum() / masks["all"].sum()
    values = {
        "PCA of the BRDFs": chain["brdf_pca_k6"]["relative_mse"],
        "Lambertian gather samples": chain["brdf_pca_k6+lambertian_gather2"]["relative_mse"],
        # all = share * edges + (1 - share) * interior: the edges' excess over the interior
        "one-ray G-buffer (edges)": float(share * (default["to_model"]["edges"]
                                                  - default["to_model"]["interior"])),
        "interior (gather samples, sub-areas, wavelets)": default["to_model"]["interior"],
    }
    ranked = sorted(values.items(), key=lambda item: item[1], reverse=True)
    dominant = ranked[0][0] if ranked[0][1] >= DOMINANT_RATIO * ranked[1][1] else \
        f"{ranked[0][0]} and {ranked[1][0]}"
    # a part of the interior's, measured where every coefficient fits
    values["of the interior: wavelet truncation at 4096 gather samples"] = \
        coarse["to_model"]["interior"] - every["to_model"]["interior"]
    return {"values": values, "dominant": dominant}
