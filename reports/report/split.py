r"""Why a method is wrong: its error split into its profile's (the model) and its own.

A subsurface method renders a radial profile (its ``profile`` knob, the classical dipole by
default) by an approximation. Three images of the same scene say where its error comes
from:

- the volumetric reference :math:`V` (Mitsuba's path tracing of the medium itself);
- the *model reference* :math:`M_p`: the BSSRDF path tracer's render of the scene with
  profile :math:`p` (:mod:`translucent.reference.bssrdf_path`): the profile integrated
  exactly over every light, shadow and inter-reflection;
- the method's image :math:`A`.

The *total error* is :math:`m(V, A)` (the report's metrics), the *model error*
:math:`m(V, M_p)`, what the profile alone costs, and the *approximation error*
:math:`m(M_p, A)`, what the method adds to its profile. Each is scored on the method's own
pixels, with its own noise floor: the approximation error's is the model reference's
noise (:func:`~translucent.reports.metrics.noise_floor`); the model error compares two
independent renders, so its floor, and the variance its relative MSE discounts, is that
of one image carrying both variances.

The errors are not additive (relative MSE of a sum is not a sum of relative MSEs), but
they say which part dominates, in relative MSE: the one that clears its noise floor when
the other does not; when both do, the larger if it is at least :data:`DOMINANCE_RATIO`
times the other, else "both"; "within noise" when neither does.

BRDF editing has the same split with its own model: the K-term PCA of its BRDFs (Nguyen et
al. 2010, Eq. 10) carried by its Lambertian-gather transport (Sect. 5.2; the method's
``model_name``, ``brdf_pca_k6+lambertian_gather2``), rendered exactly by Mitsuba with the
PCA BRDF plugin and the gather integrator (:mod:`translucent.reference.brdf_plugins`),
against the exact-BRDF reference. Another renderer's image, and a scene whose translucent
objects are heterogeneous (no radial profile), have no split; each says why.

A model named by parts (``dipole+geometry``, ``brdf_pca_k6+lambertian_gather2``) is also
split into its *steps* (:func:`model_steps`) where the reference of every simpler model is
committed: the first part against the volumetric reference, each further part against the
model without it, so that the model's error is attributed too (the PCA of the BRDFs, or the
Lambertian gather).

Examples
--------
>>> dominant_part(0.010, 0.0004, resolved=(True, True))
'model'
>>> dominant_part(0.002, 0.003, resolved=(True, True))
'both'
>>> dominant_part(0.0001, 0.0002, resolved=(False, False))
'within noise'
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...image import Image

__all__ = ["DOMINANCE_RATIO", "ENTRY_SEPARATOR", "MODEL", "ErrorSplit", "ModelStep",
           "dominant_part", "entry_name", "entry_parts", "model_reference_info",
           "model_reference_refusal", "model_steps", "split_images",
           "profile_knob_of", "refused_profile", "requested_profiles", "score_splits",
           "split_profile", "unrendered_profile", "with_both_variances"]

#: One part dominates when its relative MSE is at least this factor times the other's.
DOMINANCE_RATIO = 2.0

#: Between a method and a profile in the name of a run of that profile (``prt@better_dipole``);
#: the default profile's run is named by the method alone.
ENTRY_SEPARATOR = "@"


#: The owner of a model reference among a report's tasks: ``(MODEL, profile)``.
MODEL = "model"


def requested_profiles(profiles) -> list[str]:
    """Return the profiles a report runs besides the default (``--profiles``).

    Parameters
    ----------
    profiles : None, "all", str or list of str
        None: none; ``"all"``: every radial profile; a comma-separated string or a list.

    Raises
    ------
    InputError
        An unknown profile, naming ``--profiles`` and the valid ones.

    Examples
    --------
    >>> requested_profiles("better_dipole,dipole"), requested_profiles(None)
    (['better_dipole'], [])
    >>> requested_profiles(["all"]) == requested_profiles("all")
    True
    """
    from ...fast.knobs import DEFAULT_PROFILE, radial_profile_names

    if profiles is None:
        return []
    names = ([part.strip() for part in profiles.split(",")] if isinstance(profiles, str)
             else list(profiles))
    if "all" in names:  # as a string or as a list's item (a command line split on commas)
        names = list(radial_profile_names())
    valid = radial_profile_names()
    for name in names:
        if name not in valid:
            raise InputError(f"unknown radial profile; valid: all, {', '.join(valid)}",
                             field="--profiles", value=name)
    return [name for name in dict.fromkeys(names) if name != DEFAULT_PROFILE]


def profile_knob_of(method_name: str):
    """Return the ``profile`` knob of a registered method, or None (none, or not a method)."""
    from ...fast.base import method

    try:
        knobs = getattr(method(method_name), "KNOBS", None)
    except InputError:
        return None
    return knobs["profile"] if knobs is not None and "profile" in knobs else None


def refused_profile(module, profile: str):
    """Return the :class:`~translucent.fast.base.Refusal` of ``profile`` by a method, or None."""
    from ...fast.base import Refusal
    from ...fast.knobs import UNSUPPORTED_PROFILE

    knob = module.KNOBS["profile"]
    try:
        knob.validate(profile)
    except InputError as error:
        return Refusal(UNSUPPORTED_PROFILE, error.reason)
    return None


def model_reference_info(image: Image, source: str) -> dict:
    """Return where a model reference came from: source, spp, passes, seconds, noise."""
    meta = image.metadata
    noise = meta.get("noise") if isinstance(meta.get("noise"), dict) else {}
    return {"source": source, "spp": meta.get("spp"), "passes": meta.get("passes"),
            "seconds": meta.get("seconds"), "integrator": meta.get("integrator"),
            "noise_median": noise.get("median"), "noise_p99": noise.get("p99")}


def entry_name(method: str, profile: str | None) -> str:
    """Return the report's name for ``method`` run with ``profile`` (None: its default).

    Examples
    --------
    >>> entry_name("prt", None), entry_name("prt", "better_dipole")
    ('prt', 'prt@better_dipole')
    """
    return method if profile is None else f"{method}{ENTRY_SEPARATOR}{profile}"


def entry_parts(name: str) -> tuple[str, str | None]:
    """Return the method and the profile asked of it (None: the default) of a report entry.

    Examples
    --------
    >>> entry_parts("splatting@burley_dmfp"), entry_parts("radiosity")
    (('splatting', 'burley_dmfp'), ('radiosity', None))
    """
    method, _, profile = name.partition(ENTRY_SEPARATOR)
    return method, profile or None


def model_steps(key: str) -> list[str]:
    """Return the models a key named by parts builds on, simplest first, ``key`` last.

    Examples
    --------
    >>> model_steps("brdf_pca_k6+lambertian_gather2")
    ['brdf_pca_k6', 'brdf_pca_k6+lambertian_gather2']
    >>> model_steps("dipole")
    ['dipole']
    """
    parts = key.split("+")
    return ["+".join(parts[:count]) for count in range(1, len(parts) + 1)]


@dataclass
class ModelStep:
    """One step of a model named by parts: the error its last part adds.

    Attributes
    ----------
    model : str
        The model with this step (:func:`model_steps`).
    against : str or None
        The model without it (None: the volumetric reference).
    metrics, floor : dict
        Every metric of the step over the method's pixels, and its noise floor.
    verdicts : dict
        Each metric's noise verdict.
    """

    model: str
    against: str | None
    metrics: dict
    floor: dict | None
    verdicts: dict

    @property
    def label(self) -> str:
        """The part this step adds (``+lambertian_gather2``), or the first model's name."""
        return self.model if self.against is None else self.model[len(self.against):]

    def as_dict(self) -> dict:
        """Return the step as a block of ``metrics.json``'s ``model_steps``."""
        from .runs import json_safe

        return {"model": self.model, "against": self.against,
                "metrics": json_safe(self.metrics), "noise_floor": json_safe(self.floor),
                "noise_verdicts": dict(self.verdicts)}


