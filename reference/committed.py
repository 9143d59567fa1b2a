"""Converged references of the built-in scenes, shipped with the suite.

Each default scene of the report has a reference rendered to a noise target
(:func:`~translucent.reference.render.render_to_target`: median relative standard error over
the lit pixels at most 1 %, 99th percentile at most 5 %, or the stated budget spent) and
stored as ``reference/data/<scene>.exr``: the mean, the variance of the mean and the
provenance (scene content hash, integrator, spp, passes, seconds, variant, Mitsuba version,
the noise reached and why the render stopped).

Beside them, the *model references* (:data:`MODEL_PLANS`): each scene whose translucent
objects are homogeneous rendered by the BSSRDF path tracer
(:mod:`~translucent.reference.bssrdf_path`) with the default radial profile, and the glossy
scene with the BRDF-editing method's PCA BRDF (:mod:`~translucent.reference.brdf_plugins`),
stored as ``reference/data/model/<scene>.<model>.exr``. Against the reference it is the
model's own error; against a fast method of that model, the method's.

A committed reference is used only while its scene is the one it was rendered from: the
header's ``scene_content_hash`` must equal the hash of the scene as it loads now (and a
model reference's header must name the integrator and the profile it stands for). A stale,
unreadable, wrong-sized or non-finite file is an error that names the file and the command
that renders it again (``translucent references render NAME``); it is never silently re-used
and never silently replaced.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..image import Image, read_exr
from .mitsuba_scene import GATHER_INTEGRATOR
from .model_keys import GEOMETRY_SUFFIX, WALK_SUFFIX, model_key

__all__ = ["REFERENCE_FOLDER", "PLANS", "MODEL_PLANS", "MODEL_PROFILES", "ReferencePlan",
           "CommittedReference", "committed_path", "committed_reference",
           "committed_scene_names", "committed_model_cases", "committed_model_scene_names",
           "geometry_model",
           "render_committed", "rerender_command"]

#: Where the committed references live.
REFERENCE_FOLDER = Path(__file__).resolve().parent / "data"


@dataclass(frozen=True)
class ReferencePlan:
    """How a built-in scene's committed reference is rendered.

    Attributes
    ----------
    spp : int
        Samples per pixel of each pass: a pass of a few seconds to a few tens of seconds,
        so that there are many passes (the variance is estimated from them).
    budget_seconds : float
        Rendering time at most (wall seconds on the machine that renders it).
    target_rse, target_p99_rse : float
        Median and 99th-percentile relative standard error over the lit pixels to reach.
    min_passes : int
        Passes at least, whatever the noise: the per-pixel variance is read from them.
    integrator : str, optional
        The Mitsuba integrator (default: the reference's own choice, ``volpath`` with
        media, ``volpathmis`` with chromatic media rendered in RGB).
    """

    spp: int
    budget_seconds: float
    target_rse: float = 0.01
    target_p99_rse: float = 0.05
    min_passes: int = 16
    integrator: str | None = None


#: The built-in scenes with a committed reference and how each is rendered. The spp of a
#: pass follows the scene's cost (the Cornell block renders its medium once per channel).
#: The bowl's chromatic Chicken1 (albedo 0.67-0.91) gives RGB ``volpath`` fireflies: its
#: distances are sampled with one channel's extinction and the others weighted by ratios
#: of transmittances. Measured at 128 spp x 12 passes, efficiency (1 / (RSE^2 x seconds))
#: against ``volpath``: ``volpathmis`` 1.8x on the median and 9.5x on the 99th percentile
#: (8.4 % against 28.5 %), per-channel ``volpath`` 1.1x and 6.4x.
PLANS: dict[str, ReferencePlan] = {
    "glossy": ReferencePlan(spp=1024, budget_seconds=600.0),
    "glossy_box": ReferencePlan(spp=1024, budget_seconds=1200.0),
    "bowl": ReferencePlan(spp=1024, budget_seconds=1800.0, integrator="volpathmis"),
    "sphere": ReferencePlan(spp=128, budget_seconds=2400.0),
    "cornell_block": ReferencePlan(spp=32, budget_seconds=3600.0),
    "solid_checker": ReferencePlan(spp=256, budget_seconds=1500.0),
    "solid_veins": ReferencePlan(spp=256, budget_seconds=2400.0),
    "solid_gradient": ReferencePlan(spp=256, budget_seconds=1500.0),
    # manifold next-event estimation costs 15-20x volpath's time per sample, and makes a
    # connection at every medium vertex: RGB's ratios of transmittances (Skin1 is
    # chromatic) gave red a variance a sample 41x that of a red-only render, the fireflies
    # of its 99th percentile; one channel at a time (the conversion's own choice for
    # volpath_mnee and a chromatic medium) costs 2.7x (docs/references.md)
    "sphere_dielectric": ReferencePlan(spp=64, budget_seconds=6600.0),
    # the same estimator on a convex pebble on a floor, under a point and a spot light
    "dielectric_on_floor": ReferencePlan(spp=64, budget_seconds=3600.0),
}


#: The integrator of a profile's model reference (the BSSRDF path tracer).
MODEL_INTEGRATOR = "bssrdf_path"

#: The built-in scenes whose model references are committed, per model, and how each is rendered:
#: every default scene whose translucent objects are homogeneous with the profile every method uses
#: unless told otherwise (:data:`translucent.fast.knobs.DEFAULT_PROFILE`, the classical dipole), by
#: the BSSRDF path tracer, which needs no manifold search behind a dielectric and no per-channel
#: walks, with the half-space profile alone (``dipole``) and with the object's geometry
#: (:mod:`.geometry_term`: ``dipole+walk``, the model of PRT and splatting by default, and
#: ``dipole+geometry``, diffusion's); every default scene with a heterogeneous (solid) medium with
#: the dipole of each of its media mixed by each method's rule (``dipole+geometric_mean``:
#: splatting's, ``dipole+segment_mix``: radiosity's; :mod:`.bssrdf_tables`); and the glossy scene
#: with the BRDF-editing method's default model, the 6-term PCA of its BRDFs
#: (:func:`~translucent.materials.brdf_pca.pca_model_name`), by Mitsuba's path tracer with the PCA
#: BRDF plugin (:mod:`.brdf_plugins`), and with the method's full model, that PCA carried by its
#: Lambertian-gather transport (``brdf_pca_k6+lambertian_gather2``), and by the transport of its
#: knob ``gather_reflection="brdf"`` (``brdf_pca_k6+glossy_gather2``), by the gather integrator of
#: the same module.
#: The heterogeneous rules the built-in methods follow (splatting's, radiosity's).
METHOD_RULES = ("geometric_mean", "segment_mix")

MODEL_PLANS: dict[str, dict[str, ReferencePlan]] = {
    name: {model: ReferencePlan(spp=spp, budget_seconds=1200.0, integrator=MODEL_INTEGRATOR)
           for model in ("dipole", "dipole" + GEOMETRY_SUFFIX, "dipole" + WALK_SUFFIX)}
    for name, spp in (("sphere", 256), ("bowl", 256), ("cornell_block", 64),
                      ("sphere_dielectric", 256), ("dielectric_on_floor", 256))
} | {
    name: {f"dipole+{rule}": ReferencePlan(spp=256, budget_seconds=1200.0,
                                          integrator=MODEL_INTEGRATOR)
           for rule in METHOD_RULES}
    for name in ("solid_checker", "solid_gradient", "solid_veins")
} | {
    name: {"brdf_pca_k6": ReferencePlan(spp=1024, budget_seconds=900.0, integrator="path"),
           **{f"brdf_pca_k6+{transport}2": ReferencePlan(
               spp=1024, budget_seconds=900.0, integrator=GATHER_INTEGRATOR)
              for transport in ("lambertian_gather", "glossy_gather")}}
    for name in ("glossy", "glossy_box")
}

#: Every model whose references are committed (for some scene).
MODEL_PROFILES = tuple(sorted({profile for plans in MODEL_PLANS.values() for profile in plans}))


def geometry_model(header: dict) -> str | None:
    """Return the geometry model a model reference's header records (None: none)."""
    geometry = header.get("geometry")
    return geometry.get("model", "diffusion") if isinstance(geometry, dict) else None


