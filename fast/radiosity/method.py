"""The fast-method contract of translucent radiosity: applicability, knobs, precompute, approx."""

from __future__ import annotations

import time

from ...errors import InputError
from ...image import Image
from ...materials.profiles import (
    MixedProfiles,
    profile_for,
)
from ...resources import RADIOSITY_BYTES_PER_PAIR, check_memory
from ...scenes.mesh_shape import closed_surface
from ..base import (
    NO_TRANSLUCENT_OBJECT,
    UNSUPPORTED_MATERIAL,
    Refusal,
    StageLog,
    StageProgress,
    applicability,
    load_or_precompute,
    refuse_inapplicable,
)
from ..solid_inputs import mixed_profiles_from_solid, surface_scene
from .form_factors import build_patches, form_factors, needs_form_factors
from .geometry import scattering_geometry
from .knobs import COMPONENTS, FORMAT_VERSION, KNOBS
from .scattering import scattering_profile
from .state import RadiosityState, materials_of

#: The reason code of a scene with no translucent object: still solved (classical radiosity)
#: when asked for directly, but not this method's to be scored on.


def applies_to(scene) -> Refusal | None:
    """None when every material is Lambertian, a Dipole, a RadialProfile or MixedProfiles.

    Translucent radiosity assumes diffuse surfaces and isotropic multiple scattering
    (Sheng et al. 2014, Sect. 1, 7); glossy BRDFs and SubEdit textures are not modelled.
    """
    scene, _ = surface_scene(scene, mixed_profiles_from_solid)
    translucent = False
    for obj in scene.objects:
        try:
            profile = profile_for(obj.material)
        except InputError:
            return Refusal(UNSUPPORTED_MATERIAL,
                           f"object '{obj.name}' has a {type(obj.material).__name__} "
                           "material; translucent radiosity takes diffuse (Lambertian) "
                           "surfaces and dipole or tabulated radial profiles only")
        translucent |= profile is not None
    if not translucent:
        return Refusal(NO_TRANSLUCENT_OBJECT, "no translucent object: this is classical "
                       "radiosity (every S entry is an albedo)")
    return None


def _resolve_knobs(scene, knobs: dict) -> dict:
    """Return the knobs checked (:data:`KNOBS`), the cut-off max_d derived where None."""
    resolved = KNOBS.resolve(knobs)
    if resolved["geometry"] != "half_space":
        # the geometry's correction carries the object's finite extent in its place
        resolved["finite_object_energy"] = False
    if resolved["max_distance_mm"] is None:
        radii = []
        for obj in scene.objects:
            profile = scattering_profile(obj.material, resolved["profile"])
            profiles = profile.profiles if isinstance(profile, MixedProfiles) else \
                ((profile,) if profile is not None else ())
            radii += [p.support_radius(resolved["profile_energy_cutoff"]) for p in profiles]
        resolved["max_distance_mm"] = float(max(radii, default=1.0))
    return resolved


def scattering_pairs(patches, translucent, sheets, max_distance_mm: float) -> int:
    """Return an upper bound on the stored entries of S: patch pairs closer than max_d.

    Counted as :func:`~translucent.fast.radiosity.geometry.scattering_geometry` finds its
    candidates: front patches of each translucent object whose centroids lie within max_d
    plus the largest patch radius (a pair is kept when a sample on it lies within max_d;
    a concave object's distance inside is longer, so it keeps fewer), four blocks for a
    two-sided sheet, plus every patch's own entry.
    """
    from scipy.spatial import cKDTree

    pairs = len(patches)
    for index in translucent:
        members = patches.of_object(index)
        members = members[~patches.is_back[members]]
        if not len(members):
            continue
        centroids = patches.centroid[members] * patches.mm_per_unit
        reach = max_distance_mm + float(patches.radius[members].max()) * patches.mm_per_unit
        close = int(cKDTree(centroids).query_ball_point(centroids, reach,
                                                        return_length=True).sum())
        pairs += close * (4 if index in sheets else 1)
    return pairs


def check_precompute_memory(scene, patches, translucent, sheets, resolved) -> int:
    """Refuse, before the scattering samples are built, a precomputation too large to hold.

    Returns the estimated bytes (:data:`~translucent.resources.RADIOSITY_BYTES_PER_PAIR` a
    pair of :func:`scattering_pairs`).
    """
    max_d = resolved["max_distance_mm"]
    pairs = scattering_pairs(patches, translucent, sheets, max_d)
    estimate = pairs * RADIOSITY_BYTES_PER_PAIR
    check_memory(estimate, what=f"the radiosity precomputation ({len(patches)} patches, "
                                f"{pairs:,} scattering pairs within max_d = {max_d:g} mm)",
                 field="max_distance_mm", value=max_d, file=scene.source)
    return estimate