def dominant_part(model: float | None, approximation: float | None, *,
                  resolved: tuple[bool, bool]) -> str:
    """Return which part holds the error: "model", "approximation", "both" or "within noise".

    Parameters
    ----------
    model, approximation : float or None
        The two relative MSEs.
    resolved : (bool, bool)
        Whether each clears its noise floor.
    """
    if model is None or approximation is None:
        return "unknown"
    if resolved == (False, False):
        return "within noise"
    # a part that does not clear its floor cannot be told from none: the other holds it
    if resolved == (True, False) or (all(resolved) and model >= DOMINANCE_RATIO * approximation):
        return "model"
    if resolved == (False, True) or approximation >= DOMINANCE_RATIO * model:
        return "approximation"
    return "both"


@dataclass
class ErrorSplit:
    """A method's error on a scene, split into its profile's and its own.

    Attributes
    ----------
    profile : str or None
        The profile the method rendered (None: it has none).
    reason : str
        Why there is no split ("" when there is).
    model, approximation : dict or None
        Every metric of :math:`m(V, M_p)` and :math:`m(M_p, A)` over the method's pixels.
    model_floor, approximation_floor : dict or None
        Their noise floors.
    model_verdicts, approximation_verdicts : dict
        Each metric's noise verdict.
    model_reference : dict
        Where the model reference came from (source, spp, passes, noise).
    steps : list of ModelStep
        The model's error by its parts (empty where a simpler model has no reference).
    brightness : dict or None
        The method's image summed over its pixels over its model reference's, per channel
        (``ratio``, ``standard_error`` from both images' variances): the mean offset the
        relative MSE does not single out (:func:`brightness_ratio`).
    """

    profile: str | None
    reason: str = ""
    model: dict | None = None
    approximation: dict | None = None
    model_floor: dict | None = None
    approximation_floor: dict | None = None
    model_verdicts: dict = field(default_factory=dict)
    approximation_verdicts: dict = field(default_factory=dict)
    model_reference: dict = field(default_factory=dict)
    steps: list = field(default_factory=list)
    brightness: dict | None = None

    @property
    def dominant(self) -> str:
        """Which part holds the error (:func:`dominant_part`, on relative MSE)."""
        from ..metrics.compute import RESOLVED

        if self.model is None or self.approximation is None:
            return "unknown"
        return dominant_part(
            self.model.get("relative_mse"), self.approximation.get("relative_mse"),
            resolved=(self.model_verdicts.get("relative_mse") == RESOLVED,
                      self.approximation_verdicts.get("relative_mse") == RESOLVED))

    def sentence(self) -> str:
        """Say, in words, which part holds the error and by how much."""
        from .formatting import format_value

        if self.reason:
            return f"No split into model and approximation: {self.reason}."
        model = format_value(self.model.get("relative_mse"), 3)
        approximation = format_value(self.approximation.get("relative_mse"), 3)
        numbers = (f"relative MSE of the model {self.profile!r} against the reference "
                   f"(model) {model}, of the method against its model rendered exactly "
                   f"(approximation) {approximation}")
        sentence = {
            "model": f"The model's error dominates: {numbers}. A better method of this "
                     "model cannot do much better; another model may.",
            "approximation": f"The method's own error dominates: {numbers}. Its knobs, not "
                             "the model, hold it there.",
            "both": f"Model and method share the error: {numbers}.",
            "within noise": f"Neither part clears its noise floor: {numbers}.",
        }.get(self.dominant, numbers + ".")
        return sentence + self._brightness_sentence() + self._steps_sentence()

    def _brightness_sentence(self) -> str:
        """Say how much brighter or darker than its model, where that clears 3 sigma."""
        found = self.brightness or {}
        ratio, error = found.get("ratio"), found.get("standard_error")
        if ratio is None or error is None:
            return ""
        resolved = [abs(r - 1.0) > 3.0 * e for r, e in zip(ratio, error, strict=True)]
        if not any(resolved):
            return " Its brightness equals its model's within 3 standard errors."
        percent = " / ".join(f"{100.0 * (r - 1.0):+.1f} %" for r in ratio)
        return (f" Summed over its pixels it is {percent} (R / G / B) against its model "
                f"(standard errors {' / '.join(f'{100.0 * e:.2f}' for e in error)} %).")

    def _steps_sentence(self) -> str:
        from ..metrics.compute import RESOLVED
        from .formatting import format_value

        if len(self.steps) < 2:
            return ""
        parts = [f"{step.label} {format_value(step.metrics.get('relative_mse'), 3)}"
                 + ("" if step.verdicts.get("relative_mse") == RESOLVED else " (within noise)")
                 for step in self.steps]
        resolved = [step for step in self.steps if step.verdicts.get("relative_mse") == RESOLVED]
        largest = max(resolved, key=lambda step: step.metrics.get("relative_mse") or 0.0,
                      default=None)
        return (" The model's error step by step, each against the model before it "
                "(relative MSE, not additive): " + ", ".join(parts) + "."
                + ("" if largest is None else f" The largest step: {largest.label}."))

    def as_dict(self) -> dict:
        """Return the ``model_error`` and ``approximation_error`` blocks of ``metrics.json``."""
        from .runs import json_safe

        def block(metrics, floor, verdicts):
            if metrics is None:
                return None
            return {"metrics": json_safe(metrics), "noise": {
                key: {"value": json_safe(metrics.get(key)),
                      "noise_floor": json_safe((floor or {}).get(key)),
                      "noise_verdict": verdict} for key, verdict in verdicts.items()}}

        return {"profile": self.profile, "reason": self.reason or None,
                "dominant": None if self.reason else self.dominant,
                "sentence": self.sentence(), "model_reference": json_safe(self.model_reference),
                "model_error": block(self.model, self.model_floor, self.model_verdicts),
                "model_steps": [step.as_dict() for step in self.steps],
                "approximation_error": block(self.approximation, self.approximation_floor,
                                             self.approximation_verdicts),
                "brightness_to_model": json_safe(self.brightness)}


