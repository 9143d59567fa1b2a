"""The PRT method's entry points: applicability, precomputation, the command line."""

from __future__ import annotations

import time

import numpy as np

from ...errors import InputError
from ...image import Image
from ...materials import Dipole, measured_medium
from ..base import (
    NO_LIGHT,
    NO_TRANSLUCENT_OBJECT,
    Refusal,
    StageLog,
    applicability,
    load_or_precompute,
    refuse_inapplicable,
)
from ..indirect_light import precompute_indirect_light
from ..object_geometry import object_geometries
from .exit_vertices import refined_scene
from .knobs import KNOBS, basis_and_facts, check_knobs
from .profile_basis import basis_error_notes
from .state import PRTState
from .transfer import ObjectTransfer, precompute_object, spatial_decision, transfer_key


def _translucent_objects(scene) -> list[int]:
    return [i for i, item in enumerate(scene.objects) if isinstance(item.material, Dipole)]


def _other_objects_in_view(scene) -> list[str]:
    """Names of the objects that are not homogeneous translucent and that the camera sees."""
    translucent = set(_translucent_objects(scene))
    if len(translucent) == len(scene.objects):
        return []
    from ...scenes.gbuffer import gbuffer

    seen = set(np.unique(gbuffer(scene).object_id).tolist()) - {-1}
    return [scene.objects[i].name for i in sorted(seen - translucent)]


def applies_to(scene) -> Refusal | None:
    """None when the method renders ``scene``; otherwise why not.

    It needs a homogeneous translucent object (a :class:`~translucent.materials.Dipole`
    material) and at least one light. The method (Wang et al. 2008) computes the multiple
    scattering of homogeneous translucent objects only: other objects cast shadows through
    the ray queries but are left black, and are not scored (:func:`scored_objects`); the
    light they would bounce onto the translucent objects is missing, and counts in the
    method's error there.
    """
    if not _translucent_objects(scene):
        return Refusal(NO_TRANSLUCENT_OBJECT,
                       "no homogeneous translucent object (Dipole material) in the scene")
    if not scene.lights:
        return Refusal(NO_LIGHT, "the scene has no light")
    return None


def scored_objects(scene) -> list[str]:
    """Return the objects the method renders, and is scored on: the homogeneous translucent."""
    return [scene.objects[i].name for i in _translucent_objects(scene)]


def precompute(scene, **knobs) -> PRTState:
    """Precompute the transfer of every homogeneous translucent object (Sect. 3.2).

    Cached on disk (namespace ``prt``) by the object's geometry, ``mm_per_unit`` and the
    knobs (not the lights, not the material): a second call with the same inputs loads it.
    The knob ``profile`` picks the family the PCA basis expands (Sect. 3.1; the classical
    dipole's by default, shipped); another profile's basis is built on first use and
    cached too. The basis's relative errors on the measured media and on the scene's
    materials go to ``state.log.notes["profile basis"]``
    (:func:`~translucent.fast.prt.profile_basis.basis_error_notes`).

    Parameters
    ----------
    scene : Scene
    **knobs
        See :data:`DEFAULT_KNOBS`.

    Returns
    -------
    PRTState

    Raises
    ------
    InputError
        The method does not apply (see :func:`applies_to`) or a knob is invalid.
    """
    refuse_inapplicable(scene, applicability(applies_to, scene),
                        "the prt method cannot render this scene")
    knobs = check_knobs(knobs)
    log = StageLog()
    transfers = []
    start = time.perf_counter()
    basis, facts = basis_and_facts(knobs)
    log.notes["profile basis"] = {**basis_error_notes(basis, knobs["profile"], {
        scene.objects[i].name: scene.objects[i].material for i in _translucent_objects(scene)}),
        **facts}
    others = _other_objects_in_view(scene)
    # the geometry correction is made on the objects' own meshes, as the model reference's
    unrefined = scene
    scene = refined_scene(scene, _translucent_objects(scene), knobs, log)
    if others:
        kinds = ", ".join(f"'{name}' ({type(scene.object(name).material).__name__})"
                          for name in others)
        log.skip(f"objects left black (the method renders homogeneous translucent objects "
                 f"only; they are not scored): {kinds}")
    for index in _translucent_objects(scene):
        item = scene.objects[index]
        key = transfer_key(item, scene.mm_per_unit, knobs)
        transfer, made = load_or_precompute(
            "prt", key, lambda item=item: precompute_object(item, scene.mm_per_unit, knobs, log),
            what=f"the PRT transfer of {item.name!r}", log_of=lambda _: log,
            valid=lambda value: isinstance(value, ObjectTransfer), part=item.name)
        if not made:
            spatial_decision(item, knobs, log)
        transfers.append(transfer)
    started = time.perf_counter()
    indirect = precompute_indirect_light(
        scene, {t.name: (t.samples.positions, t.samples.normals) for t in transfers}, knobs, log)
    log.seconds["indirect light"] = time.perf_counter() - started
    samples = {t.name: t.samples for t in transfers}
    geometry = {name: (item, item.weights(samples[name].positions, samples[name].normals),
                       item.weights(scene.object(name).mesh.vertices,
                                    scene.object(name).mesh.normals))
                for name, item in object_geometries(unrefined, list(samples), knobs,
                                                    log).items()}
    hidden = [o.name for o in scene.objects
              if not isinstance(o.material, Dipole) and o.name not in others]
    if hidden:
        log.skip(f"objects {', '.join(hidden)} are not homogeneous translucent and outside "
                 "the camera's view: they only cast shadows"
                 + (" and bounce light" if indirect is not None else ""))
    log.seconds["precompute"] = time.perf_counter() - start
    return PRTState(scene, knobs, transfers, log, indirect, geometry)



