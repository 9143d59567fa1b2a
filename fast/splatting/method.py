"""The fast-method contract of splatting: applicability, precompute, the command line."""

from __future__ import annotations

import time

from ...image import Image
from ...scenes.scene import DirectionalLight, PointLight, SpotLight
from ..base import (
    NO_LIGHT,
    NO_TRANSLUCENT_OBJECT,
    UNSUPPORTED_LIGHT,
    Refusal,
    StageLog,
    applicability,
    refuse_inapplicable,
)
from ..indirect_light import precompute_indirect_light
from ..object_geometry import object_geometries
from .emitters import AREA_LIGHTS
from .knobs import KNOBS
from .state import SplattingState, translucent_objects

#: The lights the method splats (area lights become point emitters).
_LIGHTS = (PointLight, SpotLight, DirectionalLight, *AREA_LIGHTS)

#: How an InputError for a scene the method cannot render begins (the reason follows).
REFUSAL = "the splatting method cannot render this scene"


def applies_to(scene) -> Refusal | None:
    """None when the method renders ``scene``; otherwise why not.

    It needs a translucent object (Dipole, SubEdit or solid material) and point, spot,
    directional, rectangular or spherical lights (Chen et al. 2012 splat point and
    directional lights; the others become point emitters,
    :mod:`~translucent.fast.splatting.emitters`). Environments are refused.
    """
    if not translucent_objects(scene):
        return Refusal(NO_TRANSLUCENT_OBJECT,
                       "no translucent object (Dipole, SubEdit or solid material) in the scene")
    others = sorted({type(light).__name__ for light in scene.lights
                     if not isinstance(light, _LIGHTS)})
    if others:
        return Refusal(UNSUPPORTED_LIGHT, "the method handles point, spot, directional and "
                       f"area lights only; the scene has {', '.join(others)}")
    if not scene.lights:
        return Refusal(NO_LIGHT, "the scene has no light")
    return None


def scored_objects(scene) -> list[str]:
    """Return the objects the method renders, and is scored on: the translucent ones.

    Each is splatted from its own buffers; other objects stay black in its image.
    """
    return [scene.objects[i].name for i in translucent_objects(scene)]


def _check_knobs(knobs: dict) -> dict:
    return KNOBS.resolve(knobs)


def _check_scene(scene) -> None:
    refuse_inapplicable(scene, applicability(applies_to, scene), REFUSAL)


def precompute(scene, **knobs) -> SplattingState:
    """Validate the scene and knobs; precompute the indirect light's gather where it bounces.

    The method itself needs no precomputation (Chen et al. 2012): every buffer is rebuilt
    each frame from the current mesh, so a deforming mesh costs nothing extra and nothing
    can go stale. The only tables (the SubEdit conversion of a dipole, Eq. 14's lookup
    table and the mean profile's energy of the profile upsampling) depend on the material
    alone and are built on first use. Where the scene has Lambertian surfaces and the knob
    ``indirect_light`` is ``"diffuse"`` (the default), the light they bounce is gathered
    at each translucent triangle (:mod:`translucent.fast.indirect_light`, cached on disk):
    that part is for the mesh given here, and so is the geometry correction of a
    homogeneous object's profile (knob ``geometry``, :mod:`translucent.fast.object_geometry`).
    """
    _check_scene(scene)
    resolved = _check_knobs(knobs)
    log = StageLog()
    started = time.perf_counter()
    receivers = {scene.objects[i].name: (scene.objects[i].mesh.face_centroids,
                                         scene.objects[i].mesh.face_normals)
                 for i in translucent_objects(scene)}
    indirect = precompute_indirect_light(scene, receivers, resolved, log)
    log.seconds["indirect light"] = time.perf_counter() - started
    geometry = object_geometries(scene, list(receivers), resolved, log)
    return SplattingState(scene, resolved, log, check_scene=_check_scene, indirect=indirect,
                          geometry=geometry)


def add_approx_arguments(parser) -> None:
    """Options of ``translucent approx splatting SCENE``."""
    parser.add_argument("--material", default=None,
                        help="replace the translucent material: a built-in SubEdit name "
                             "(checker, veined_marble, wax_gradient) or a SubEdit .npz file")
    KNOBS.add_arguments(parser)


def approx(scene, args) -> Image:
    """Render ``scene`` with the options parsed by :func:`add_approx_arguments`."""
    from ...materials.subedit import BUILTIN_SUBEDIT, builtin_subedit, load_subedit

    knobs = KNOBS.from_arguments(args)
    material = None
    if args.material:
        material = builtin_subedit(args.material) if args.material in BUILTIN_SUBEDIT \
            else load_subedit(args.material)
    return precompute(scene, **knobs).render(material=material)