def model_reference_refusal(scene, profile: str | None = None) -> str:
    """Return why ``scene`` can have no model reference of ``profile`` ("" when it can).

    The BSSRDF path tracer renders homogeneous translucent objects
    (:class:`~translucent.materials.Dipole` materials) by their radial profile; a
    heterogeneous medium has none. A PCA BRDF model (``brdf_pca_kK``) needs an analytic
    BRDF.
    """
    from ...materials.brdf_pca import pca_model_basis
    from ...materials.brdfs import AnalyticBRDF
    from ...reference.model_keys import model_rule

    if pca_model_basis(profile) is not None:
        if not any(isinstance(item.material, AnalyticBRDF) for item in scene.objects):
            return "the scene has no analytic BRDF: no PCA BRDF is rendered"
        return ""

    heterogeneous = heterogeneous_objects(scene)
    if heterogeneous and model_rule(profile or "") is None:
        return (f"the translucent object {', '.join(heterogeneous)} is a heterogeneous "
                "medium, which has no one radial profile: the method names no rule that "
                "mixes its media (HETEROGENEOUS_RULE)")
    if heterogeneous:
        return ""
    if not _has_dipole(scene):
        return "the scene has no homogeneous translucent object: no profile is rendered"
    return ""


def unrendered_profile(profile: str) -> str:
    """Return why the BSSRDF path tracer renders no model reference of ``profile`` ("": it does).

    A method's profile knob also takes the radial average of a directional profile
    (``directional_dipole_average``); the tracer renders the directional profile itself,
    with each sample's own incident direction, and not its average.

    Examples
    --------
    >>> unrendered_profile("better_dipole")
    ''
    """
    from ...materials.brdf_pca import pca_model_basis
    from ...materials.profiles import PROFILE_NAMES
    from ...reference.model_keys import parse_model_key

    profile = parse_model_key(profile)[0]
    if profile in PROFILE_NAMES or pca_model_basis(profile) is not None:
        return ""
    return (f"{profile!r} is the radial average of a directional profile; the BSSRDF path "
            "tracer renders the directional profile itself (each sample with its own "
            "incident direction), not its average")


