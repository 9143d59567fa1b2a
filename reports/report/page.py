"""The report's page: one self-contained HTML file from the scenes' results."""

from __future__ import annotations

import html
from pathlib import Path

from ..metrics.registry import METRIC_LABELS, REPORTED_METRICS, TOLERANCES
from .baselines import BaselineCheck
from .formatting import format_seconds, format_speedup, format_value
from .model import SceneReport
from .runs import MethodRun

__all__ = ["html_page"]


def _reference_text(settings: dict) -> str:
    if settings.get("committed"):
        return (f"the committed ones of the built-in scenes, other scenes rendered to a median "
                f"relative standard error of {100 * settings['target_rse']:g} % (at most "
                f"{settings['budget_seconds']:g} s each)")
    return f"{settings['spp']} spp x {settings['passes']} passes, rendered for this run"


def _stylesheet() -> str:
    path = Path(__file__).resolve().parents[1] / "templates" / "report.css"
    return path.read_text(encoding="utf-8") if path.is_file() else ""


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _figure(src: str, caption: str, *, css: str = "", scale: str = "") -> str:
    return (f'<figure class="{css}"><img src="{_e(src)}" alt="{_e(caption)}">{scale}'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


#: Colours sampled along each colour bar (CSS interpolates between them).
COLOUR_BAR_STOPS = 17


def colour_bar(style) -> str:
    """Draw the scale of an error map under it: its colours, both ends and the unit.

    Parameters
    ----------
    style : MapStyle
        The map's colour map and range (:data:`~translucent.reports.metrics.maps.MAP_STYLES`).

    Returns
    -------
    str
        HTML: a gradient of the colour map's own colours from ``vmin`` to ``vmax``, values
        beyond clipped as in the map.
    """
    import numpy as np

    from ..metrics.maps import colour_map

    values = np.linspace(style.vmin, style.vmax, COLOUR_BAR_STOPS)[None, :]
    stops = ", ".join(f"rgb({r},{g},{b}) {100 * i / (COLOUR_BAR_STOPS - 1):.4g}%"
                      for i, (r, g, b) in enumerate(colour_map(values, style)[0]))
    low, high = f"{style.vmin:g}", f"{style.vmax:g}"
    return (f'<div class=scale title="{_e(style.unit)}">'
            f'<div class=bar style="background: linear-gradient(to right, {stops})"></div>'
            f"<div class=ends><span>{_e(low)}</span><span>{_e(style.unit)}</span>"
            f"<span>{_e(high)}</span></div></div>")


def _verdict_class(status: str) -> str:
    return {"regression": "bad", "improved": "good", "ok": "ok"}.get(status, "note")


def html_page(reports: list[SceneReport], chosen: list[str], context: dict) -> str:
    """Return the report's ``index.html``: summary, legend, one section per scene."""
    from ..metrics.maps import MAP_STYLES

    versions = context["versions"]
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        "<title>translucent report</title>",
        f"<style>{_stylesheet()}</style></head><body>",
        "<h1>Fast methods against their references</h1>",
        f"<p class=meta>Generated {_e(context['generated'])}; Mitsuba {_e(versions['mitsuba'])} "
        f"({_e(versions['variant'])}), Dr.Jit {_e(versions['drjit'])}; references: "
        f"{_e(_reference_text(context['reference']))}; tasks "
        f"on {_e(context['scheduler'])}; whole run {context['seconds']:.1f} s.</p>",
    ]
    regressions = context["regressions"]
    if regressions:
        parts.append(f'<p class="verdict bad">{len(regressions)} regression(s) against the '
                     f"baseline <code>{_e(context['baseline'])}</code>"
                     f"{' (baseline now rewritten)' if context['baseline_updated'] else ''}:"
                     "</p><ul class=bad>" + "".join(f"<li>{_e(r)}</li>" for r in regressions)
                     + "</ul>")
    else:
        rewritten = " (baseline rewritten from this run)" if context["baseline_updated"] else ""
        # the results with metrics: a method that did not apply has nothing to compare
        checks = [check for report in reports for name, check in report.checks.items()
                  if name in report.metrics]
        compared = sum(check.status in ("ok", "improved") for check in checks)
        unmatched = sum(check.status == "no baseline" for check in checks)
        other = sum(check.status == "not compared" for check in checks)
        reasons = ", ".join(filter(None, [
            f"{unmatched} result(s) had no baseline entry" if unmatched else "",
            f"{other} were made against another reference" if other else ""]))
        baseline = f"<code>{_e(context['baseline'])}</code>"
        if compared:
            extra = f"; {reasons}" if reasons else ""
            parts.append(f'<p class="verdict ok">No regression in the {compared} result(s) '
                         f"compared with the baseline {baseline}{extra}{rewritten}.</p>")
        else:
            parts.append(f'<p class="verdict fail">Nothing was compared with the baseline '
                         f"{baseline} ({reasons or 'no result to compare'}){rewritten}; no "
                         "regression can be told.</p>")
    summary = _summary_table(reports, chosen)
    if context.get("overview"):
        summary = (f'<div class="row overview">{summary}'
                   + _figure(context["overview"], "every method on every scene: warm frame "
                             "time against relative MSE over the pixels it is scored on",
                             css="overview") + "</div>")
    parts.append(summary)
    parts.append(_summary_note())
    parts.append(_legend(MAP_STYLES))
    if context["excluded"]:
        parts.append("<h2>Built-in scenes left out</h2><ul>" + "".join(
            f"<li><b>{_e(n)}</b>: {_e(r)}</li>" for n, r in context["excluded"].items())
            + "</ul>")
    for report in reports:
        parts.append(_scene_section(report, chosen))
    parts.append(_tolerance_note())
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def _summary_table(reports: list[SceneReport], chosen: list[str]) -> str:
    head = "".join(f"<th>{_e(n)}</th>" for n in chosen)
    rows = []
    for report in reports:
        cells = []
        for name in chosen:
            run = report.runs.get(name)
            metrics = report.metrics.get(name)
            check = report.checks.get(name)
            css = _verdict_class(check.status) if check else "note"
            if metrics is not None:
                text = (f'<a href="#{_e(report.slug)}-{_e(name)}">'
                        f"{_score_line(report, name, 'hdr_flip', 'FLIP', 3)}</a><br>"
                        f"{_score_line(report, name, 'relative_mse', 'relMSE', 2)}<br>"
                        f"{_split_line(report, name)}"
                        f"{_times_line(report, name, run)} "
                        f'<span class="tag">{_e(check.status)}</span>')
            elif run is not None and run.status in ("not applicable", "not installed", "not run"):
                text, css = f"<small>{_e(run.status)}</small>", "muted"
                if check is not None and check.status == "regression":
                    text, css = f"<small>{_e(run.status)}; regression</small>", "bad"
            else:
                status = run.status if run else "not run"
                if status == "ok":
                    status = "no metrics"  # an image but no reference, or metrics failed
                text = (f"<small>{_e(status)}"
                        f"{'; regression' if check and check.status == 'regression' else ''}"
                        "</small>")
                css = "bad" if check is not None and check.status == "regression" else "fail"
            cells.append(f'<td class="{css}">{text}</td>')
        rows.append(f'<tr><th><a href="#{_e(report.slug)}">{_e(report.name)}</a></th>'
                    + "".join(cells) + "</tr>")
    return f'<table class=summary><tr><th>scene</th>{head}</tr>{"".join(rows)}</table>'