# ====================================================================== command line


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx prt SCENE``."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--material", default=None,
                       help="a measured medium of Jensen et al. 2001 (Marble, Skin1, ...)")
    group.add_argument("--sigma-a", type=float, nargs=3, metavar=("R", "G", "B"),
                       help="absorption coefficient, mm^-1 (with --sigma-s-prime)")
    parser.add_argument("--sigma-s-prime", type=float, nargs=3, metavar=("R", "G", "B"),
                        help="reduced scattering coefficient, mm^-1 (with --sigma-a)")
    parser.add_argument("--eta", type=float, default=None,
                        help="relative index of refraction (default 1.3, or the medium's)")
    KNOBS.add_arguments(parser)


def material_from_arguments(args) -> Dipole | None:
    """Return the Dipole the options ask for (None: keep the scene's).

    Raises
    ------
    InputError
        ``--sigma-a`` without ``--sigma-s-prime`` (or the reverse), ``--sigma-s-prime``
        with ``--material``, bad coefficients.
    """
    if args.material and args.sigma_s_prime is not None:
        raise InputError("give --material or --sigma-a/--sigma-s-prime, not both",
                         field="sigma_s_prime", value=args.sigma_s_prime)
    if args.material:
        medium = measured_medium(args.material)
        if args.eta is None:
            return medium
        return Dipole(medium.sigma_a, medium.sigma_s_prime, args.eta, medium.g, medium.name)
    if (args.sigma_a is None) != (args.sigma_s_prime is None):
        raise InputError("give both --sigma-a and --sigma-s-prime (mm^-1, R G B)",
                         field="sigma_s_prime" if args.sigma_a else "sigma_a", value=None)
    if args.sigma_a is not None:
        return Dipole(args.sigma_a, args.sigma_s_prime, 1.3 if args.eta is None else args.eta)
    if args.eta is not None:
        raise InputError("--eta needs --material or --sigma-a/--sigma-s-prime", field="eta",
                         value=args.eta)
    return None


def approx(scene, args) -> Image:
    """Render ``scene`` with the options parsed by :func:`add_approx_arguments`."""
    material = material_from_arguments(args)
    knobs = KNOBS.from_arguments(args)
    state = precompute(scene, **knobs)
    image = state.render(material=material)
    for sentence in image.metadata.get("skipped", []):
        print(f"skipped: {sentence}")
    return image.with_metadata(seconds_precompute=state.log.seconds.get("precompute"))