def committed_model_cases() -> list[tuple[str, str]]:
    """Return every ``(scene, model)`` whose model reference is committed."""
    return [(name, profile) for name, plans in MODEL_PLANS.items() for profile in plans]


def committed_scene_names() -> list[str]:
    """Return the built-in scenes that have a reference plan, in the order of :data:`PLANS`."""
    return list(PLANS)


def committed_model_scene_names(profile: str | None = None) -> list[str]:
    """Return the built-in scenes with a committed model reference (of ``profile``)."""
    return [name for name, plans in MODEL_PLANS.items() if profile is None or profile in plans]


def _plan(name: str, profile: str | None = None) -> ReferencePlan:
    """Return the plan of ``name`` (a model reference's with ``profile``), or an InputError."""
    if profile is None:
        if name not in PLANS:
            raise InputError(f"no committed reference is planned for this scene (planned: "
                             f"{', '.join(PLANS)})", field="scene", value=name)
        return PLANS[name]
    if profile not in MODEL_PROFILES:
        raise InputError(f"no model reference is committed for this profile (committed: "
                         f"{', '.join(MODEL_PROFILES)})", field="profile", value=profile)
    if profile not in MODEL_PLANS.get(name, {}):
        raise InputError(f"no committed model reference of {profile} is planned for this "
                         f"scene (planned: {', '.join(committed_model_scene_names(profile))})",
                         field="scene", value=name)
    return MODEL_PLANS[name][profile]