def _summary_note() -> str:
    """Return what the summary table's cells hold."""
    return ("<p class=meta>Per method: HDR-FLIP and relative MSE against the reference (0 is "
            "identical) over the pixels of the objects, each beside its noise floor (what "
            "the reference's own noise alone gives; <i>within noise</i>: the value does not "
            "clear it); the precomputation, the warm frame (median of the relit frames; the "
            "first frame, which can include compiling kernels, is in the scene's section) "
            "and the speed-up over Mitsuba path tracing at the same relative MSE (~: "
            "extrapolated beyond the path-tracing ladder); the verdict against the "
            "baseline. For a method of a radial profile, its error split: <i>model</i>, the "
            "profile rendered exactly by the BSSRDF path tracer against the reference; "
            "<i>method</i>, the method against that render; and which part dominates (one "
            "at least twice the other and clear of its noise). <code>METHOD@PROFILE</code>: "
            "the method run with another profile.</p>")


def _score_line(report: SceneReport, name: str, key: str, label: str, digits: int) -> str:
    """Return one metric of a summary cell: its value, its noise floor, whether within it."""
    value = report.metrics[name].get(key)
    floor = (report.floor_of(name) or {}).get(key)
    noisy = report.verdicts.get(name, {}).get(key) == "within reference noise"
    floor_text = f" <small>(noise {format_value(floor, 2)})</small>" if floor is not None else ""
    mark = " <small class=fail>within noise</small>" if noisy else ""
    return f"{label} {_e(format_value(value, digits))}{floor_text}{mark}"


