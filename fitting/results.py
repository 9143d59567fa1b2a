"""Posterior summaries, the "can the data constrain this?" verdict, and the material file.

A parameter's posterior is summarised by its median and its 16/84 % and 2.5/97.5 %
quantiles. Its verdict compares the posterior with the prior in the sampling space (where
the priors of :mod:`translucent.fitting.models` are uniform):

* ``unconstrained``: the 68 % interval covers more than :data:`UNCONSTRAINED_RATIO` of the
  prior's 68 % interval: the data say little beyond the prior;
* ``upper limit`` / ``lower limit``: the 95 % interval reaches within
  :data:`EDGE_FRACTION` of a prior bound: only one side is constrained;
* ``multimodal``: the samples fall into two or more modes of the posterior (the local
  maxima the sampler started from), each holding at least :data:`MODE_SHARE` of them, and
  the parameter tells those modes apart (their 68 % intervals do not overlap): the data
  allow two or more separate values, and the overall 95 % interval spans them;
* ``constrained`` otherwise; ``nuisance`` for the exposure scale.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..atomic import atomic_write_text
from ..tomlio import toml_value

__all__ = ["ParameterSummary", "read_material", "summarise_posterior", "toml_text",
           "write_material"]

#: A 68 % posterior interval wider than this fraction of the prior's 68 % interval means
#: the data barely constrain the parameter (1 would be the prior itself).
UNCONSTRAINED_RATIO = 0.5
#: A 95 % interval within this fraction of the prior width from a bound reaches the bound.
EDGE_FRACTION = 0.02
#: SubEdit knots (smoothness prior, no informative box): a 68 % interval wider than this
#: (nats) is reported as weakly constrained.
KNOT_WIDTH_NATS = 1.0
#: A mode holding fewer samples than this cannot move a 68 % interval much and is not
#: reported (it still widens the 95 % interval when it holds more than 2.5 %).
MODE_SHARE = 0.05


@dataclass(frozen=True)
class ParameterSummary:
    """Posterior of one parameter, in physical units.

    Attributes
    ----------
    name, unit : str
    median, low68, high68, low95, high95 : float
        Median and the 16, 84, 2.5 and 97.5 % quantiles.
    status : str
        ``constrained``, ``upper limit``, ``lower limit``, ``unconstrained``,
        ``weakly constrained``, ``multimodal``, ``nuisance``, or ``model misfit`` (the
        goodness-of-fit tests reject the model: the interval is conditional on it).
    prior : (float, float)
        Prior range, physical units.
    width_ratio : float
        68 % posterior width over the prior's 68 % width (sampling space).
    modes : tuple of (float, float)
        For a ``multimodal`` parameter: the median within each mode (physical units) and
        the share of the samples in it, heaviest first; empty otherwise.
    """

    name: str
    unit: str
    median: float
    low68: float
    high68: float
    low95: float
    high95: float
    status: str
    prior: tuple[float, float]
    width_ratio: float
    modes: tuple = ()

    def describe(self) -> str:
        """One line for the terminal."""
        text = (f"{self.name:>18} = {self.median:.4g}  (68 %: {self.low68:.4g} .. "
                f"{self.high68:.4g}; 95 %: {self.low95:.4g} .. {self.high95:.4g}) {self.unit}")
        if self.status == "upper limit":
            text += f"  [upper limit: < {self.high95:.3g} at 97.5 %]"
        elif self.status == "lower limit":
            text += f"  [lower limit: > {self.low95:.3g} at 2.5 %]"
        elif self.status == "weakly constrained":
            text += (f"  [weakly constrained: 68 % interval {self.high68 - self.low68:.2g} "
                     "nats wide]")
        elif self.status == "model misfit":
            text += "  [model misfit: this interval assumes a model the data reject]"
        elif self.status == "multimodal":
            text += "  [multimodal: " + ", ".join(f"{median:.3g} ({share:.0%})"
                                                 for median, share in self.modes) + "]"
        elif self.status not in ("constrained", "nuisance"):
            text += f"  [{self.status}: posterior {self.width_ratio:.0%} as wide as the prior]"
        return text


def _separated_modes(values, labels):
    """Per-mode (median, share) of one coordinate when its modes are told apart, else ().

    Only modes holding at least :data:`MODE_SHARE` of the samples count; the coordinate
    separates them when two of their 68 % intervals do not overlap.
    """
    if labels is None:
        return ()
    counts = np.bincount(labels)
    heavy = [k for k in np.argsort(-counts) if counts[k] >= MODE_SHARE * labels.size]
    if len(heavy) < 2:
        return ()
    intervals = {k: np.percentile(values[labels == k], [16, 50, 84]) for k in heavy}
    apart = any(intervals[j][2] < intervals[k][0] or intervals[k][2] < intervals[j][0]
                for i, j in enumerate(heavy) for k in heavy[i + 1:])
    if not apart:
        return ()
    return tuple((intervals[k][1], float(counts[k] / labels.size)) for k in heavy)


def summarise_posterior(model, samples, labels=None) -> list[ParameterSummary]:
    """Median, 68 % and 95 % intervals and the verdict of every parameter of ``model``.

    Parameters
    ----------
    model : ProfileModel
    samples : ndarray, shape (m, ndim)
        Flat chain in the sampling space.
    labels : ndarray of int, shape (m,), optional
        The posterior mode of each sample (``ChainResult.sample_modes``); without it no
        parameter is called ``multimodal``.

    Returns
    -------
    list of ParameterSummary
    """
    samples = np.atleast_2d(samples)
    labels = None if labels is None else np.asarray(labels, dtype=int)
    quantiles = np.percentile(samples, [50, 16, 84, 2.5, 97.5], axis=0)
    out = []
    for i, info in enumerate(model.parameters):
        q = quantiles[:, i]
        width = info.upper - info.lower
        ratio = float((q[2] - q[1]) / (0.68 * width)) if width > 0 else 0.0
        modes = ()
        if info.kind == "exposure":
            status = "nuisance"
        elif info.kind == "ln_p":
            status = "constrained" if q[2] - q[1] <= KNOT_WIDTH_NATS else "weakly constrained"
        elif ratio > UNCONSTRAINED_RATIO:
            status = "unconstrained"
        elif modes := _separated_modes(samples[:, i], labels):
            status = "multimodal"
            modes = tuple((float(info.to_physical(median)), share) for median, share in modes)
        elif q[3] - info.lower < EDGE_FRACTION * width:
            status = "upper limit"
        elif info.upper - q[4] < EDGE_FRACTION * width:
            status = "lower limit"
        else:
            status = "constrained"
        physical = info.to_physical(q)
        prior = tuple(float(v) for v in info.to_physical([info.lower, info.upper]))
        out.append(ParameterSummary(info.name, info.unit, *map(float, physical), status,
                                    prior, ratio, modes))
    return out


def summaries_to_json(summaries) -> list[dict]:
    """Return the summaries as JSON-able dicts."""
    return [asdict(s) for s in summaries]


def toml_text(table: dict, comments: list[str] = ()) -> str:
    """Write a flat TOML document: comment lines, then ``key = value`` lines.

    ``None`` values inside lists (channels not fitted) are written as ``nan``.
    """
    lines = [f"# {line}" if line else "#" for line in comments]
    for key, value in table.items():
        if isinstance(value, list):
            value = [[float("nan") if v is None else v for v in item]
                     if isinstance(item, list) else (float("nan") if item is None else item)
                     for item in value]
        lines.append(f"{key} = {toml_value(value)}")
    return "\n".join(lines) + "\n"


def write_material(path, material: dict, summaries, *, source: str = "",
                   diagnostics: str = "") -> None:
    """Write the fitted material as TOML (the keys the scene files take), atomically.

    The posterior intervals go in comment lines, so the file is the material table of
    ``materials/factory.py`` and nothing else: ``type``, ``sigma_a``, ``sigma_s_prime``,
    ``eta``, ``g`` for a dipole.
    """
    comments = ["Fitted by translucent fit" + (f" from {source}" if source else ""),
                "Values are posterior medians; intervals (16-84 %) below."]
    if diagnostics:
        comments.append(diagnostics)
    comments += [s.describe().strip() for s in summaries]
    atomic_write_text(path, toml_text(material, comments))


def read_material(name_or_path):
    """Read a :class:`~translucent.materials.Dipole` from a measured-medium name or TOML file.

    The file holds a material table at its top level (as :func:`write_material` writes
    it) or under ``[material]``; it is built by
    :func:`translucent.materials.factory.material_from_dict`.

    Raises
    ------
    InputError
        Unknown name, unreadable file, or a table that is not a dipole medium.
    """
    from pathlib import Path

    from ..atomic import check_input_file, note_input
    from ..errors import InputError
    from ..materials import Dipole, measured_medium
    from ..materials.factory import material_from_dict
    from ..tomlio import parse_toml

    path = Path(str(name_or_path))
    if path.suffix.lower() != ".toml":
        return measured_medium(str(name_or_path))
    check_input_file(path, "material", what="material file")
    note_input(path, "material")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"not a readable TOML file ({error})", file=path) from error
    table = parse_toml(text, file=path)
    table = table.get("material", table)
    material = material_from_dict(table, file=path)
    if not isinstance(material, Dipole):
        raise InputError("a capture needs a homogeneous dipole medium", file=path,
                         field="material.type", value=table.get("type"))
    return material