def committed_path(name: str, profile: str | None = None) -> Path:
    """Return where the committed reference of built-in scene ``name`` lives.

    With ``profile``: its model reference, ``model/<name>.<profile>.exr``.
    """
    if profile is None:
        return REFERENCE_FOLDER / f"{name}.exr"
    return REFERENCE_FOLDER / "model" / f"{name}.{profile}.exr"


def rerender_command(name: str, profile: str | None = None) -> str:
    """Return the command that renders the committed reference of ``name`` again."""
    return f"translucent references render {name}" + \
        (f" --profile {profile}" if profile is not None else "")


@dataclass(frozen=True)
class CommittedReference:
    """A committed reference and what is known of it.

    Attributes
    ----------
    name : str
        The built-in scene.
    path : Path
    profile : str or None
        A model reference's profile; None: the volumetric reference.
    image : Image or None
        None when the file is missing or cannot be used (``problem`` says why).
    current : bool
        True when the file is readable, of the scene's size, finite, with a variance, and
        rendered from the scene as it loads now.
    problem : str
        Why it cannot be used ("" when current).
    """

    name: str
    path: Path
    image: Image | None
    current: bool
    problem: str = ""
    profile: str | None = None

    def require(self) -> Image:
        """Return the image, or raise :class:`InputError` naming the file and the fix."""
        if not self.current:
            raise InputError(f"{self.problem}; render it again with "
                             f"`{rerender_command(self.name, self.profile)}`", file=self.path,
                             field="scene", value=self.name)
        return self.image