#: How a summary cell names the part of the error that dominates (:mod:`.split`).
DOMINANT_TEXT = {"model": "the profile's error dominates",
                 "approximation": "the method's own error dominates",
                 "both": "profile and method share it",
                 "within noise": "neither part clears its noise"}


def _split_line(report: SceneReport, name: str) -> str:
    """Return a summary cell's split: model and approximation relative MSE, which dominates."""
    split = report.splits.get(name)
    if split is None or split.reason:
        return ""
    model = format_value(split.model.get("relative_mse"), 2)
    approximation = format_value(split.approximation.get("relative_mse"), 2)
    return (f"<small>model {_e(model)}, method {_e(approximation)}: "
            f"<b>{_e(DOMINANT_TEXT.get(split.dominant, split.dominant))}</b></small><br>")


def _split_block(report: SceneReport, name: str) -> str:
    """Return a method's split: total, model and approximation error, floors and verdicts."""
    split = report.splits.get(name)
    if split is None:
        return ""
    if split.reason:
        return f"<p class=meta>{_e(split.sentence())}</p>"
    rows = []
    parts = [("total (method against transport)", report.metrics[name],
              report.floor_of(name), report.verdicts.get(name, {})),
             (f"model (profile {split.profile} rendered exactly, against transport)",
              split.model, split.model_floor, split.model_verdicts),
             *((f"step {step.label} (against "
                f"{step.against or 'transport'})", step.metrics, step.floor, step.verdicts)
               for step in split.steps),
             ("approximation (method against its profile rendered exactly)",
              split.approximation, split.approximation_floor, split.approximation_verdicts)]
    noisy = " <small class=fail>within noise</small>"
    for label, metrics, floor, verdicts in parts:
        cells = "".join(
            f"<td>{_e(format_value(metrics.get(key), 3))} <small>(noise "
            f"{_e(format_value((floor or {}).get(key), 2))})</small>"
            f"{noisy if verdicts.get(key) == 'within reference noise' else ''}"
            "</td>" for key in ("relative_mse", "hdr_flip"))
        rows.append(f"<tr><th>{_e(label)}</th>{cells}</tr>")
    info = split.model_reference
    origin = (f"Model reference: {_e(info.get('source', ''))}, BSSRDF path tracer, "
              f"{_e(info.get('spp'))} spp x {_e(info.get('passes'))} passes.")
    return ("<h4>Why: the error split</h4><table class=small><tr><th></th><th>relative MSE"
            "</th><th>HDR-FLIP</th></tr>" + "".join(rows) + "</table>"
            f"<p>{_e(split.sentence())} <span class=meta>{origin}</span></p>")


