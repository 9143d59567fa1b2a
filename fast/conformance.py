"""Checks that a fast method keeps the contract, run the same way over every registered method.

Each check takes a method's module (or object), a small scene it applies to and the knobs
to run it with, and raises :class:`ConformanceFailure` (an :class:`AssertionError`) saying
what broke, or returns a sentence on what it checked, or raises :class:`NotChecked` where
the scene gives it nothing to check. :func:`check_method` runs them all; the suite's own
tests run it over every method of :data:`~translucent.fast.registry.METHODS`, and a
method kept elsewhere can run it in its own tests::

    from translucent.fast.conformance import check_method
    check_method("lambert")

The checks, and why each matters to a user of the report:

``contract``
    The module has the contract's names (:func:`~translucent.fast.registry.contract_problems`).
``refusal``
    Where the method does not apply (a catalogue scene it refuses, and the scene with its
    lights taken away), ``applies_to`` says why with a
    :class:`~translucent.fast.base.Refusal`: a reason code programs branch on and a
    sentence, never a bare string or a falsy answer.
``knobs``
    An unknown knob is refused with an :class:`~translucent.errors.InputError` (a typo in
    a benchmark must not run the defaults silently).
``render``
    ``precompute(scene).render()`` is an :class:`~translucent.image.Image` of the
    camera's size, three channels, finite and non-negative radiance.
``determinism``
    Two precomputations in empty caches give the same image (a report is reproducible).
``relighting``
    ``state.render(lights=moved)`` equals a fresh precomputation of the scene lit by the
    moved lights, and differs from the first frame: relighting reuses the precomputation
    and really uses the new lights.
``editing``
    ``state.render(material=edited)`` equals a fresh precomputation of the scene with
    the edited material (Dipole: another measured medium; analytic BRDF: another
    gamma; Lambertian: half the albedo).
``profiles``
    Where the method declares a ``profile`` knob
    (:func:`~translucent.fast.knobs.profile_knob`): every radial profile it takes renders
    a finite image, and one that differs from the default profile's wherever the profile
    differs on the scene's Dipole materials (the knob is really used); every profile it
    refuses is an :class:`~translucent.errors.InputError` naming the profile
    (:func:`check_profile` checks one). With the method's quick knobs this runs with
    its default ``geometry`` as well: each profile takes the object's shape.
``geometry``
    Where the method declares a ``geometry`` knob
    (:func:`~translucent.fast.object_geometry.geometry_knobs`): each model of the object's
    shape (``"walk"``, ``"diffusion"``) renders a finite image that differs from the
    half-space profile's on the scene's closed Dipole object (the knob is really used), and
    adds light there (a finite object re-emits more than the half-space, never less, on a
    sphere; the walks also return the light the dipole's diffusion misses).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..image import Image
from .base import Refusal, applicability, scored_object_names
from .registry import contract_problems, method

__all__ = ["CHECKS", "ConformanceFailure", "IMAGE_RTOL", "NotChecked", "TINY_SPHERE",
           "check_method", "check_profile", "conformance_scene", "edited_material",
           "profile_knob_of", "run_check", "run_profile_check", "tiny_sphere_text"]

def tiny_sphere_text(name: str = "conformance_sphere", size: int = 16) -> str:
    """Return a scene file: a 320-face skin sphere under a point light, ``size`` pixels square.

    The first scene the checks try (small enough that every check of a precomputing method
    takes seconds); tests of the report use it too.
    """
    return f"""
[scene]
name = "{name}"
description = "a 320-face skin sphere under a point light"
mm_per_unit = 10.0

[camera]
origin = [0.0, 0.0, 5.0]
target = [0.0, 0.0, 0.0]
fov = 30.0
width = {size}
height = {size}

[[objects]]
name = "sphere"
mesh = {{ type = "icosphere", subdivisions = 2, radius = 1.0 }}
material = {{ type = "measured", name = "Skin1" }}

