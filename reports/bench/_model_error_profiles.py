"""The profile axis of ``translucent bench model_error --profiles``: which profile, which method.

For each medium of the table and each radial profile asked (the default one, the classical
dipole, always), the BSSRDF path tracer renders the sphere with that profile (the model
reference, :mod:`translucent.reference.bssrdf_path`, at the reference's spp and passes),
and each method that takes the profile runs with it. A row holds, per profile: the model
error (model reference against the volumetric reference: two independent renders, so the
variance it discounts, and its noise floor, carry both), and per method its total error,
its approximation error (against the model reference; its floor is the model
reference's noise), its warm frame and its speed-up over path tracing at equal error
(the path-tracing ladder of the report, :mod:`translucent.reports.report.speedup`,
rendered once per medium). The pair (method,
profile) of lowest total relative MSE is named per medium, with its speed-up.

All relative MSEs are over the object's pixels, each with its reference's variance
discounted (:func:`~translucent.reports.bench.model_error.object_metrics`).
"""

from __future__ import annotations

from ...errors import InputError

__all__ = ["measure_profiles", "profiles_markdown"]


def measure_profiles(scene, medium, reference, mask, methods, profiles, default_runs, *,
                     spp: int, passes: int, metrics, noise,
                     knobs: dict | None = None) -> dict:
    """Return a medium's profile axis: model error, and per method total and approximation.

    Parameters
    ----------
    scene : Scene
        The bench scene with the medium in place.
    medium : Dipole
    reference : Image
        Its volumetric reference.
    mask : ndarray of bool
        The object's pixels.
    methods : sequence of str
    profiles : sequence of str
        Radial profiles; the default one is measured with the runs of ``default_runs``.
    default_runs : dict
        Method -> its :class:`~translucent.reports.report.runs.MethodRun` at the defaults.
    spp, passes : int
        The model references' samples (as the volumetric reference's).
    metrics : callable
        ``metrics(reference, test, mask) -> dict`` with ``relative_mse`` (the bench's
        :func:`~translucent.reports.bench.model_error.object_metrics`).
    noise : callable
        ``noise(image, mask) -> dict`` with ``noise_relative_mse`` (the bench's
        :func:`~translucent.reports.bench.model_error.reference_noise`).
    knobs : dict, optional
        Method -> knobs besides its defaults.
    """
    from ...fast.base import method
    from ...fast.knobs import DEFAULT_PROFILE
    from ..report.runs import run_method
    from ..report.speedup import PATH_TRACING_SPP, path_tracing_ladder, scored_curve
    from ..report.split import refused_profile

    curve = scored_curve(path_tracing_ladder(scene, PATH_TRACING_SPP), reference, mask)
    table: dict = {}
    for profile in [DEFAULT_PROFILE] + [p for p in profiles if p != DEFAULT_PROFILE]:
        table[profile] = found = _model_error(scene, reference, mask, profile, spp=spp,
                                              passes=passes, metrics=metrics, noise=noise)
        model = found.pop("model")
        refuses_medium = _refuses_medium(profile, medium)
        for name in methods:
            refusal = refused_profile(method(name), profile)
            if refusal is not None or refuses_medium:
                found["methods"][name] = {"status": "not applicable", "reason":
                                          refusal.sentence if refusal else refuses_medium}
                continue
            run = (default_runs[name] if profile == DEFAULT_PROFILE else
                   run_method(name, scene, {**(knobs or {}).get(name, {}), "profile": profile}))
            found["methods"][name] = _entry(run, reference, model, mask, curve, metrics)
    return {"profiles": table, "best": _best(table), "fastest": _fastest(table),
            "path_tracing": curve.as_dict() if curve is not None else None}


def _refuses_medium(profile: str, medium) -> str | None:
    """Return why ``profile`` takes no ``medium`` (burley_dmfp without absorption); else None.

    A method cannot run a profile its medium has none of: "not applicable", as a profile the
    method refuses, not "failed".
    """
    from ...fast.knobs import radial_profile

    try:
        radial_profile(profile, medium)
    except InputError as error:
        return f"the profile refuses this medium: {error.reason}"
    return None


def _model_error(scene, reference, mask, profile, *, spp, passes, metrics, noise) -> dict:
    """Return a profile's model error and floors, with its ``model`` render (None: why not).

    The methods still run where the profile has no model reference (the radial average of
    a directional profile): their total error needs none.
    """
    from ...reference import render
    from ..report.split import unrendered_profile, with_both_variances

    reason = unrendered_profile(profile)
    if reason:
        return {"error": reason, "model": None, "methods": {}}
    try:
        model = render(scene, spp=spp, passes=passes, progress=False,
                       integrator="bssrdf_path", profile=profile)
    except InputError as error:
        return {"error": error.reason, "model": None, "methods": {}}
    both = with_both_variances(reference, model)
    return {"model_relative_mse": metrics(both, model, mask)["relative_mse"],
            "model_noise_relative_mse": noise(both, mask)["noise_relative_mse"],
            "approximation_noise_relative_mse": noise(model, mask)["noise_relative_mse"],
            "model": model, "methods": {}}