def _times_line(report: SceneReport, name: str, run) -> str:
    """Return a summary cell's times: precomputation, warm frame, speed-up."""
    found = report.speedups.get(name) or {}
    speed = format_speedup(found.get("speedup_vs_path_tracing"), found.get("extrapolated"))
    why = found.get("reason") if found.get("speedup_vs_path_tracing") is None else None
    title = f' title="{_e(why)}"' if why else ""
    return (f"<small>precompute {_e(format_seconds(run.precompute_seconds))}, frame "
            f"{_e(format_seconds(run.frame_seconds))}, <span{title}>vs path tracing "
            f"{_e(speed)}</span></small>")


def _legend(styles) -> str:
    items = "".join(f"<li><b>{_e(name)}</b>: {_e(style.unit)}, colour map {_e(style.colormap)} "
                    f"from {style.vmin:g} to {style.vmax:g}</li>"
                    for name, style in styles.items() if name != "p_value")
    return (f"<details><summary>How to read the error maps</summary><ul>{items}</ul><p>"
            "Grey stripes: not scored. A map shows in colour the pixels its method's "
            "numbers count (the objects it renders); the others are hatched grey. Method "
            "images are shown with the reference's exposure (its 99th-percentile "
            "luminance is white), so a brightness error stays visible.</p></details>")


def _scene_section(report: SceneReport, chosen: list[str]) -> str:
    parts = [f'<section id="{_e(report.slug)}"><h2>{_e(report.name)}</h2>',
             f"<p>{_e(report.scene.description)}</p>"]
    if report.reference is not None:
        meta = report.reference.metadata
        caption = (f"reference: {meta.get('integrator', '?')}, {meta.get('spp')} spp x "
                   f"{meta.get('passes')} passes, rendered in {format_seconds(meta.get('seconds'))}"
                   f"{_reference_origin(report)}")
        row = _figure(report.files["reference"]["png"], caption, css="reference")
        if "tradeoff" in report.files:
            row += _figure(report.files["tradeoff"]["png"], _tradeoff_caption(report),
                           css="tradeoff")
        parts.append('<div class=row>' + row + "</div>")
        for sentence in meta.get("substitutions") or []:
            parts.append(f"<p class=note>Reference: {_e(sentence)}</p>")
        source = {"committed": "committed with the suite (translucent references)",
                  "progressive": f"rendered to a noise target ({meta.get('stopped', '?')})",
                  "fixed passes": "rendered in fixed passes for this run"}.get(
                      report.reference_source, report.reference_source)
        noise = (f"; relative standard error {report.reference_noise.text()}"
                 if report.reference_noise is not None else "")
        parts.append(f"<p class=meta>Reference {_e(source)}{_e(noise)}.</p>")
        if report.scored_mask is not None:
            parts.append(f"<p class=meta>Every metric below is computed over the "
                         f"{int(report.scored_mask.sum())} pixels that see an object of the "
                         "scene (the background, the same in every image, is left out); "
                         "whole-image values are in metrics.json (<code>image_metrics</code>)."
                         "</p>")
        if report.noise_warning:
            parts.append(f"<p class=fail>Warning: {_e(report.noise_warning)}.</p>")
    else:
        parts.append(f"<p class=fail>The reference could not be rendered: "
                     f"{_e(report.reference_error)}</p>")
    not_run = []
    for name in chosen:
        run = report.runs.get(name)
        if run is None or run.status in ("not applicable", "not installed", "not run"):
            reason = run.reason if run else "not run"
            status = run.status if run else "not run"
            extra = ""
            check = report.checks.get(name)
            if check is not None and check.status == "regression":
                extra = f' <span class=bad>regression: {_e(check.message)}</span>'
            not_run.append(f"<li><b>{_e(name)}</b> ({_e(status)}): {_e(reason)}{extra}</li>")
            continue
        parts.append(_method_block(report, name, run))
    if not_run:
        parts.append("<h3>Methods not run on this scene</h3><ul>" + "".join(not_run) + "</ul>")
    parts.append("</section>")
    return "\n".join(parts)