def heterogeneous_objects(scene) -> list[str]:
    """Return the names of ``scene``'s heterogeneous translucent objects (solid media)."""
    from ...materials.solid import SolidMedium

    return [item.name for item in scene.objects
            if isinstance(item.material, SolidMedium) and not item.material.is_uniform]


def split_profile(name: str, knobs: dict | None, scene=None) -> tuple[str | None, str]:
    """Return the model a report entry rendered (its model reference's key), or why none.

    The key is the profile's name, with the suffix of the geometry model
    (:data:`~translucent.reference.model_keys.GEOMETRY_SUFFIXES`) where the method adds the
    object's geometry to it (its knob ``geometry`` is ``"walk"`` or ``"diffusion"``,
    :mod:`translucent.fast.object_geometry`): the model reference then
    renders the same correction (:mod:`translucent.reference.geometry_term`), so that the
    method is not credited with its model's gain.

    Parameters
    ----------
    name : str
        The entry (:func:`entry_name`).
    knobs : dict or None
        The knobs of its run (besides the defaults).
    scene : Scene, optional
        The scene it rendered: on a heterogeneous one the key names the method's
        ``HETEROGENEOUS_RULE`` (``dipole+segment_mix``), the rule the model reference
        renders the media by.
    """
    from ...fast.base import method
    from ...fast.knobs import DEFAULT_PROFILE
    from ...reference.model_keys import model_key
    from ...reference.peers.registry import entry_mode

    peer = entry_mode(name)
    if peer is not None:
        renderer, mode = peer
        model = renderer.model_of(mode)
        return (model, "") if model else (None, f"{name} renders no model the suite knows: "
                                                "its error cannot be split")
    method_name, asked = entry_parts(name)
    try:
        module = method(method_name)
    except InputError:
        return None, "another renderer's image: the model it renders is not known"
    if callable(getattr(module, "model_name", None)):
        return module.model_name(dict(knobs or {})), ""
    if profile_knob_of(method_name) is None:
        return None, (f"{method_name} names no model (no model_name, no profile knob): its "
                      "error cannot be split")
    chosen = (knobs or {}).get("profile", asked or DEFAULT_PROFILE)
    spec = getattr(module, "KNOBS", None)
    geometry = None
    if spec is not None and "geometry" in spec:
        geometry = (knobs or {}).get("geometry", spec["geometry"].default)
        geometry = None if geometry == "half_space" else geometry
    if scene is not None and heterogeneous_objects(scene):
        rule = getattr(module, "HETEROGENEOUS_RULE", None)
        if rule is None:
            return None, (f"{method_name} names no rule that mixes a heterogeneous medium "
                          "(HETEROGENEOUS_RULE): its error cannot be split")
        # the geometry correction is made for homogeneous (Dipole) objects only
        return model_key(chosen, geometry if _has_dipole(scene) else None, rule), ""
    return model_key(chosen, geometry), ""


