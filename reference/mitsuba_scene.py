r"""Scene -> Mitsuba 3 scene dictionary for :func:`mitsuba.load_dict`.

Every part of a :class:`~translucent.scenes.Scene` becomes its Mitsuba counterpart:

=====================  ==========================================================
suite                  Mitsuba 3
=====================  ==========================================================
``Mesh``               a ``mi.Mesh`` built from the numpy positions, faces, normals
``Dipole``             ``dielectric`` boundary (``int_ior = eta``, ``ext_ior = 1``)
                       around a ``homogeneous`` interior medium; ``null`` boundary
                       when ``eta == 1`` (index-matched)
``Lambertian``         ``twosided`` ``diffuse``
``PointLight``         ``point`` (or a small ``sphere`` emitter, see below)
``SpotLight``          ``spot`` (or a shaded small ``sphere`` emitter, see below)
``DirectionalLight``   ``directional`` (or a small bright disk in an ``envmap``)
``RectangularArea..``  ``rectangle`` with an ``area`` emitter
``SphereAreaLight``    ``sphere`` with an ``area`` emitter
``ConstantEnv..``      ``constant``
``ImageEnvironment``   ``envmap`` (latitude-longitude, Mitsuba's own layout)
``Camera``             ``perspective`` (``fov_axis = "x"``), ``hdrfilm`` with a box
                       filter: the sensor of :mod:`translucent.scenes.raycast`, so that
                       pixel ``(row, col)`` averages the rays through its own square
                       and its centre is the G-buffer's ray (row 0 at the top)
=====================  ==========================================================

Medium coefficients are converted once, here: the materials are in mm^-1 and the
geometry in scene units, so each coefficient is multiplied by ``scene.mm_per_unit``
(mm per unit) to give units^-1; Mitsuba's ``scale`` carries that factor together with
the largest channel of :math:`\sigma_t` (its RGB inputs must lie in [0, 1]).

Other material types (analytic BRDFs, SubEdit media) are added by the modules that define
them through :func:`register_material_converter`, so that this module does not need to
know them.

A delta light (point, spot, directional) cannot reach a medium behind a ``dielectric``
boundary in ``volpath``: the shadow ray from a scattering point stops at the boundary and a
BSDF-sampled path never hits a light of zero size, so the medium renders black. When a
scene holds such a boundary and such a light, the default integrator is ``volpath_mnee``,
which connects the medium to the light through the boundary by manifold next-event
estimation (:mod:`translucent.reference.manifold_nee`), with specular manifold sampling
of the further refraction paths where the boundary is concave; the choice is stated in
:attr:`MitsubaConversion.substitutions`. With ``integrator="volpath"`` forced, those lights
are replaced by emitters of finite size and the same power instead
(:mod:`translucent.reference.delta_lights`), listed there and in the image metadata.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..backend import mitsuba
from ..errors import InputError, check_count
from ..materials import Dipole, Lambertian
from ..materials.brdf_pca import GLOSSY_GATHER, pca_model_basis, pca_model_gather
from ..materials.brdfs import AnalyticBRDF
from ..scenes import (
    ConstantEnvironment,
    DirectionalLight,
    ImageEnvironment,
    PointLight,
    RectangularAreaLight,
    Scene,
    SphereAreaLight,
    SpotLight,
)
from ..scenes.frame import Frame, rendering_frame
from ..scenes.mesh_shape import is_convex
from ..scenes.raycast import perspective_sensor_dict, to_mitsuba_mesh
from . import delta_lights

__all__ = [
    "INTEGRATORS",
    "DEFAULT_MAX_DEPTH",
    "ConversionContext",
    "MaterialParts",
    "MitsubaConversion",
    "convert_scene",
    "to_mitsuba_dict",
    "register_integrator_builder",
    "register_material_converter",
    "material_converter",
    "rgb",
]

#: The integrators a reference may use; ``path`` ignores media, so it is refused for a
#: scene that has one. ``volpath_mnee`` is ``volpath`` with manifold next-event
#: estimation through a dielectric boundary (:mod:`translucent.reference.manifold_nee`);
#: ``bssrdf_path`` renders translucent objects by a profile (:mod:`.bssrdf_path`).
INTEGRATORS = ("volpath", "volpathmis", "volpath_mnee", "path", "bssrdf_path")

#: The integrator of a PCA BRDF model carried by the Lambertian gather
#: (``brdf_pca_kK+lambertian_gatherN``, :mod:`.brdf_plugins`): chosen by that model's name.
GATHER_INTEGRATOR = "translucent_lambertian_gather"

#: The lights of zero size that a path cannot hit.
DELTA_LIGHTS = (PointLight, SpotLight, DirectionalLight)

#: -1 is unbounded: paths end by leaving the scene or by Russian roulette, without bias. A
#: finite depth darkens media of high albedo, whose paths scatter hundreds of times.
DEFAULT_MAX_DEPTH = -1

#: Russian roulette from this depth in scenes without a medium of high albedo.
DEFAULT_RR_DEPTH = 5

#: A medium whose single-scattering albedo exceeds this in some channel switches Russian
#: roulette off. Mitsuba keeps a path with probability min(throughput, 0.95): where the
#: albedo is near 1 the throughput stays near 1, every event kills 5 % of the paths and
#: multiplies the survivors' weight by 1/0.95, and walks of hundreds of events end as rare
#: huge samples. Measured (Marble sphere of radius 10 mm, constant environment, 48 x 48, 256
#: spp): relative standard error 0.83 in 5.9 s with roulette from depth 5, 0.12 in 28 s
#: without (10x the efficiency); Skin1 (albedo <= 0.96): 0.10 in 2.5 s with, 0.076 in 7 s
#: without (roulette 1.6x more efficient); Ketchup: equal error, 3x the time without.
RR_ALBEDO_THRESHOLD = 0.99

#: Why an RGB render of a chromatic medium uses ``volpathmis``. Measured on the index-matched
#: sphere of radius 10 mm under a point light, two seeds of 16 passes each (64 x 64, 128 spp;
#: Skin1 at 96 x 96, 256 spp), efficiency 1 / (median RSE^2 x seconds) R G B:
#: Skin1 volpath 39 / 154 / 133 and red sums of the two seeds 1.5 % apart (a firefly),
#: volpathmis 95 / 186 / 140 and 0.1 % apart, per channel 78 / 95 / 99; Chicken1 136 / 314
#: / 210 (red 1.2 % apart), 449 / 626 / 353, 235 / 294 / 268; Ketchup 33 / 228 / 174,
#: 253 / 337 / 267, 329 / 191 / 177; Apple 45 / 39 / 69, 50 / 44 / 68, 36 / 37 / 27
#: (docs/references.md).
RGB_ESTIMATOR_NOTE = ("RGB volpath of a chromatic medium is heavy-tailed; volpathmis "
                      "(spectral MIS) is not")

#: ``rr_depth`` that switches Russian roulette off (deeper than any path gets).
NO_RUSSIAN_ROULETTE = 1 << 30


@dataclass(frozen=True)
class ConversionContext:
    """What a material converter may need besides the material.

    Parameters
    ----------
    scene : Scene
        The whole scene (``mm_per_unit`` converts mm^-1 to units^-1).
    object_name : str
        The object the material belongs to (for error messages).
    channel : int or None
        For a per-channel monochrome render, the RGB channel (0, 1, 2) whose coefficients
        every channel should carry; None for an ordinary RGB render.
    brdf_basis : int
        K > 0: an analytic BRDF renders the K-term PCA of its edited term.
    frame_scale : float
        ``scene`` is in a rendering frame of this many units per unit of the user's scene
        (:mod:`translucent.scenes.frame`): what a converter says of lengths divides by it.
    """

    scene: Scene
    object_name: str
    channel: int | None = None
    #: K > 0: analytic BRDFs render their K-term PCA (the BRDF-editing method's model)
    brdf_basis: int = 0
    frame_scale: float = 1.0

    def per_channel(self, values) -> list[float]:
        """Return an RGB triple, or channel ``channel`` repeated three times."""
        values = np.broadcast_to(np.asarray(values, dtype=np.float64), (3,))
        if self.channel is not None:
            values = np.full(3, values[self.channel])
        return [float(v) for v in values]


@dataclass(frozen=True)
class MaterialParts:
    """A material as Mitsuba sees it on a closed mesh.

    Parameters
    ----------
    bsdf : dict
        A Mitsuba BSDF dictionary for the surface.
    interior : dict, optional
        A Mitsuba medium dictionary for the inside of the mesh.
    blocks_delta_lights : bool
        True when the surface is a specular boundary around a medium: delta lights cannot
        reach the medium through it and are replaced (module docstring).
    max_albedo : float
        Largest single-scattering albedo of the interior medium over channels (0 without
        one); above :data:`RR_ALBEDO_THRESHOLD` Russian roulette is switched off.
    chromatic : bool
        The interior's extinction differs between channels.
    description : str
        What the image header should say of the medium ("" for nothing), for example a
        heterogeneous medium's grid resolution.
    prefers_per_channel : bool
        The medium renders far more efficiently one channel at a time whatever its
        albedo (a chromatic heterogeneous medium, :mod:`.solid_medium`).
    """

    bsdf: dict
    interior: dict | None = None
    blocks_delta_lights: bool = False
    max_albedo: float = 0.0
    chromatic: bool = False
    description: str = ""
    prefers_per_channel: bool = False


MaterialConverter = Callable[[Any, ConversionContext], MaterialParts]
_CONVERTERS: dict[type, MaterialConverter] = {}


def register_material_converter(material_type: type, converter: MaterialConverter) -> None:
    """Teach the reference how to turn a material type into Mitsuba objects.

    Parameters
    ----------
    material_type : type
        The material class (exact type; subclasses are found through the MRO).
    converter : callable
        ``converter(material, context: ConversionContext) -> MaterialParts``.
    """
    if not callable(converter):
        raise InputError("must be callable", field="converter", value=converter)
    _CONVERTERS[material_type] = converter


#: Integrators of the suite's models that other modules of the reference build (the
#: Lambertian gather of :mod:`.brdf_plugins`), by name: ``builder(*arguments) -> dict``,
#: the Mitsuba integrator entry. Registered by those modules, as material converters are.
_INTEGRATOR_BUILDERS: dict[str, Callable[..., dict]] = {}


def register_integrator_builder(name: str, builder: Callable[..., dict]) -> None:
    """Teach the conversion how to build the integrator ``name`` of a model."""
    if not callable(builder):
        raise InputError("must be callable", field="builder", value=builder)
    _INTEGRATOR_BUILDERS[name] = builder


def _integrator_builder(name: str) -> Callable[..., dict]:
    if name not in _INTEGRATOR_BUILDERS:
        _import_reference_modules()
    return _INTEGRATOR_BUILDERS[name]


def _import_reference_modules() -> None:
    """Import every module of :mod:`translucent.reference`: each registers its converters.

    A scene loaded from a file may hold a material whose converter lives in a module
    nobody has imported yet (the analytic-BRDF plugin, for example).
    """
    import importlib
    import pkgutil

    package = __name__.rpartition(".")[0]
    for info in pkgutil.iter_modules(importlib.import_module(package).__path__):
        importlib.import_module(f"{package}.{info.name}")


def material_converter(material, *, object_name: str = "?") -> MaterialConverter:
    """Return the converter registered for ``type(material)`` or one of its base classes.

    Raises
    ------
    InputError
        When no converter is registered; names the object and lists the known types.
    """
    for attempt in range(2):
        for cls in type(material).__mro__:
            if cls in _CONVERTERS:
                return _CONVERTERS[cls]
        if attempt == 0:
            _import_reference_modules()
    known = ", ".join(sorted(cls.__name__ for cls in _CONVERTERS))
    raise InputError(f"no Mitsuba conversion for material type {type(material).__name__}; "
                     f"known: {known}", field=f"objects[{object_name!r}].material",
                     value=type(material).__name__)


def rgb(values) -> dict:
    """Return a Mitsuba ``rgb`` spectrum dictionary from a number or an RGB triple."""
    values = np.broadcast_to(np.asarray(values, dtype=np.float64), (3,))
    return {"type": "rgb", "value": [float(v) for v in values]}


def dipole_medium(material: Dipole, context: ConversionContext) -> dict:
    r"""Return the ``homogeneous`` medium of a :class:`~translucent.materials.Dipole` per unit.

    :math:`\sigma_t = \sigma_a + \sigma'_s / (1 - g)` and albedo :math:`\sigma_s/\sigma_t`
    (Jensen et al. 2001, Sect. 2: :math:`\sigma'_s = (1 - g)\sigma_s`), in mm^-1, times
    ``mm_per_unit``. Mitsuba multiplies the ``sigma_t`` RGB (which must lie in [0, 1]) by
    ``scale``, so the RGB holds :math:`\sigma_t / \max\sigma_t` and ``scale`` holds
    :math:`\max\sigma_t \cdot` ``mm_per_unit``.
    """
    sigma_t = np.asarray(context.per_channel(material.sigma_t))
    albedo = context.per_channel(material.albedo)
    peak = float(sigma_t.max())
    normalised = sigma_t / peak if peak > 0 else sigma_t
    phase = {"type": "isotropic"} if material.g == 0 else {"type": "hg", "g": material.g}
    return {"type": "homogeneous", "sigma_t": rgb(normalised), "albedo": rgb(albedo),
            "scale": peak * context.scene.mm_per_unit, "phase": phase}


def _convert_dipole(material: Dipole, context: ConversionContext) -> MaterialParts:
    medium = dipole_medium(material, context)
    max_albedo = max(context.per_channel(material.albedo))
    sigma_t = context.per_channel(material.sigma_t)
    chromatic = max(sigma_t) > min(sigma_t)
    if material.eta == 1.0:
        # index-matched: nothing refracts, delta lights reach the medium through a null surface
        return MaterialParts({"type": "null"}, medium, False, max_albedo, chromatic)
    boundary = {"type": "dielectric", "int_ior": material.eta, "ext_ior": 1.0}
    return MaterialParts(boundary, medium, True, max_albedo, chromatic)


def _convert_lambertian(material: Lambertian, context: ConversionContext) -> MaterialParts:
    # two-sided: open meshes (floors, walls) reflect on both sides as the fast methods assume
    diffuse = {"type": "diffuse", "reflectance": rgb(context.per_channel(material.albedo))}
    return MaterialParts({"type": "twosided", "bsdf": diffuse})


register_material_converter(Dipole, _convert_dipole)
register_material_converter(Lambertian, _convert_lambertian)


@dataclass
class MitsubaConversion:
    """The result of :func:`convert_scene`.

    Attributes
    ----------
    scene_dict : dict
        For :func:`mitsuba.load_dict`.
    integrator : str
        ``volpath``, ``volpathmis`` or ``path``.
    max_depth : int
        The integrator's maximum path depth (-1: unbounded).
    rr_depth : int
        Depth at which Russian roulette starts (:data:`NO_RUSSIAN_ROULETTE`: never).
    has_media : bool
        Whether any object has an interior medium.
    per_channel_recommended : bool
        A chromatic medium of albedo above :data:`RR_ALBEDO_THRESHOLD` (its long walks),
        one that prefers it (a chromatic heterogeneous medium), or any chromatic medium
        rendered with ``volpath_mnee`` (a connection at every vertex): it converges much faster
        rendered one channel at a time (:func:`translucent.reference.render`).
    substitutions : list of str
        One sentence for each light replaced by an emitter of finite size.
    media : dict of str to str
        Object name -> what its converter says of its medium (heterogeneous ones).
    shape_props : dict of str to dict
        Shape key of ``scene_dict`` -> the plugins attached to that mesh (``bsdf``,
        ``interior``), as dictionaries: what an exported XML file writes beside the mesh.
    frame : Frame, optional
        The frame ``scene_dict`` is in (:func:`~translucent.scenes.frame.rendering_frame`):
        its lengths are ``(x - frame.origin) * frame.scale`` of the scene's.
    """

    scene_dict: dict
    integrator: str
    max_depth: int
    rr_depth: int
    has_media: bool
    per_channel_recommended: bool = False
    substitutions: list[str] = field(default_factory=list)
    media: dict[str, str] = field(default_factory=dict)
    shape_props: dict[str, dict] = field(default_factory=dict)
    profile: dict = field(default_factory=dict)
    frame: Frame | None = None


def _shape_key(name: str, used: set) -> str:
    key = "object_" + re.sub(r"[^A-Za-z0-9_]", "_", name)
    while key in used:
        key += "_"
    used.add(key)
    return key


def _spot_transform(light: SpotLight):
    mi = mitsuba()
    up = delta_lights.any_perpendicular(light.direction)
    return mi.ScalarTransform4f().look_at(origin=light.position.tolist(),
                                          target=(light.position + light.direction).tolist(),
                                          up=up.tolist())


def _rectangle_transform(light: RectangularAreaLight):
    mi = mitsuba()
    matrix = np.eye(4)
    matrix[:3, 0] = light.u_axis
    matrix[:3, 1] = light.v_axis
    matrix[:3, 2] = light.normal
    matrix[:3, 3] = light.center
    return mi.ScalarTransform4f(matrix.tolist())


def _light_entries(light, index: int, substitute: bool, scene: Scene, size: float,
                   environment: delta_lights.EnvironmentParts, notes: list[str],
                   frame_scale: float = 1.0) -> dict:
    """Mitsuba entries for one light (environments are collected into ``environment``).

    ``scene`` is in a rendering frame of ``frame_scale`` units per user unit: the notes give
    lengths in the user's.
    """
    name = f"light_{index}"
    if isinstance(light, PointLight):
        if substitute:
            entries, note = delta_lights.point_light_equivalent(light, scene, size,
                                                                  frame_scale)
            notes.append(f"{name} ({note})")
            return {f"{name}_{k}": v for k, v in entries.items()}
        return {name: {"type": "point", "position": light.position.tolist(),
                       "intensity": rgb(light.intensity)}}
    if isinstance(light, SpotLight):
        if substitute:
            entries, note = delta_lights.spot_light_equivalent(light, scene, size,
                                                                 frame_scale)
            notes.append(f"{name} ({note})")
            shade_mesh, shade_bsdf = entries.pop("shade")
            entries["shade"] = to_mitsuba_mesh(shade_mesh, f"{name}_shade",
                                               props={"bsdf": shade_bsdf})
            return {f"{name}_{k}": v for k, v in entries.items()}
        return {name: {"type": "spot", "to_world": _spot_transform(light),
                       "intensity": rgb(light.intensity), "cutoff_angle": light.cutoff_angle,
                       "beam_width": light.beam_width}}
    if isinstance(light, DirectionalLight):
        if substitute:
            notes.append(f"{name} ({environment.add_sun(light, size)})")
            return {}
        return {name: {"type": "directional", "direction": light.direction.tolist(),
                       "irradiance": rgb(light.irradiance)}}
    if isinstance(light, RectangularAreaLight):
        return {name: {"type": "rectangle", "to_world": _rectangle_transform(light),
                       "emitter": {"type": "area", "radiance": rgb(light.radiance)}}}
    if isinstance(light, SphereAreaLight):
        return {name: {"type": "sphere", "center": light.center.tolist(),
                       "radius": light.radius,
                       "emitter": {"type": "area", "radiance": rgb(light.radiance)}}}
    if isinstance(light, ConstantEnvironment):
        environment.add_constant(light.radiance)
        return {}
    if isinstance(light, ImageEnvironment):
        environment.add_image(light)
        return {}
    raise InputError(f"unknown light type {type(light).__name__}", file=scene.source,
                     field=f"lights[{index}]", value=type(light).__name__)


def _brdf_model(scene: Scene, integrator, profile, brdf_basis: int) -> dict:
    """Check a PCA BRDF model asked of ``scene``; return what the image header says of it."""
    gather = pca_model_gather(profile) if brdf_basis else None
    if integrator == GATHER_INTEGRATOR and gather is None:
        raise InputError("renders a model brdf_pca_kK+lambertian_gatherN only",
                         file=scene.source, field="integrator", value=integrator)
    if not brdf_basis:
        return {}
    if integrator not in (None, "path" if gather is None else GATHER_INTEGRATOR):
        raise InputError(f"the PCA BRDF model {profile} renders with the path integrator "
                         "(or the Lambertian gather its name asks for)",
                         file=scene.source, field="integrator", value=integrator)
    objects = {obj.name: f"{obj.material.model} gamma {obj.material.gamma:g}"
               for obj in scene.objects if isinstance(obj.material, AnalyticBRDF)}
    if not objects:
        raise InputError(f"the PCA BRDF model {profile} needs an analytic BRDF; the scene "
                         "has none", file=scene.source, field="profile", value=profile)
    return {"name": profile, "objects": objects,
            "brdf": f"edited term by its {brdf_basis}-term PCA (Nguyen et al. 2010, Eq. 10)",
            **({} if gather is None else {"transport": _gather_text(*gather)})}


def _gather_text(transport: str, bounces: int) -> str:
    if transport == GLOSSY_GATHER:
        return (f"first surface by its BRDF, the next {bounces + 1} diffusely but for the "
                "second's direct light, by its BRDF (gather_reflection 'brdf')")
    return (f"first surface by its BRDF, the next {bounces + 1} diffusely (Lambertian gather "
            "samples, Sect. 5.2)")


def convert_scene(scene: Scene, *, integrator: str | None = None, max_depth: int | None = None,
                  spp: int = 64, channel: int | None = None,
                  substitute_delta_lights: bool | None = None,
                  delta_light_size: float = delta_lights.DEFAULT_SIZE,
                  rr_depth: int | None = None, profile: str | None = None
                  ) -> MitsubaConversion:
    """Convert ``scene`` to a Mitsuba scene dictionary and say what was substituted.

    Parameters
    ----------
    scene : Scene
    integrator : {"volpath", "volpathmis", "volpath_mnee", "path", "bssrdf_path"}, optional
        Default: ``volpath_mnee`` when a delta light meets a dielectric boundary around a
        medium, else ``volpathmis`` when a medium is chromatic (:data:`RGB_ESTIMATOR_NOTE`),
        ``volpath`` when any object has a medium, ``path`` otherwise.
        ``bssrdf_path`` renders each translucent object by ``profile`` instead of its medium.
    max_depth : int, optional
        Longest path (-1 unbounded, the default: :data:`DEFAULT_MAX_DEPTH`).
    spp : int
        Samples per pixel of the sampler (``mitsuba.render`` may override it).
    channel : {0, 1, 2}, optional
        Give every channel of every material the coefficients of this RGB channel (a
        monochrome render of one channel; see :func:`translucent.reference.render`).
    substitute_delta_lights : bool, optional
        Replace point, spot and directional lights by emitters of finite size. Default:
        when some material blocks delta lights (a dielectric boundary around a medium) and
        the integrator is not ``volpath_mnee``, which reaches them.
    delta_light_size : float
        Size of those emitters: their radius as a fraction of the distance from the light
        to the nearest surface, the sine of a sun disk's angular radius
        (:data:`~translucent.reference.delta_lights.DEFAULT_SIZE`).
    rr_depth : int, optional
        Depth at which Russian roulette starts. Default :data:`DEFAULT_RR_DEPTH`, or none
        at all (:data:`NO_RUSSIAN_ROULETTE`) when a medium's albedo exceeds
        :data:`RR_ALBEDO_THRESHOLD`.
    profile : str, optional
        With ``bssrdf_path`` (and only with it): the profile's name
        (:data:`~translucent.materials.profiles.PROFILE_NAMES`). Or ``brdf_pca_kK``
        (:func:`~translucent.materials.brdf_pca.pca_model_name`), with ``path``: every
        analytic BRDF renders the K-term PCA of its edited term, the BRDF-editing method's
        model (:mod:`.brdf_plugins`); ``brdf_pca_kK+lambertian_gatherN`` renders it by the
        method's Lambertian-gather transport with N bounces
        (:func:`~.brdf_plugins.gather_integrator`) whatever ``max_depth``.

    Returns
    -------
    MitsubaConversion

    Raises
    ------
    InputError
        Unknown integrator or material type, ``path`` for a scene with media, a bad
        ``channel``, ``spp`` or ``max_depth``.
    """
    if integrator is not None and integrator not in (*INTEGRATORS, GATHER_INTEGRATOR):
        raise InputError(f"unknown integrator; valid: {', '.join(INTEGRATORS)}",
                         field="integrator", value=integrator)
    if channel is not None and (not isinstance(channel, (int, np.integer))
                                or isinstance(channel, bool) or channel not in (0, 1, 2)):
        raise InputError("must be 0, 1, 2 (R, G, B) or None", field="channel", value=channel)
    check_count(spp, "spp")
    from .bssrdf_path import bssrdf_conversion

    # float32 ray offsets must not depend on the user's unit (scenes/frame.py)
    frame = rendering_frame(scene)
    scene = frame.apply(scene)

    brdf_basis = pca_model_basis(profile) or 0
    brdf_model = _brdf_model(scene, integrator, profile, brdf_basis)
    bssrdf = None if brdf_basis else bssrdf_conversion(scene, integrator, profile, channel)
    if max_depth is None:
        max_depth = DEFAULT_MAX_DEPTH
    if max_depth != -1:
        check_count(max_depth, "max_depth", 1, why=" (or -1: unbounded)")
    if not 0 < delta_light_size < 0.5:
        raise InputError("must be in (0, 0.5)", field="delta_light_size",
                         value=delta_light_size)

    shapes: dict[str, Any] = {}
    used: set = set()
    has_media = False
    blocks_delta = False
    max_albedo = 0.0
    per_channel_recommended = False
    chromatic_media = False
    media: dict[str, str] = {}
    blocking: list[int] = []
    shape_props: dict[str, dict] = {}
    for index, obj in enumerate(scene.objects):
        context = ConversionContext(scene, obj.name, channel, brdf_basis, frame.scale)
        parts = material_converter(obj.material, object_name=obj.name)(obj.material, context)
        if bssrdf is not None:  # a translucent object's boundary alone: the profile is inside
            parts = bssrdf.surface_parts(index, obj, parts)
        has_media |= parts.interior is not None
        blocks_delta |= parts.blocks_delta_lights
        if parts.blocks_delta_lights:
            blocking.append(index)
        max_albedo = max(max_albedo, parts.max_albedo)
        # a chromatic medium's long walks (or one that prefers it) converge much faster
        per_channel_recommended |= parts.chromatic and (
            parts.max_albedo > RR_ALBEDO_THRESHOLD or parts.prefers_per_channel)
        chromatic_media |= parts.chromatic
        if parts.description:
            media[obj.name] = parts.description
        key = _shape_key(obj.name, used)
        props = {"bsdf": parts.bsdf}
        if parts.interior is not None:
            props["interior"] = parts.interior
        shapes[key] = to_mitsuba_mesh(obj.mesh, key, props=props)
        shape_props[key] = props

    notes: list[str] = []
    has_delta_lights = any(isinstance(light, DELTA_LIGHTS) for light in scene.lights)
    if integrator is None:
        if blocks_delta and has_delta_lights:
            integrator = "volpath_mnee"
            notes.append("delta lights reached through the dielectric boundary by manifold "
                         "next-event estimation (volpath_mnee), not replaced")
        elif chromatic_media:
            # volpath samples distances with one channel's extinction and weights the
            # others by ratios of transmittances: a heavy tail (RGB_ESTIMATOR_NOTE)
            integrator = "volpathmis"
        else:
            integrator = "volpath" if has_media else "path"
    if integrator == "path" and has_media:
        raise InputError("the path integrator ignores media; use volpath or volpathmis",
                         file=scene.source, field="integrator", value=integrator)
    if rr_depth is None:
        rr_depth = NO_RUSSIAN_ROULETTE if max_albedo > RR_ALBEDO_THRESHOLD else DEFAULT_RR_DEPTH
    check_count(rr_depth, "rr_depth", 1)
    if substitute_delta_lights is None:
        substitute = blocks_delta and integrator != "volpath_mnee"
    else:
        substitute = bool(substitute_delta_lights)
    seeded_solutions = False
    if integrator == "volpath_mnee":
        from .manifold_nee import check_closed_boundaries, register

        # every medium vertex makes a connection weighted by the path's throughput, whose
        # other channels carry ratios of transmittances (distances are sampled with one
        # channel's extinction): Skin1 at eta 1.3, red's variance a sample is 41x that of a
        # red-only render, at 2.7x the time for all three (docs/references.md)
        per_channel_recommended |= chromatic_media
        check_closed_boundaries(scene, blocking)
        register()
        # a concave boundary often refracts one light into one point along several paths,
        # of which the solve from the straight line finds one: the others by specular
        # manifold sampling (convex ones have them only past a lens caustic; off there,
        # docs/references.md gives what that leaves out)
        concave = [scene.objects[i].name for i in blocking
                   if not is_convex(scene.objects[i].mesh.vertices, scene.objects[i].mesh.faces)]
        if concave:
            seeded_solutions = True
            notes.append("the refraction paths the solve from the straight line misses on "
                         f"the concave boundary of {', '.join(repr(n) for n in concave)} "
                         "are found by specular manifold sampling (seeded_solutions)")
    integrator_props = {} if bssrdf is None else bssrdf.integrator_properties(list(shapes))
    environment = delta_lights.EnvironmentParts()
    emitters: dict[str, Any] = {}
    for index, light in enumerate(scene.lights):
        emitters.update(_light_entries(light, index, substitute, scene, delta_light_size,
                                       environment, notes, frame.scale))
    env_entry = environment.mitsuba_entry()
    if env_entry is not None:
        emitters["environment"] = env_entry

    integrator_entry = {"type": integrator, "max_depth": int(max_depth),
                        "rr_depth": int(rr_depth),
                        **({"seeded_solutions": True} if seeded_solutions else {}),
                        **integrator_props}
    if pca_model_gather(profile) is not None:
        integrator_entry = _integrator_builder(GATHER_INTEGRATOR)(*pca_model_gather(profile))
        integrator, max_depth = integrator_entry["type"], integrator_entry["max_depth"]
    scene_dict = {
        "type": "scene",
        "integrator": integrator_entry,
        # the sensor of the G-buffers in translucent.scenes.raycast: same pixels
        "sensor": perspective_sensor_dict(scene.camera, spp=spp, frame_scale=frame.scale),
        **shapes,
        **emitters,
    }
    return MitsubaConversion(scene_dict, integrator, int(max_depth), int(rr_depth), has_media,
                             per_channel_recommended, notes, media, shape_props,
                             brdf_model if bssrdf is None else bssrdf.description(), frame)


def to_mitsuba_dict(scene: Scene, *, integrator: str | None = None,
                    max_depth: int | None = None, spp: int = 64, **options) -> dict:
    """Return the Mitsuba scene dictionary of ``scene`` (see :func:`convert_scene` for the options).

    Returns
    -------
    dict
        Ready for ``mitsuba.load_dict``; meshes are ``mi.Mesh`` objects.
    """
    return convert_scene(scene, integrator=integrator, max_depth=max_depth, spp=spp,
                         **options).scene_dict