[[lights]]
type = "point"
position = [3.0, 4.0, 4.0]
intensity = 100.0
"""


#: The scene file of the first scene the checks try (:func:`tiny_sphere_text`).
TINY_SPHERE = tiny_sphere_text()

#: Scenes tried, in order, for the first one a method applies to: the tiny sphere, then
#: catalogue scenes.
SCENES = ("conformance_sphere", "glossy", "cornell_block", "heterogeneous", "solid_gradient",
          "bowl")

#: Width of the conformance scenes, pixels (the height keeps the camera's aspect).
WIDTH = 16

#: Two renders of the same thing agree to this relative L2 difference. Methods solve with
#: iterative solvers whose stopping point depends on the starting guess (radiosity's
#: tolerance is 1e-4), and sum in parallel in an order that varies: float32 round-off and
#: solver tolerance are far below it; a method that ignores its new lights or material is
#: off by the size of the change (the moved lights change the images by more than 1e-2).
IMAGE_RTOL = 2e-3

#: How far the relighting check moves the lights: scene units, or radians for directions.
LIGHT_OFFSET = 0.3

#: The smallest relative change moving the lights must make for the relighting check to
#: test anything.
MIN_RELIGHT_CHANGE = 1e-2

#: An unknown knob name no method has.
UNKNOWN_KNOB = "no_such_knob_of_any_method"


class ConformanceFailure(AssertionError):
    """A method broke the contract: the message says which check and how."""


class NotChecked(Exception):
    """The scene gives the check nothing to test (say why)."""


def conformance_scene(module, scenes=SCENES, width: int = WIDTH):
    """Return the first catalogue scene ``module`` applies to, at ``width`` pixels.

    Raises
    ------
    NotChecked
        When the method applies to none of them (then give :func:`check_method` a scene).
    """
    from ..scenes import load_scene, loads_scene

    reasons = []
    for name in scenes:
        scene = loads_scene(TINY_SPHERE) if name == "conformance_sphere" else load_scene(name)
        reason = applicability(module.applies_to, scene)
        if reason is None:
            camera = scene.camera
            height = max(1, round(width * camera.height / camera.width))
            return scene.with_camera(replace(camera, width=width, height=height))
        reasons.append(f"{name}: {reason}")
    raise NotChecked("applies to no catalogue scene (" + "; ".join(reasons) + ")")


def _precompute(module, scene, knobs):
    from ..cache import private_cache

    with private_cache():
        return module.precompute(scene, **knobs)


def _pixels(image, scene, what: str) -> np.ndarray:
    if not isinstance(image, Image):
        raise ConformanceFailure(f"{what} returned a {type(image).__name__}, not an Image")
    pixels = np.asarray(image.rgb)
    shape = (scene.camera.height, scene.camera.width, 3)
    if pixels.shape != shape:
        raise ConformanceFailure(f"{what} is {pixels.shape}, the camera's size is {shape}")
    if not np.all(np.isfinite(pixels)):
        raise ConformanceFailure(f"{what} has {int((~np.isfinite(pixels)).sum())} values "
                                 "that are not finite")
    if (pixels < 0).any():
        raise ConformanceFailure(f"{what} has negative radiance (min {pixels.min():.3g})")
    return pixels.astype(np.float64)


def _relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    scale = max(float(np.sqrt(np.mean(b**2))), 1e-30)
    return float(np.sqrt(np.mean((a - b) ** 2))) / scale


def _agree(a, b, what: str) -> str:
    difference = _relative_difference(a, b)
    if not difference <= IMAGE_RTOL:
        raise ConformanceFailure(f"{what}: relative L2 difference {difference:.3g} > "
                                 f"{IMAGE_RTOL:g}")
    return f"{what}: relative L2 difference {difference:.2g}"


def check_contract(module, scene, knobs) -> str:
    """Check that the contract's names are there."""
    problems = contract_problems(module)
    if problems:
        raise ConformanceFailure("; ".join(problems))
    return "applies_to, precompute and DEFAULT_KNOBS are there"


def check_refusal(module, scene, knobs) -> str:
    """Check that every refusal is a Refusal with a code and a sentence."""
    from ..scenes import load_scene, loads_scene

    candidates = [(name, loads_scene(TINY_SPHERE) if name == "conformance_sphere"
                   else load_scene(name)) for name in SCENES]
    candidates.append(("the scene without its lights", scene.with_lights(())))
    refused = []
    for name, candidate in candidates:
        reason = module.applies_to(candidate)
        if reason is None:
            continue
        if not isinstance(reason, Refusal):
            raise ConformanceFailure(f"applies_to({name}) returned a {type(reason).__name__} "
                                     f"({reason!r}): a refusal is a translucent.fast.base."
                                     "Refusal(code, sentence)")
        if not reason.code or not reason.sentence:
            raise ConformanceFailure(f"applies_to({name}): a Refusal without a code or a "
                                     f"sentence ({reason!r})")
        refused.append(f"{name} ({reason.code})")
    if not refused:
        raise NotChecked("applies to every catalogue scene and to the scene without lights")
    return "refuses with a Refusal: " + ", ".join(refused)