def _entry(run, reference, model, mask, curve, metrics) -> dict:
    """Return one method with one profile: total and approximation error, frame, speed-up."""
    from ..report.speedup import speedup

    if run.status != "ok":
        return {"status": run.status, "reason": run.reason}
    total = metrics(reference, run.image, mask)["relative_mse"]
    found = speedup(curve, total, run.frame_seconds, None)
    approximation = None if model is None else metrics(model, run.image, mask)["relative_mse"]
    return {"status": "ok", "relative_mse": total,
            "approximation_relative_mse": approximation,
            "frame_seconds": run.frame_seconds,
            "speedup_vs_path_tracing": found["speedup_vs_path_tracing"],
            "speedup_extrapolated": found["extrapolated"]}


def _best(table: dict) -> dict | None:
    """Return the (method, profile) of lowest total relative MSE, and its speed-up."""
    return _chosen(table, "relative_mse", min)


def _fastest(table: dict) -> dict | None:
    """Return the (method, profile) of highest speed-up over path tracing at equal error.

    Where the errors are close the lowest error says little, the speed-up much (PRT and
    radiosity with one profile on an absorbing medium: the same error, ten times apart).
    """
    return _chosen(table, "speedup_vs_path_tracing", max)


def _chosen(table: dict, key: str, pick) -> dict | None:
    """Return the pair whose ``key`` ``pick`` (min or max) chooses among the runs that have it."""
    candidates = [(entry[key], name, profile, entry)
                  for profile, row in table.items() for name, entry in row["methods"].items()
                  if entry.get("status") == "ok" and entry.get(key) is not None]
    if not candidates:
        return None
    _, name, profile, entry = pick(candidates, key=lambda c: c[0])
    return {"method": name, "profile": profile, "relative_mse": entry["relative_mse"],
            "speedup_vs_path_tracing": entry["speedup_vs_path_tracing"],
            "speedup_extrapolated": entry["speedup_extrapolated"]}


def profiles_markdown(result: dict, table_cell) -> str:
    """Return the profile axis of a table as Markdown ("" when it has none).

    ``table_cell(value, digits)`` formats a number (the bench's own).
    """
    rows = [row for row in result["rows"] if row.get("profiles")]
    if not rows:
        return ""
    methods = result["methods"]
    header = ["medium", "profile", "model relMSE"]
    for name in methods:
        header += [f"{name} relMSE", f"{name} approx.", f"{name} vs PT"]
    lines = ["", "## The profile axis", "",
             "Per medium and profile: the model error (the BSSRDF path tracer's render of "
             "the profile against the volumetric reference), then per method its total "
             "relative MSE, its approximation error (against the profile's render) and its "
             "speed-up over path tracing at equal error (~: extrapolated). `*`: below "
             "the noise its references add (within noise).", "",
             "| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    why: dict = {}  # one sentence per profile without a model, per refused pair
    for row in rows:
        total_floor = row["reference"].get("noise_relative_mse")
        for profile, entry in row["profiles"]["profiles"].items():
            if entry.get("error"):
                why[f"{profile}: no model reference"] = entry["error"]
            cells = [row["medium"], profile, "none" if entry.get("error") else _floored(
                table_cell, entry.get("model_relative_mse"),
                entry.get("model_noise_relative_mse"))]
            for name in methods:
                method = entry["methods"].get(name, {})
                if method.get("status") != "ok":
                    if method.get("status") == "not applicable":
                        why[f"{name} with {profile}: not applicable"] = method["reason"]
                    cells += [method.get("status", "–"), "–", "–"]
                    continue
                speed = method["speedup_vs_path_tracing"]
                cells += [_floored(table_cell, method["relative_mse"], total_floor),
                          _floored(table_cell, method["approximation_relative_mse"],
                                   entry.get("approximation_noise_relative_mse")),
                          ("~" if method["speedup_extrapolated"] else "")
                          + (table_cell(speed, 2) + "x" if speed is not None else "–")]
            lines.append("| " + " | ".join(cells) + " |")
    lines += [""] + [f"- {what} ({reason})" for what, reason in why.items()]
    for key, title in (("best", "Lowest total error"), ("fastest", "Highest speed-up over "
                                                            "path tracing at equal error")):
        lines += ["", f"{title} per medium:", ""]
        for row in rows:
            lines.append(f"- {row['medium']}: {_pair(row['profiles'].get(key), table_cell)}")
    return "\n".join(lines) + "\n"


def _pair(pair: dict | None, table_cell) -> str:
    """Return a (method, profile) pair in words: its error and speed-up."""
    if pair is None:
        return "no method ran"
    speed = pair["speedup_vs_path_tracing"]
    return (f"{pair['method']} with {pair['profile']}, relative MSE "
            f"{table_cell(pair['relative_mse'])}, {'~' if pair['speedup_extrapolated'] else ''}"
            f"{table_cell(speed, 2) if speed is not None else '–'}x path tracing")


def _floored(table_cell, value, floor) -> str:
    """Return a cell, marked ``*`` where the value is below its noise floor."""
    if value is None:
        return "–"
    return table_cell(value) + ("*" if floor is not None and value < floor else "")