def _has_dipole(scene) -> bool:
    from ...materials import Dipole

    return any(isinstance(item.material, Dipole) for item in scene.objects)


def score_splits(report) -> None:
    """Split every scored entry's error of ``report`` (fills ``report.splits``)."""
    cache: dict = {}
    for name in report.metrics:
        report.splits[name] = _split(report, name, cache)


def _split(report, name: str, cache: dict) -> ErrorSplit:
    profile, reason = split_profile(name, report.runs[name].knobs, report.scene)
    if reason:
        return ErrorSplit(profile, reason)
    model = report.model_references.get(profile)
    if model is None:
        why = report.model_reference_errors.get(profile) or "no model reference was made"
        return ErrorSplit(profile, f"no model reference of {profile!r}: {why}")
    mask = report.mask_of(name)
    key = (profile, tuple(sorted(report.scored_objects.get(name, ()))))
    try:
        found = split_images(report.reference, model, report.runs[name].image, mask,
                             cache=cache, key=key)
        steps = _steps(report, profile, mask, key[1], cache)
    except InputError as error:
        return ErrorSplit(profile, f"the model reference cannot be compared: {error.reason}")
    return ErrorSplit(profile, "", *found, report.model_reference_info.get(profile, {}),
                      steps, brightness_ratio(report.runs[name].image, model, mask))