def committed_reference(name: str, scene=None, profile: str | None = None
                        ) -> CommittedReference:
    """Look up and check the committed reference of built-in scene ``name``.

    Parameters
    ----------
    name : str
        A key of :data:`PLANS` (of :data:`MODEL_PLANS` with ``profile``).
    scene : Scene, optional
        The scene as loaded now (default: the built-in scene ``name``).
    profile : str, optional
        The model reference of this profile (:data:`MODEL_PROFILES`) instead of the
        volumetric one; its header must name ``bssrdf_path`` and the profile.

    Returns
    -------
    CommittedReference
        ``current`` is False, with the reason in ``problem``, for a missing, unreadable,
        wrong-sized, non-finite or stale file.
    """
    import numpy as np

    from ..cache import content_hash

    plan = _plan(name, profile)
    path = committed_path(name, profile)
    if scene is None:
        from ..scenes import load_scene

        scene = load_scene(name)
    what = "the committed reference" if profile is None else "the committed model reference"

    def unusable(problem, image=None):
        return CommittedReference(name, path, image, False, problem.replace(
            "the committed reference", what, 1), profile)

    if not path.is_file():
        return unusable("the committed reference is missing")
    try:
        image = read_exr(path)  # refuses NaN and Inf pixels
    except InputError as error:
        return unusable(f"the committed reference cannot be read ({error.reason})")
    expected = (scene.camera.height, scene.camera.width)
    if image.shape != expected:
        return unusable(f"the committed reference is {image.shape[1]} x {image.shape[0]} "
                        f"pixels, the scene's camera {expected[1]} x {expected[0]}", image)
    if image.variance is None or not np.isfinite(image.variance).all():
        return unusable("the committed reference has no usable variance", image)
    recorded = image.metadata.get("scene_content_hash")
    if recorded != content_hash(scene):
        return unusable(f"the committed reference is stale: it was rendered from another "
                        f"version of scene {name!r} (scene hash {str(recorded)[:12]}, now "
                        f"{content_hash(scene)[:12]})", image)
    if profile is not None:
        meta = image.metadata
        made = (meta.get("profile") or {}).get("name") if isinstance(
            meta.get("profile"), dict) else None
        if made is not None:
            made = model_key(made, geometry_model(meta))
        if meta.get("integrator") != plan.integrator or made != profile:
            return unusable(f"the committed reference is not the {plan.integrator} render of "
                            f"profile {profile!r} (integrator {meta.get('integrator')!r}, "
                            f"profile {made!r})", image)
        if isinstance(meta.get("geometry"), dict):
            from .geometry_term import geometry_settings  # needs numba: only for such a one

            now = geometry_settings(geometry_model(meta))
            if meta["geometry"] != now:
                return unusable(f"the committed reference is stale: its geometry correction "
                                f"was rendered with {meta['geometry']}, the suite's is "
                                f"{now}", image)
    return CommittedReference(name, path, image, True, profile=profile)


def render_committed(name: str, *, budget_seconds: float | None = None,
                     progress: bool = True, on_pass=None, profile: str | None = None) -> Image:
    """Render the committed reference of ``name`` to its plan and write it in place.

    Parameters
    ----------
    name : str
        A key of :data:`PLANS` (of :data:`MODEL_PLANS` with ``profile``).
    profile : str, optional
        Render the model reference of this profile (:data:`MODEL_PROFILES`).
    budget_seconds : float, optional
        Overrides the plan's budget.
    progress : bool
        Show a progress bar.
    on_pass : callable, optional
        As :func:`~translucent.reference.render.render_to_target`.

    Returns
    -------
    Image
        The reference as written to :func:`committed_path`.
    """
    from ..scenes import load_scene
    from .render import render_to_target

    plan = _plan(name, profile)
    budget = plan.budget_seconds if budget_seconds is None else budget_seconds
    if not (isinstance(budget, int | float) and math.isfinite(budget) and budget > 0):
        raise InputError("must be > 0 seconds", field="--budget", value=budget_seconds)
    image = render_to_target(load_scene(name), target_rse=plan.target_rse,
                             target_p99_rse=plan.target_p99_rse, budget_seconds=budget,
                             spp=plan.spp, min_passes=plan.min_passes, progress=progress,
                             integrator=plan.integrator, on_pass=on_pass, profile=profile)
    image = image.with_metadata(committed=True)
    path = committed_path(name, profile)
    path.parent.mkdir(parents=True, exist_ok=True)
    image.write(path)
    return image
