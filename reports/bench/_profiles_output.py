r"""What ``translucent bench profiles`` writes besides its JSON: the Markdown and the plots.

Both read only the figures :mod:`translucent.reports.bench.profiles` measured (the result
dict, the panels' arrays), so that this module knows nothing of how they were measured.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np

__all__ = ["joined", "markdown", "percent", "plot_medium"]

#: Profiles from this index on are drawn dashed (ten colours, ten profiles: the styles tell
#: the two halves apart in print).
DASHED_FROM = 5
#: The top panels reach this many times the walk's highest point.
CEILING = 1.8
#: The ratio panels' range and ticks.
RATIO_RANGE = (0.25, 4.0)
RATIO_TICKS = (0.25, 0.5, 1.0, 2.0, 4.0)
#: Colours of the written PNG: ten profiles, black, grey and their antialiasing (fewer
#: merge the profiles' hues).
PALETTE_COLOURS = 256


def plot_medium(path: Path, name: str, panels) -> Path:
    r"""Write one medium's profiles against the walk, one column a channel, as a small PNG.

    Top: the energy of each ring per unit :math:`\ln r`, the walk as points with two
    standard errors, each profile as a line; bottom: each profile's ring energy over the
    walk's, inside the radius holding 99 % of the walk's energy.

    Parameters
    ----------
    path : Path
        The PNG to write.
    name : str
        The medium, for the titles.
    panels : sequence of dict
        Per channel: ``channel`` (a letter), ``centre`` (ring centres, mm), ``log_width``
        (each ring's ln(outer/inner)), ``walk`` and ``walk_se`` (the walk's ring energies
        and standard errors), ``rings`` (indices inside the 99 % radius), ``radius_99``
        (mm) and ``profiles`` (name -> ring energies).

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(2, len(panels), figsize=(10, 5.2), sharex="col",
                                gridspec_kw={"height_ratios": [2, 1]}, squeeze=False)
    colours = plt.get_cmap("tab10")
    for column, panel in enumerate(panels):
        top, bottom = axes[0, column], axes[1, column]
        centre, width, walked = panel["centre"], panel["log_width"], panel["walk"]
        rings = panel["rings"]
        top.errorbar(centre, walked / width, yerr=2.0 * panel["walk_se"] / width, fmt="o",
                     ms=2.5, color="black", label="random walk (MC)", zorder=3)
        for index, (label, energy) in enumerate(panel["profiles"].items()):
            style = "--" if index >= DASHED_FROM else "-"
            top.plot(centre, energy / width, style, lw=1.1, color=colours(index), label=label)
            with np.errstate(divide="ignore", invalid="ignore"):
                bottom.plot(centre[rings], energy[rings] / walked[rings], style, lw=1.1,
                            color=colours(index))
        top.set_xscale("log")
        # the walk sets the scale: a profile far off (the directional dipole's excess
        # energy) leaves the panel rather than flattening the others
        top.set_ylim(0.0, CEILING * float(np.max(walked / width)))
        top.set_title(f"{name}, {panel['channel']}: 99 % inside {panel['radius_99']:.3g} mm",
                      fontsize=9)
        bottom.set_yscale("log")
        bottom.set_ylim(*RATIO_RANGE)
        bottom.set_yticks(RATIO_TICKS, [f"{t:g}" for t in RATIO_TICKS])
        bottom.minorticks_off()
        bottom.axhline(1.0, color="black", lw=0.8)
        bottom.set_xlabel("r (mm)", fontsize=8)
        for axis in (top, bottom):
            axis.tick_params(labelsize=7)
    axes[0, 0].set_ylabel("ring energy per unit ln r", fontsize=8)
    axes[1, 0].set_ylabel("profile / MC", fontsize=8)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    figure.legend(handles, labels, loc="lower center", ncol=6, fontsize=7, frameon=False)
    figure.tight_layout(rect=(0, 0.09, 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    figure.savefig(buffer, dpi=72)
    plt.close(figure)
    # a line plot needs few colours: a palette image is a third of the RGBA one's size
    from PIL import Image

    buffer.seek(0)
    with Image.open(buffer) as image:
        image.convert("RGB").quantize(colors=PALETTE_COLOURS).save(path, optimize=True)
    return path


def joined(names) -> str:
    """Return tied names, those of one family folded: ``burley_{searchlight, dmfp}``."""
    families = {}
    for name in names:
        family, _, variant = name.partition("_")
        families.setdefault(family, []).append((name, variant))
    parts = []
    for family, members in families.items():
        if len(members) > 1 and all(variant for _, variant in members):
            parts.append(f"{family}_{{{', '.join(variant for _, variant in members)}}}")
        else:
            parts += [name for name, _ in members]
    return " = ".join(parts)


def percent(value, within: bool = False) -> str:
    """Return a fraction as a percentage of 3 significant figures (``*``: within noise)."""
    if value is None or not math.isfinite(value):
        return "–"
    return f"{100.0 * value:.3g}{'*' if within else ''}"


def _row_table(result: dict, metric: str) -> list[str]:
    """Return one Markdown table: a row per walk row, a column per profile."""
    names = result["profiles"]
    header = ["row", "MC total", "MC noise %"] + list(names)
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    for row in result["rows"]:
        mc = row["mc"]
        cells = [row["case"], f"{mc['total']:.4g}", percent(mc["noise"][metric])]
        for name in names:
            entry = row["profiles"][name]
            cells.append("refused" if entry["status"] != "ok" else percent(
                entry["errors"][metric], entry["within_noise"][metric]))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _burley_lines(burley: dict) -> list[str]:
    if not burley["per_albedo"]:
        return ["No albedo of the Burley set-up was measured."]
    lines = [f"Searchlight fit (Eq. 5) against the walk; {burley['set_up']}; albedos "
             f"{', '.join(f'{a:g}' for a in burley['albedos'])}, {burley['photons']:,} "
             f"photons each: average energy-weighted relative L1 error inside the 99 % "
             f"radius **{percent(burley['measured'])} %** (the walk's noise alone: "
             f"{percent(burley['noise'])} %; pointwise, the mean of |fit / MC - 1| over rings "
             f"equally spaced in ln r: {percent(burley['pointwise'])} %). Christensen and "
             f"Burley 2015 report **{percent(burley['published'])} %**.", "",
             "| albedo | A (walk) | L1 % | pointwise % | noise % |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {e['albedo']:g} | {e['A']:.4f} | {percent(e['l1'])} | "
              f"{percent(e['pointwise'])} | {percent(e['noise'])} |"
              for e in burley["per_albedo"]]
    if abs(burley["measured"] - burley["published"]) > burley["explain_above"]:
        lines += ["", f"The two differ by more than {100 * burley['explain_above']:g} "
                      "points: docs/profiles.md says why."]
    return lines


def _summary_lines(result: dict) -> list[str]:
    summary, metrics = result["summary"], result["metrics"]
    lines = ["| region | rows | " + " | ".join(f"best {m}" for m in metrics) + " |",
             "|" + " --- |" * (2 + len(metrics))]
    for region, entry in summary.items():
        cells = [region, str(entry["rows"])]
        for m in metrics:
            names = entry["best_model"][m]
            cells.append(f"{joined(names)} ({percent(entry['profiles'][names[0]][m])})"
                         if names else "–")
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Mean |error| in % per region, `L1 / total`:", ""]
    regions = list(summary)
    lines += ["| profile | " + " | ".join(regions) + " |", "|" + " --- |" * (1 + len(regions))]
    for name in result["profiles"]:
        cells = [name]
        for region in regions:
            means = summary[region]["profiles"][name]
            refused = f" ({means['refused']} refused)" if means["refused"] else ""
            cells.append(f"{percent(means['l1'])} / {percent(means['total'])}{refused}")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _timing_lines(timing: dict) -> list[str]:
    lines = [f"Evaluation of {timing['radii']:,} radii x 3 channels ({timing['medium']}), "
             f"best of {timing['repeats']}; baseline {timing['baseline']}: "
             f"{1e3 * timing['baseline_seconds']:.1f} ms in the same run; target "
             f"{1e3 * timing['target_seconds']:.0f} ms. The shipped walk table is read once "
             f"a process ({1e3 * timing['walk_table_read_seconds']:.0f} ms).", "",
             "| profile | evaluate, ms | x np.exp | build, ms | builds a table | target met |",
             "| --- | --- | --- | --- | --- | --- |"]
    for name, entry in timing["profiles"].items():
        lines.append(f"| {name} | {1e3 * entry['evaluate_seconds']:.1f} | "
                     f"{entry['evaluate_ratio']:.2f} | {1e3 * entry['build_seconds']:.1f} | "
                     f"{'yes' if entry['table'] else 'no'} | "
                     f"{'yes' if entry['meets_target'] else 'no'} |")
    return lines


#: The row tables, in order: measure and title.
ROW_TABLES = (("l1", "Energy-weighted relative L1 error inside the 99 % radius, %"),
              ("total", "Relative error of the total reflectance, %"),
              ("near", "L1 error inside one reduced mean free path, %"),
              ("tail", "L1 error between the 90 % and 99 % radii, %"))


def markdown(result: dict, *, rows: bool = True) -> str:
    """Return a bench result as Markdown (``rows=False``: without the per-row tables)."""
    settings = result["settings"]
    lines = ["# Radial profiles against the photon random walk", "",
             f"Grid in optical units (sigma_t = 1 mm^-1): albedos "
             f"{', '.join(f'{a:g}' for a in settings['albedos'])} x eta "
             f"{', '.join(f'{e:g}' for e in settings['etas'])} x g "
             f"{', '.join(f'{g:g}' for g in settings['gs'])}; measured media: "
             f"{', '.join(settings['media']) or 'none'}; {settings['photons']:,} photons a "
             f"row in {settings['batches']} batches ({result['walks_cached']} of "
             f"{len(result['rows'])} walks from the cache).", "",
             result["normalisation"], "", result["noise_rule"], "",
             "## Christensen and Burley 2015", "", *_burley_lines(result["burley"]), "",
             "## Best model where (mean |error| in %, the walk's own table left out)", "",
             *_summary_lines(result), "", "## Evaluation time", "",
             *_timing_lines(result["timing"])]
    if rows:
        for metric, title in ROW_TABLES:
            lines += ["", f"## {title}", "", "`*`: within the walk's noise.", "",
                      *_row_table(result, metric)]
    return "\n".join(lines) + "\n"