def _tradeoff_caption(report: SceneReport) -> str:
    """Caption of the run-time-against-error plot: what is drawn, the speed-ups."""
    spp = ", ".join(str(n) for n in report.curve.spp) if report.curve is not None else ""
    speeds = "; ".join(
        f"{name} {format_speedup(v['speedup_vs_path_tracing'], v['extrapolated'])}"
        for name, v in report.speedups.items() if v["speedup_vs_path_tracing"] is not None)
    missing = report.curve.error if report.curve is not None and report.curve.error else ""
    return (f"run time against relative MSE: path tracing at {spp} spp, each method's warm "
            f"frame at its defaults (filled) and at the cheap end of its quality ladder "
            f"(hollow, joined by a dashed line); the red dashed line is the reference's noise "
            f"floor"
            f"{'; speed-up at equal error: ' + speeds if speeds else ''}"
            f"{'; path tracing: ' + missing if missing else ''}")


def _reference_origin(report: SceneReport) -> str:
    if report.reference_source == "committed":
        return " (committed with the suite)"
    return " (from the cache)" if report.reference_cached else ""


def _method_block(report: SceneReport, name: str, run: MethodRun) -> str:
    from ..metrics.maps import MAP_STYLES

    check = report.checks.get(name)
    anchor = f"{report.slug}-{name}"
    parts = [f'<div class=method id="{_e(anchor)}"><h3>{_e(name)}']
    if check is not None:
        parts.append(f' <span class="tag {_verdict_class(check.status)}">{_e(check.status)}'
                     "</span>")
    parts.append("</h3>")
    if run.status == "failed":
        parts.append(f"<p class=fail>The method failed: {_e(run.reason)}</p>")
        if run.details:
            parts.append(f"<details><summary>traceback</summary><pre>{_e(run.details)}</pre>"
                         "</details>")
    files = report.files.get(name, {})
    if files:
        figures = [_figure(files["png"], f"{name}")]
        for map_name in ("flip", "relative_error", "ciede2000", "ssim"):
            if f"map_{map_name}" in files:
                figures.append(_figure(files[f"map_{map_name}"], map_name.replace("_", " "),
                                       scale=colour_bar(MAP_STYLES[map_name])))
        if report.reference is not None:
            figures.insert(0, _figure(report.files["reference"]["png"], "reference"))
        parts.append('<div class=row>' + "".join(figures) + "</div>")
    if name in report.metric_errors:
        parts.append(f"<p class=fail>No metrics: {_e(report.metric_errors[name])}</p>")
    if check is not None:
        parts.append(f'<p class="{_verdict_class(check.status)}">Baseline: {_e(check.message)}'
                     "</p>")
    metrics = report.metrics.get(name)
    if metrics is not None and name in report.method_masks:
        mask = report.method_masks[name]
        count = int(mask.sum()) if mask is not None else 0
        parts.append(f"<p class=meta>Scored on the {count} pixels of the objects it renders "
                     f"({_e(', '.join(report.scored_objects[name]))}); the others it leaves "
                     "black, and they are not scored.</p>")
    if metrics is not None:
        parts.append(_metrics_table(metrics, check, report.floor_of(name),
                                    report.verdicts.get(name, {})))
        parts.append(_split_block(report, name))
        parts.append(_systematic_line(report, name))
    if run.status == "ok":
        cached = (f" Image and times from the run of {_e(run.measured_at)} (cached: nothing "
                  "it depends on has changed since)." if run.cached else "")
        cache_note = run.notes.get("cache") if isinstance(run.notes, dict) else None
        notes = cache_note.values() if isinstance(cache_note, dict) else [cache_note]
        from_cache = (" The method loaded its precomputation from its own cache; the stage "
                      "times below are those of the run that computed it."
                      if cache_note and all(note == "hit" for note in notes) else "")
        first = run.first_frame_seconds if run.first_frame_seconds is not None \
            else run.frame_seconds
        parts.append(f"<p>Precomputation {format_seconds(run.precompute_seconds)}, first frame "
                     f"(the first <code>state.render()</code>, first-call costs included) "
                     f"{format_seconds(first)}, warm frame (the median of the relit frames) "
                     f"{format_seconds(run.frame_seconds)}{_speedup_sentence(report, name)}."
                     f"{_ratio_sentence(report, name)}{cached}{from_cache}</p>")
        parts.append(_ladder_sentence(report, name))
        if run.stage_seconds:
            parts.append("<details><summary>stage times</summary><table class=small>" + "".join(
                f"<tr><td>{_e(stage)}</td><td>{format_seconds(seconds)}</td></tr>"
                for stage, seconds in run.stage_seconds.items()) + "</table></details>")
    solid = run.notes.get("solid medium") if isinstance(run.notes, dict) else None
    if solid:
        parts.append(_solid_note(name, solid))
    if run.skipped:
        parts.append("<p>Skipped for this scene:</p><ul class=skipped>" + "".join(
            f"<li>{_e(sentence)}</li>" for sentence in run.skipped) + "</ul>")
    elif run.status == "ok":
        parts.append("<p class=meta>The method skipped nothing for this scene.</p>")
    parts.append("</div>")
    return "\n".join(parts)