def check_knobs(module, scene, knobs) -> str:
    """Check that an unknown knob is an InputError."""
    try:
        _precompute(module, scene, {**knobs, UNKNOWN_KNOB: 1})
    except InputError as error:
        return f"an unknown knob is refused: {error.reason}"
    raise ConformanceFailure(f"precompute accepted the unknown knob {UNKNOWN_KNOB!r}: it "
                             "must raise translucent.errors.InputError "
                             "(translucent.fast.base.with_defaults does it)")


def check_render(module, scene, knobs) -> str:
    """Check that a frame is a finite, non-negative image of the camera's size."""
    pixels = _pixels(_precompute(module, scene, knobs).render(), scene, "render()")
    if not pixels.any():
        raise ConformanceFailure("render() is black on a scene the method applies to")
    return f"a {pixels.shape[1]} x {pixels.shape[0]} image, finite and non-negative"


def check_determinism(module, scene, knobs) -> str:
    """Check that two precomputations in empty caches give the same image."""
    first = _pixels(_precompute(module, scene, knobs).render(), scene, "render()")
    second = _pixels(_precompute(module, scene, knobs).render(), scene, "render()")
    return _agree(second, first, "two precomputations")


def check_relighting(module, scene, knobs) -> str:
    """Check that relighting equals precomputing the relit scene, and changes the image."""
    from ..scenes import moved_lights

    lights = moved_lights(scene.lights, LIGHT_OFFSET)
    state = _precompute(module, scene, knobs)
    before = _pixels(state.render(), scene, "render()")
    relit = _pixels(state.render(lights=lights), scene, "render(lights=moved)")
    change = _relative_difference(relit, before)
    if change < MIN_RELIGHT_CHANGE:
        if _relative_difference(
                _pixels(_precompute(module, scene.with_lights(lights), knobs).render(), scene,
                        "render() of the relit scene"), before) < MIN_RELIGHT_CHANGE:
            raise NotChecked("moving the lights does not change this scene's image")
        raise ConformanceFailure(f"render(lights=moved) changed the image by {change:.2g} "
                                 "only: the new lights were not used")
    fresh = _pixels(_precompute(module, scene.with_lights(lights), knobs).render(), scene,
                    "render() of the relit scene")
    return _agree(relit, fresh, "relit against precomputed with the moved lights")


def edited_material(material):
    """Return another material of the same kind (None where the kind is not known here)."""
    from ..materials import Dipole, Lambertian, measured_medium
    from ..materials.brdfs import GAMMA_RANGES, AnalyticBRDF

    if isinstance(material, Dipole):
        for name in ("Ketchup", "Marble"):
            other = measured_medium(name)
            if not np.allclose(other.sigma_a, material.sigma_a):
                return replace(other, eta=material.eta)
    if isinstance(material, AnalyticBRDF):
        low, high = GAMMA_RANGES[material.model]
        middle = 0.5 * (low + high)
        gamma = middle if abs(material.gamma - middle) > 0.1 * (high - low) else \
            low + 0.25 * (high - low)
        return replace(material, gamma=gamma)
    if isinstance(material, Lambertian):
        return Lambertian(material.albedo * 0.5)
    return None


def _edit_candidates(module, scene):
    """Scored objects with an editable material: translucent and glossy before Lambertian."""
    from ..materials import Lambertian

    names = scored_object_names(module, scene)
    kinds: dict = {}
    for name in names:
        kinds.setdefault(type(scene.object(name).material), []).append(name)
    ordered = sorted(names, key=lambda n: isinstance(scene.object(n).material, Lambertian))
    for name in ordered:
        material = edited_material(scene.object(name).material)
        if material is not None:
            alone = len(kinds[type(scene.object(name).material)]) == 1
            yield name, material, (material if alone else {name: material})


