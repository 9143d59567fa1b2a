"""Pictures of a fit for a person: the corner plot, and the fitted profile over the measured one.

Written with matplotlib's Agg backend (no display needed), atomically.
"""

from __future__ import annotations

import numpy as np

from ..atomic import atomic_save_figure

__all__ = ["corner_plot", "profile_plot"]

_COLOURS = ("tab:red", "tab:green", "tab:blue")
#: Posterior draws used for the model band of the profile plot.
BAND_DRAWS = 100


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def corner_plot(path, model, samples, *, truths=None, title: str = "", columns=None) -> None:
    """Corner plot of the posterior (sampling space: ln of log-uniform parameters).

    Parameters
    ----------
    path : str or Path
        PNG file.
    model : ProfileModel
    samples : ndarray, shape (m, ndim)
    truths : ndarray, shape (ndim,), optional
        True values in the sampling space (synthetic captures), drawn as lines.
    title : str
    columns : slice, optional
        The parameters to show (default: all).
    """
    import corner

    _pyplot()  # the Agg backend before corner draws
    columns = slice(None) if columns is None else columns
    labels = [(f"ln {p.name}" if p.transform == "log" else p.name)
              for p in model.parameters][columns]
    samples = np.atleast_2d(samples)[:, columns]
    truths = None if truths is None else np.asarray(truths)[columns]
    # corner needs some spread in every coordinate
    spread = np.ptp(samples, axis=0) > 0
    shown = [name for name, spreads in zip(labels, spread, strict=True) if spreads]
    figure = corner.corner(samples[:, spread], labels=shown,
                           quantiles=[0.16, 0.5, 0.84], show_titles=True, title_fmt=".3g",
                           truths=None if truths is None else np.asarray(truths)[spread],
                           truth_color="tab:orange")
    if title:
        figure.suptitle(title)
    atomic_save_figure(path, figure, dpi=80)


def profile_plot(path, model, samples, *, title: str = "", seed: int = 0) -> None:
    """Measured annulus means (with standard errors) and the fitted model, with residuals.

    Top: the means per channel against radius on a log scale, the median model prediction
    and the 16-84 % band of the predictions of posterior draws. Bottom: residuals in units
    of the standard error.

    Parameters
    ----------
    path : str or Path
        PNG file.
    model : ProfileModel
    samples : ndarray, shape (m, ndim)
    title : str
    seed : int
        Seed of the posterior draws.
    """
    plt = _pyplot()
    profile = model.profile
    samples = np.atleast_2d(samples)
    rng = np.random.default_rng(seed)
    draws = samples[rng.choice(samples.shape[0], size=min(BAND_DRAWS, samples.shape[0]),
                               replace=False)]
    predictions = model.predictions(draws)
    median_prediction = model.predictions(np.median(samples, axis=0))
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(7, 7), sharex=True,
                                         gridspec_kw={"height_ratios": [3, 1]})
    for c in model.channels:
        use = profile.used[:, c]
        radius = profile.radius_mm[use, c]
        mean, stderr, _ = profile.observations(c)
        colour = _COLOURS[c]
        top.errorbar(radius, mean, yerr=stderr, fmt="o", ms=3, color=colour, alpha=0.8,
                     label=f"measured {'RGB'[c]}")
        low, high = np.percentile(predictions[c], [16, 84], axis=0)
        top.fill_between(radius, low, high, color=colour, alpha=0.25, lw=0)
        top.plot(radius, median_prediction[c][0], color=colour, lw=1.2)
        bottom.plot(radius, (mean - median_prediction[c][0]) / stderr, "o", ms=3, color=colour)
        dropped = ~use & np.isfinite(profile.mean[:, c]) & (profile.mean[:, c] > 0)
        top.plot(profile.radius_mm[dropped, c], profile.mean[dropped, c], "x", ms=3,
                 color=colour, alpha=0.4)
    top.set_yscale("log")
    top.set_ylabel("annulus mean (stored units above black)")
    top.legend(fontsize=8, title="x: dropped annuli", title_fontsize=8)
    if title:
        top.set_title(title, fontsize=9)
    for level in (-2, 0, 2):
        bottom.axhline(level, color="0.6", lw=0.8, ls="-" if level == 0 else ":")
    bottom.set_xlabel("radius from the incident point (mm)")
    bottom.set_ylabel("residual / std. error")
    figure.tight_layout()
    atomic_save_figure(path, figure)
