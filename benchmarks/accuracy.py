"""Each fast method's accuracy and speed on the report's default scenes, commit by commit.

One report per commit (``setup_cache``: ``translucent report`` on the default scenes, in a
temporary folder, with its own cache) gives every ``track_*`` its number: relative MSE and
HDR-FLIP against the committed reference, each with the reference's noise floor recorded
beside it (``track_*_noise_floor``: a change within the floor is noise, not a step), and the
model and approximation parts of the error split. The warm frame of each method on
``sphere`` and ``glossy`` (relit with nudged lights, as the report times it) is timed by
asv itself (``time_frame``). A scene or method a commit does not have, or where a method
does not apply, is skipped (asv shows n/a); a figure its report lacks is NaN.

The report is run through its command line, which every commit of the history has, so that
these benchmarks run unchanged against old commits. Read in docs/history.md.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

#: The report's default scenes and the built-in methods, fixed so that every commit of a
#: history is asked the same (a commit without one: n/a).
BUILTIN_SCENES = ["sphere", "bowl", "cornell_block", "sphere_dielectric",
                  "dielectric_on_floor", "glossy", "glossy_box", "solid_checker",
                  "solid_gradient", "solid_veins"]
BUILTIN_METHODS = ["prt", "radiosity", "splatting", "brdf_pca"]


def _registered_methods() -> list[str]:
    """Return the methods the installed translucent registers besides the built-ins.

    A user's own, through the ``translucent.methods`` entry point, as the report finds them.
    """
    try:
        from translucent.fast.base import METHODS as registered
    except Exception:  # noqa: BLE001 - an old commit, or none installed: the built-ins
        return []
    return [name for name in registered if name not in BUILTIN_METHODS]


SCENES = BUILTIN_SCENES
METHODS = BUILTIN_METHODS + _registered_methods()

#: A report of the default scenes with an empty cache takes a few minutes on 2 cores.
REPORT_TIMEOUT_SECONDS = 3600

#: Where each tracked figure lies in a method's block of the report's ``metrics.json``.
FIGURES = {
    "relative_mse": ("noise", "relative_mse", "value"),
    "relative_mse_noise_floor": ("noise", "relative_mse", "noise_floor"),
    "hdr_flip": ("noise", "hdr_flip", "value"),
    "hdr_flip_noise_floor": ("noise", "hdr_flip", "noise_floor"),
    "model_relative_mse": ("model_error", "metrics", "relative_mse"),
    "approximation_relative_mse": ("approximation_error", "metrics", "relative_mse"),
}


def run_report(folder: Path) -> dict:
    """Run ``translucent report`` of the default scenes into ``folder``; return metrics.json.

    Exit code 1 (a regression against the commit's own baseline) is a result, not a failure.
    """
    environment = {**os.environ, "TRANSLUCENT_CACHE": str(folder / "cache")}
    code = ("from translucent.reports.cli import main; import sys; "
            f"sys.exit(main(['report', '--out', {str(folder / 'report')!r}, '--no-progress']))")
    done = subprocess.run([sys.executable, "-c", code], env=environment, capture_output=True,
                          text=True, timeout=REPORT_TIMEOUT_SECONDS)
    if done.returncode not in (0, 1):
        raise RuntimeError(f"translucent report exited {done.returncode}: "
                           f"{done.stderr[-2000:]}")
    return json.loads((folder / "report" / "metrics.json").read_text())


def figures_of(metrics: dict) -> dict:
    """Return ``{scene: {method: {figure: value}}}`` of a report's ``metrics.json``."""
    found: dict = {}
    for scene, block in (metrics.get("scenes") or {}).items():
        for method, entry in (block.get("methods") or {}).items():
            if entry.get("status") != "ok":
                continue
            values = {}
            for figure, path in FIGURES.items():
                value = entry
                for key in path:
                    value = value.get(key) if isinstance(value, dict) else None
                if isinstance(value, (int, float)):
                    values[figure] = float(value)
            found.setdefault(scene, {})[method] = values
    return found


class Accuracy:
    """The report's figures per default scene and method (one report a commit)."""

    params = (SCENES, METHODS)
    param_names = ["scene", "method"]
    timeout = REPORT_TIMEOUT_SECONDS

    def setup_cache(self):
        """Run one report of the default scenes; return its figures."""
        with tempfile.TemporaryDirectory(prefix="translucent-asv-") as folder:
            return figures_of(run_report(Path(folder)))

    setup_cache.timeout = REPORT_TIMEOUT_SECONDS

    def setup(self, figures, scene, method):
        """Skip a scene and method the commit's report has no figures of (asv: n/a)."""
        if method not in figures.get(scene, {}):
            raise NotImplementedError(f"{method} on {scene}: not run at this commit")

    @staticmethod
    def _figure(figures, scene, method, figure):
        """Return one figure; NaN where the commit's report has none (asv: n/a)."""
        value = figures.get(scene, {}).get(method, {}).get(figure)
        return math.nan if value is None else value


def _tracker(figure: str, unit: str, what: str):
    def track(self, figures, scene, method):
        return self._figure(figures, scene, method, figure)

    track.__name__ = track.__qualname__ = f"track_{figure}"
    track.__doc__ = f"Return {what}."
    track.unit = unit
    return track


#: The tracked figures: (unit, what each is), one ``track_<figure>`` of :class:`Accuracy`
#: a figure.
TRACKED = {
    "relative_mse": ("relative MSE", "the relative MSE against the committed reference (its "
                                     "noise discounted)"),
    "relative_mse_noise_floor": ("relative MSE", "the reference's noise floor of the "
                                                 "relative MSE"),
    "hdr_flip": ("HDR-FLIP", "HDR-FLIP against the committed reference"),
    "hdr_flip_noise_floor": ("HDR-FLIP", "the reference's noise floor of HDR-FLIP"),
    "model_relative_mse": ("relative MSE", "the model's part of the error (its model "
                                           "reference against the reference)"),
    "approximation_relative_mse": ("relative MSE", "the method's own part (its image "
                                                   "against its model reference)"),
}

for _figure_name, (_unit, _what) in TRACKED.items():
    setattr(Accuracy, f"track_{_figure_name}", _tracker(_figure_name, _unit, _what))


class Frame:
    """The warm frame of each method on ``sphere`` and ``glossy`` (its precomputation cached)."""

    params = (["sphere", "glossy"], METHODS)
    param_names = ["scene", "method"]
    timeout = 1800

    def setup(self, scene, method):
        """Precompute (or load) the method's state and render a first frame."""
        import translucent

        loaded = translucent.load_scene(scene)
        module = translucent.method(method)
        if module.applies_to(loaded) is not None:
            raise NotImplementedError(f"{method} does not apply to {scene}")
        self.state = module.precompute(loaded)
        self.state.render()
        self.lights = list(loaded.lights)
        self.frame = 0

    def time_frame(self, scene, method):
        """Relight a warm state with nudged lights: the interactive path, as the report."""
        try:
            from translucent.reports.report.runs import nudged_lights
        except ImportError:  # an older commit: the scene's own lights again
            self.state.render(lights=self.lights)
            return
        self.frame += 1
        self.state.render(lights=nudged_lights(self.lights, self.frame))


#: Synthetic captures per commit for the fit's interval coverage (48 x 48, dipole-made).
FIT_CAPTURES = 8


def fit_figures(result) -> dict:
    """Return the tracked figures of a :func:`~translucent.fitting.validation.coverage_study`."""
    seconds = getattr(result, "fit_seconds", None)
    per_fit = (float(sum(seconds) / len(seconds)) if seconds is not None and len(seconds)
               else float(result.seconds) / max(len(result.converged), 1))
    return {"coverage": float(result.fraction), "seconds": per_fit,
            "converged": float(sum(bool(c) for c in result.converged)
                               / max(len(result.converged), 1))}


class Fit:
    """The dipole fit of synthetic captures made by the dipole: coverage and seconds a fit."""

    timeout = 1800

    def setup_cache(self):
        """Fit :data:`FIT_CAPTURES` captures of random truth; None where the commit cannot."""
        try:
            from translucent.fitting.validation import coverage_study

            return fit_figures(coverage_study(captures=FIT_CAPTURES, seed=0, size=48))
        except (ImportError, TypeError):  # an older commit without this study
            return None

    setup_cache.timeout = 1800

    def setup(self, figures):
        """Skip a commit without the study (asv: n/a)."""
        if figures is None:
            raise NotImplementedError("no coverage study at this commit")

    def track_interval_coverage(self, figures):
        """Return the fraction of true coefficients inside their 95 % intervals."""
        return figures["coverage"]

    track_interval_coverage.unit = "fraction"

    def track_seconds_per_fit(self, figures):
        """Return the mean wall time of a fit (profile, MAP, chain, goodness of fit)."""
        return figures["seconds"]

    track_seconds_per_fit.unit = "seconds"

    def track_converged(self, figures):
        """Return the fraction of chains that converged."""
        return figures["converged"]

    track_converged.unit = "fraction"