def check_editing(module, scene, knobs) -> str:
    """Check that editing equals precomputing the edited scene.

    The edit is one material where the object is the only one of its kind, else
    ``{object name: material}``; an edit the method refuses (an InputError) moves on to
    the next object.
    """
    refused = []
    state = None
    for chosen, material, argument in _edit_candidates(module, scene):
        edited_scene = scene.with_material(chosen, material)
        reason = applicability(module.applies_to, edited_scene)
        if reason is not None:
            refused.append(f"{chosen}: {reason}")
            continue
        state = state or _precompute(module, scene, knobs)
        _pixels(state.render(), scene, "render()")
        try:
            edited = _pixels(state.render(material=argument), scene,
                             "render(material=edited)")
        except InputError as error:
            refused.append(f"{chosen}: {error.reason}")
            state = None  # a refused edit may have left the state half-edited
            continue
        fresh = _pixels(_precompute(module, edited_scene, knobs).render(), scene,
                        "render() of the edited scene")
        return _agree(edited, fresh,
                      f"{chosen} edited against precomputed with the new material")
    raise NotChecked("no scored object whose edit the method takes"
                     + (" (" + "; ".join(refused) + ")" if refused else ""))


#: Two profiles whose values differ by less than this, relative to the larger, at every
#: probed radius are the same profile (the image must then stay the same).
SAME_PROFILE_RTOL = 1e-9


def profile_knob_of(module):
    """Return the method's ``profile`` knob (a :class:`~translucent.fast.knobs.Knob`) or None."""
    spec = getattr(module, "KNOBS", None)
    try:
        return spec["profile"] if spec is not None and "profile" in spec else None
    except (KeyError, TypeError):
        return None


def _profile_differs(scene, name: str, default: str) -> bool:
    """Whether profile ``name`` differs from ``default`` on some Dipole material of the scene."""
    from ..materials import Dipole
    from .knobs import radial_profile

    radii = np.geomspace(1e-3, 1e2, 61)
    for obj in scene.objects:
        if isinstance(obj.material, Dipole):
            chosen = radial_profile(name, obj.material).reflection(radii)
            usual = radial_profile(default, obj.material).reflection(radii)
            if np.any(np.abs(chosen - usual) > SAME_PROFILE_RTOL * np.maximum(chosen, usual)):
                return True
    return False


def check_profile(module, scene, knobs, name: str) -> str:
    """Check one value of the method's ``profile`` knob: taken and used, or refused by name.

    Raises
    ------
    NotChecked
        The method declares no ``profile`` knob.
    ConformanceFailure
        A profile it takes renders a bad image, or the default profile's image where the
        profile differs; one it refuses is taken, or refused without being named.
    """
    from ..cache import private_cache

    knob = profile_knob_of(module)
    if knob is None:
        raise NotChecked("the method declares no profile knob")
    refused = dict(knob.refused)
    if name in refused:
        try:
            _precompute(module, scene, {**knobs, "profile": name})
        except InputError as error:
            if name not in str(error):
                raise ConformanceFailure(f"profile {name!r} is refused without being named: "
                                         f"{error}") from None
            return f"profile {name!r} is refused: {error.reason}"
        raise ConformanceFailure(f"profile {name!r} is declared refused ({refused[name]}), "
                                 "but precompute took it")
    if name not in knob.choices:
        raise ConformanceFailure(f"profile {name!r} is neither taken nor refused by the knob")
    with private_cache():
        pixels = _pixels(module.precompute(scene, **{**knobs, "profile": name}).render(),
                         scene, f"render() with profile {name!r}")
        if name == knob.default:
            return f"the default profile {name!r} renders"
        usual = _pixels(module.precompute(scene, **knobs).render(), scene, "render()")
    if not pixels.any():
        raise ConformanceFailure(f"render() with profile {name!r} is black")
    difference = _relative_difference(pixels, usual)
    if _profile_differs(scene, name, knob.default) and not difference > IMAGE_RTOL:
        raise ConformanceFailure(f"profile {name!r} renders the default profile's image "
                                 f"(relative L2 difference {difference:.2g}): not used")
    return f"profile {name!r} renders, {difference:.2g} from the default's"