def brightness_ratio(image: Image, model: Image, mask=None) -> dict | None:
    """Return ``image``'s sum over ``mask`` over ``model``'s, per channel, with its error.

    The standard error propagates both images' variances (an image without one counts as
    exact); None where the model's sum is not positive in every channel.

    Examples
    --------
    >>> import numpy as np
    >>> ones = Image(np.ones((2, 2, 3)), np.full((2, 2, 3), 0.01))
    >>> brighter = Image(np.full((2, 2, 3), 1.5))
    >>> found = brightness_ratio(brighter, ones)
    >>> found["ratio"], [round(e, 4) for e in found["standard_error"]]
    ([1.5, 1.5, 1.5], [0.075, 0.075, 0.075])
    """
    def sums(item: Image):
        rgb = np.asarray(item.rgb, dtype=np.float64)
        variance = (np.zeros_like(rgb) if item.variance is None
                    else np.asarray(item.variance, dtype=np.float64))
        if mask is not None:
            rgb, variance = rgb[mask], variance[mask]
        return rgb.reshape(-1, 3).sum(axis=0), variance.reshape(-1, 3).sum(axis=0)

    (top, top_variance), (bottom, bottom_variance) = sums(image), sums(model)
    if not np.all(bottom > 0) or not np.all(np.isfinite(top)):
        return None
    ratio = top / bottom
    error = np.sqrt(top_variance / bottom ** 2 + ratio ** 2 * bottom_variance / bottom ** 2)
    return {"ratio": ratio.tolist(), "standard_error": error.tolist()}


def split_images(reference: Image, model: Image, image: Image, mask=None, *,
                 cache: dict | None = None, key=None) -> tuple:
    """Return the split of ``image``'s error against ``reference`` through ``model``.

    Parameters
    ----------
    reference, model, image : Image
        The volumetric (or exact) reference, the model reference, the method's image.
    mask : ndarray of bool, optional
        The pixels scored (None: all).
    cache, key : dict and hashable, optional
        Where the model's part is kept for other images of the same model and pixels.

    Returns
    -------
    tuple
        ``(model metrics, approximation metrics, model floor, approximation floor, model
        verdicts, approximation verdicts)``, as :class:`ErrorSplit` takes them.

    Raises
    ------
    InputError
        Images that cannot be compared (another size).
    """
    from ..metrics.compute import evaluate_on, noise_verdicts

    cache = {} if cache is None else cache
    if key not in cache:  # one per model and set of pixels, whatever the method
        cache[key] = (*_model_error(reference, model, mask), _floor(model, mask))
    model_metrics, model_floor, approximation_floor = cache[key]
    approximation = evaluate_on(model, image, [mask])[0].metrics.as_dict()
    return (model_metrics, approximation, model_floor, approximation_floor,
            noise_verdicts(model_metrics, model_floor),
            noise_verdicts(approximation, approximation_floor))


def _steps(report, profile: str, mask, objects: tuple, cache: dict) -> list[ModelStep]:
    """Return the steps of ``profile`` (:func:`model_steps`), [] when one has no reference."""
    from ..metrics.compute import noise_verdicts

    chain = model_steps(profile)
    if len(chain) < 2 or any(key not in report.model_references for key in chain):
        return []
    steps = []
    for before, key in zip([None, *chain[:-1]], chain, strict=True):
        cache_key = ("step", key, before, objects)
        if cache_key not in cache:
            earlier = report.reference if before is None else report.model_references[before]
            metrics, floor = _model_error(earlier, report.model_references[key], mask)
            cache[cache_key] = (metrics, floor)
        metrics, floor = cache[cache_key]
        steps.append(ModelStep(key, before, metrics, floor, noise_verdicts(metrics, floor)))
    return steps


def with_both_variances(reference: Image, model: Image) -> Image:
    """Return ``reference`` carrying its variance plus ``model``'s (as it is without both).

    A model error compares two independent renders: the variance its relative MSE
    discounts, and its noise floor, are the sum of theirs.
    """
    if reference.variance is None or model.variance is None:
        return reference
    return Image(reference.rgb, reference.variance + model.variance, reference.metadata)


def _model_error(reference: Image, model: Image, mask) -> tuple[dict, dict | None]:
    """Return the profile's error over ``mask`` and its floor (the two variances summed)."""
    from ..metrics.compute import evaluate_on

    both = with_both_variances(reference, model)
    metrics = evaluate_on(both, model, [mask])[0].metrics.as_dict()
    return metrics, _floor(both, mask)


def _floor(image: Image, mask) -> dict | None:
    from ..metrics.compute import noise_floors

    found = noise_floors(image, [mask])[0]
    return None if found is None else found.as_dict()