def _systematic_line(report: SceneReport, name: str) -> str:
    """Say how bright the image is against the reference, and its converged error.

    The converged error needs the image's own variance (:func:`~.scoring.systematic_error`).
    """
    found = report.systematic.get(name) or {}
    bright = found.get("brightness_to_reference")
    converged = found.get("relative_mse_converged")
    words = []
    if bright:
        words.append("Summed over its pixels, against the reference: " + " / ".join(
            f"{100.0 * (r - 1.0):+.1f} %" for r in bright["ratio"]) + " (R / G / B; standard "
            "errors " + " / ".join(f"{100.0 * e:.2f}" for e in bright["standard_error"]) +
            " %).")
    if converged:
        words.append(f"Relative MSE with its own noise discounted too (converged) "
                     f"{format_value(converged['value'], 3)} +- "
                     f"{format_value(converged['standard_error'], 2)}.")
    return f"<p class=meta>{_e(' '.join(words))}</p>" if words else ""


def _ratio_sentence(report: SceneReport, name: str) -> str:
    """Return the times as multiples of a 1-spp path-traced render timed in the same run."""
    from .speedup import same_run_ratios

    ratios = same_run_ratios(report.curve, report.runs.get(name))
    frame = ratios["frame_in_path_traced_1spp_renders"]
    if frame is None:
        return ""
    precompute = ratios["precompute_in_path_traced_1spp_renders"]
    return (f" In 1-spp path-traced renders of this scene timed in the same run "
            f"({format_seconds(ratios['path_tracing_1spp_seconds'])} each): a warm frame takes "
            f"{format_value(frame)}"
            + (f", the precomputation {format_value(precompute)}" if precompute is not None
               else "") + ".")


def _ladder_sentence(report: SceneReport, name: str) -> str:
    """One line per cheaper setting the report ran: its knobs, error and times."""
    lines = []
    for entry in report.ladder_points.get(name, []):
        knobs = ", ".join(f"{k} = {v}" for k, v in entry["knobs"].items())
        if entry["relative_mse"] is None:
            lines.append(f"<li><code>{_e(knobs)}</code>: {_e(entry['status'])} "
                         f"{_e(entry['reason'])}</li>")
            continue
        lines.append(f"<li><code>{_e(knobs)}</code>: relative MSE "
                     f"{format_value(entry['relative_mse'])}, precomputation "
                     f"{format_seconds(entry['precompute_seconds'])}, warm frame "
                     f"{format_seconds(entry['frame_seconds'])}</li>")
    if not lines:
        return ""
    return "<p>At cheaper settings (the plot's hollow point):</p><ul>" + "".join(lines) + "</ul>"