def precompute(scene, **knobs) -> RadiosityState:
    """Patches, form factors, optical distances and scattering samples; cached on disk.

    Sheng et al. 2014, Sect. 5.1-5.2. The cache key holds the geometry, which objects are
    translucent (and the labels of heterogeneous ones) and the knobs -- never the lights or
    the homogeneous materials, so relighting and translucency changes reuse it. With
    ``max_distance_mm=None`` the cut-off comes from the scene's profiles (part of the key).
    The knob ``profile`` (the classical dipole by default) picks the radial profile made
    from each Dipole material (:func:`~translucent.fast.radiosity.scattering.scattering_profile`);
    S is filled from it when the state is made, so it enters the key only through that
    cut-off.
    A precomputation larger than the cache's entry limit
    (:func:`~translucent.cache.entry_limit`, set by the report) is not stored, and the log
    says so.

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    RadiosityState
    """
    from ...cache import content_hash

    scene, solid_notes = surface_scene(scene, mixed_profiles_from_solid)
    reason = applicability(applies_to, scene)
    if reason is not None and reason.code != NO_TRANSLUCENT_OBJECT:
        refuse_inapplicable(scene, reason, "radiosity does not apply")
    resolved = _resolve_knobs(scene, knobs)
    translucent = [i for i, o in enumerate(scene.objects) if profile_for(o.material) is not None]
    # an open translucent surface is a thin sheet of constant thickness, lit from both
    # sides (the rose petals of Sheng et al. 2014, Sect. 6.1)
    sheets = [i for i in translucent
              if not closed_surface(scene.objects[i].mesh.faces, scene.objects[i].mesh.vertices)]
    labels = {scene.objects[i].name: scene.objects[i].material.face_labels
              for i in translucent if isinstance(scene.objects[i].material, MixedProfiles)}
    geometry_knobs = KNOBS.keyed(resolved)
    key = content_hash("radiosity", FORMAT_VERSION, scene.geometry_key(), geometry_knobs,
                       [scene.objects[i].name for i in translucent], labels)

    def compute():
        log = StageLog()
        reason = needs_form_factors(scene)
        F = None
        with StageProgress(log, "radiosity precomputation",
                           stages=2 if reason else 3) as progress:
            with progress.stage("patches"):
                patches = build_patches(scene,
                                        triangles_per_patch=resolved["triangles_per_patch"],
                                        two_sided=sheets)
            for index in sheets:
                log.notes.setdefault("thin sheets", []).append(scene.objects[index].name)
            log.notes["patches"] = len(patches)
            log.notes["memory_estimate_bytes"] = check_precompute_memory(
                scene, patches, translucent, sheets, resolved)
            if reason is not None:
                log.skip(reason)
            else:
                with progress.stage("form_factors"):
                    F, facts = form_factors(scene, patches,
                                            rays_per_patch=resolved["rays_per_patch"],
                                            threshold=resolved["form_factor_threshold"],
                                            seed=resolved["seed"])
                log.notes["form_factors"] = facts
            with progress.stage("scattering"):
                geometry = scattering_geometry(
                    scene, patches, translucent, max_distance_mm=resolved["max_distance_mm"],
                    knobs=resolved, log=log, sheet_thickness_mm=resolved["sheet_thickness_mm"])
        log.notes["scattering_bytes"] = geometry.bytes
        log.notes["max_distance_mm"] = resolved["max_distance_mm"]
        if solid_notes:
            log.notes["solid medium"] = solid_notes
        return patches, F, geometry, log

    def size(stored):
        _, F, geometry, _ = stored
        return geometry.bytes + (0 if F is None else F.data.nbytes + F.indices.nbytes
                                 + F.indptr.nbytes)

    (patches, F, geometry, log), made = load_or_precompute(
        "radiosity", key, compute, what="the radiosity precomputation",
        log_of=lambda stored: stored[3],
        valid=lambda stored: isinstance(stored, tuple) and len(stored) == 4, nbytes=size)
    if not made and solid_notes:
        log.notes["solid medium"] = solid_notes
    return _state(scene, patches, F, geometry, resolved, log)


def _state(scene, patches, F, geometry, resolved, log) -> RadiosityState:
    """Build the state under a progress bar: it makes the scattering matrix S.

    S depends on the materials, which are edited, so it is not cached; on large objects it
    takes seconds.
    """
    with StageProgress(log, "radiosity materials", stages=1) as progress:
        with progress.stage("scattering_matrix"):
            return RadiosityState(scene, patches, F, geometry, resolved, log)


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx radiosity SCENE``."""
    parser.add_argument("--material", default=None,
                        help="for every translucent object: a measured material name "
                             "(Jensen et al. 2001 table, e.g. Marble) or a CSV profile table "
                             "(r in mm, then 1 or 3 reflection columns, optionally as many "
                             "transmission columns)")
    parser.add_argument("--component", default="both", choices=COMPONENTS,
                        help="bounce component of Sheng et al. 2014, Fig. 6 (default: both)")
    parser.add_argument("--semi-infinite", action="store_true",
                        help="the dipole as the paper uses it: --geometry half_space "
                        "--no-finite-object-energy")
    KNOBS.add_arguments(parser)


def approx(scene, args) -> Image:
    """Precompute (or load) and render ``scene`` for ``translucent approx radiosity``."""
    from pathlib import Path

    from ...materials import measured_medium
    from ...materials.profiles import TabulatedProfile

    started = time.perf_counter()
    material = None
    if args.material and Path(args.material).is_file():
        material = TabulatedProfile.from_file(args.material)
    elif args.material:
        material = measured_medium(args.material)
    if material is not None:
        targets = materials_of(scene, material)
        if not targets:
            raise InputError(f"no translucent object in scene {scene.name!r} to give it to",
                             field="material", value=args.material)
        for name in targets:
            scene = scene.with_material(name, material)
    knobs = KNOBS.from_arguments(args)
    if args.semi_infinite:
        knobs["finite_object_energy"] = False
        knobs["geometry"] = "half_space"
    state = precompute(scene, **knobs)
    image = state.render(component=args.component)
    for sentence in state.log.skipped:
        print(f"skipped: {sentence}")
    print(f"patches {len(state.patches)}, iterations {image.metadata['iterations']}, "
          f"max column sum of S {state.convergence['max_scattering_column_sum']:.4f}")
    return image.with_metadata(seconds=time.perf_counter() - started,
                               precompute_seconds=dict(state.log.seconds))