def check_profiles(module, scene, knobs) -> str:
    """Check every value of the ``profile`` knob (:func:`check_profile`), taken or refused."""
    knob = profile_knob_of(module)
    if knob is None:
        raise NotChecked("the method declares no profile knob")
    names = list(knob.choices) + [name for name, _ in knob.refused]
    for name in names:
        check_profile(module, scene, knobs, name)
    return (f"{len(knob.choices)} profiles taken and used, {len(knob.refused)} refused by "
            "name")


def check_geometry(module, scene, knobs) -> str:
    """Check the ``geometry`` knob: the object's shape is taken, used, and adds light."""
    spec = getattr(module, "KNOBS", None)
    if spec is None or "geometry" not in spec:
        raise NotChecked("the method declares no geometry knob")
    # the half-space profile alone (a method's own finite-object energy off too)
    half_space = getattr(module, "HALF_SPACE_KNOBS", {"geometry": "half_space"})
    flat = _pixels(module.precompute(scene, **{**knobs, **half_space}).render(),
                   scene, "render() with geometry 'half_space'")
    gains = []
    for model in ("walk", "diffusion"):
        shaped = _pixels(module.precompute(scene, **{**knobs, "geometry": model}).render(),
                         scene, f"render() with geometry {model!r}")
        difference = _relative_difference(shaped, flat)
        if not difference > IMAGE_RTOL:
            raise ConformanceFailure(f"geometry {model!r} renders the half-space's image "
                                     f"(relative L2 difference {difference:.2g}): not used")
        gain = shaped.sum() / max(flat.sum(), 1e-300)
        if not gain > 1.0:
            raise ConformanceFailure(f"geometry {model!r} takes light away on a closed "
                                     f"object ({gain:.4f} of the half-space's)")
        gains.append(f"{model!r} renders {gain:.4f} of the half-space's light")
    return "geometry " + ", ".join(gains)


#: The checks by name, in the order :func:`check_method` runs them.
CHECKS = {"contract": check_contract, "refusal": check_refusal, "knobs": check_knobs,
          "render": check_render,
          "determinism": check_determinism, "relighting": check_relighting,
          "editing": check_editing, "profiles": check_profiles, "geometry": check_geometry}


def run_check(name: str, check: str, scene=None, knobs: dict | None = None) -> str:
    """Run one check on method ``name``; see :func:`check_method` for the arguments.

    Raises
    ------
    ConformanceFailure
        The check failed.
    NotChecked
        The check has nothing to test on this scene.
    """
    return CHECKS[check](*_prepared(name, scene, knobs))


def run_profile_check(name: str, profile: str, scene=None, knobs: dict | None = None) -> str:
    """Run :func:`check_profile` for one profile on method ``name`` (as :func:`run_check`)."""
    return check_profile(*_prepared(name, scene, knobs), profile)


def _prepared(name: str, scene, knobs):
    """Return the method's module, the scene and the knobs the checks run with."""
    module = method(name)
    if scene is None:
        scene = conformance_scene(module)
    chosen = dict(getattr(module, "QUICK_KNOBS", {}) or {}) if knobs is None else dict(knobs)
    return module, scene, chosen


def check_method(name: str, scene=None, knobs: dict | None = None) -> dict[str, str]:
    """Run every check on the registered method ``name``; the first failure raises.

    Parameters
    ----------
    name : str
        A registered method (:data:`~translucent.fast.registry.METHODS`).
    scene : Scene, optional
        Where to run it; default the first catalogue scene it applies to, at 16 pixels
        wide (:func:`conformance_scene`).
    knobs : dict, optional
        Default the method's ``QUICK_KNOBS`` (else its defaults).

    Returns
    -------
    dict
        Check name -> what it found ("not checked: ..." where it had nothing to test).

    Raises
    ------
    ConformanceFailure
        Naming the check that failed and how.
    """
    try:
        prepared = _prepared(name, scene, knobs)  # once: the scene is loaded a single time
    except NotChecked as why:
        return {check: f"not checked: {why}" for check in CHECKS}
    found = {}
    for check, run in CHECKS.items():
        try:
            found[check] = run(*prepared)
        except NotChecked as why:
            found[check] = f"not checked: {why}"
        except ConformanceFailure as failure:
            raise ConformanceFailure(f"{name}: {check}: {failure}") from None
    return found