def _speedup_sentence(report: SceneReport, name: str) -> str:
    """Return ", N x faster than path tracing at equal error" or why it is not given."""
    found = report.speedups.get(name)
    if not found:
        return ""
    if found["speedup_vs_path_tracing"] is None:
        return f"; no speed-up over path tracing: {_e(found['reason'])}"
    extra = f" ({_e(found['reason'])})" if found["reason"] else ""
    return (f"; {format_speedup(found['speedup_vs_path_tracing'], found['extrapolated'])} "
            f"faster than Mitsuba path tracing at the same relative MSE "
            f"({format_seconds(found['path_tracing_seconds'])}){extra}")


def _solid_note(method_name: str, conversions: dict) -> str:
    """Say what a method assumed of a solid medium and what reading it at the surface cost."""
    from ...fast.solid_inputs import SURFACE_ASSUMPTIONS

    assumption = SURFACE_ASSUMPTIONS.get(method_name, "the medium is read at the surface")
    items = "".join(
        f"<li>{_e(obj)}: {int(note.get('media', 0))} media, quantisation error "
        f"{format_value(note.get('quantisation_error'))}, SubEdit fit error "
        f"{format_value(note.get('profile_error'))}</li>" for obj, note in conversions.items())
    return (f"<p class=note>The reference renders the medium in the volume; {_e(method_name)} "
            f"reads it at the surface and assumes that {_e(assumption)}.</p><ul class=small>"
            f"{items}</ul>")


def _metrics_table(metrics: dict, check: BaselineCheck | None, floors: dict | None = None,
                   verdicts: dict | None = None) -> str:
    from ..metrics.compute import NOISE_MARGIN

    gated = check.metrics if check is not None else {}
    floors, verdicts = floors or {}, verdicts or {}
    rows = []
    for key in REPORTED_METRICS:
        value = metrics.get(key)
        entry = gated.get(key)
        noise = verdicts.get(key, "")
        noise_css = " muted" if noise == "within reference noise" else ""
        noise_cells = (f"<td>{format_value(floors.get(key))}</td>"
                       f'<td class="{noise_css.strip()}">{_e(noise)}</td>')
        if entry is not None:
            css = {"worse": "bad", "better": "good"}.get(entry["verdict"], "")
            rows.append(f'<tr class="{css}"><td>{_e(METRIC_LABELS[key])}</td>'
                        f"<td>{format_value(value)}</td>{noise_cells}"
                        f"<td>{format_value(entry['baseline'])}</td>"
                        f"<td>{format_value(entry['limit'])}</td><td>{_e(entry['verdict'])}</td></tr>")
        else:
            tolerance = "gated" if key in TOLERANCES else ""
            rows.append(f"<tr><td>{_e(METRIC_LABELS[key])}</td><td>{format_value(value)}</td>"
                        f"{noise_cells}<td>–</td><td>–</td><td>{tolerance}</td></tr>")
    return ("<table class=metrics><tr><th>metric</th><th>value</th><th>noise floor</th>"
            "<th>against the noise</th><th>baseline</th><th>worst accepted</th>"
            "<th>against the baseline</th></tr>" + "".join(rows) + "</table>"
            "<p class=meta>Noise floor: what the metric gives when the only difference is the "
            "reference's own noise (the reference against itself perturbed by noise of its "
            f"variance). 'within reference noise': the value does not clear the floor by a "
            f"factor of {NOISE_MARGIN:g} (errors; 1 - SSIM; the MSE behind PSNR), so the "
            "reference cannot "
            "tell this method from a perfect one by this metric.</p>")


def _tolerance_note() -> str:
    items = "".join(
        f"<li>{_e(METRIC_LABELS[name])}: worse by more than {t.absolute:g}"
        f"{f' + {t.relative:.0%} of the baseline' if t.relative else ''}</li>"
        for name, t in TOLERANCES.items())
    return (f"<h2>Regression tolerances</h2><p>A result is a regression when a gated metric "
            f"is worse than its baseline by more than:</p><ul>{items}</ul>")
