"""Scenes: applicability, rasterised views and the precomputed state."""

from __future__ import annotations

import hashlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ...image import Image
from ...materials.homogeneous import Dipole
from ...materials.solid import SolidMedium
from ...materials.subedit import SubEditProfiles
from ...scenes.frame import translucent_object_indices
from ...scenes.scene import DirectionalLight
from ..base import StageLog
from ..indirect_light import IndirectLight, reflectance_of
from ..knobs import DEFAULT_PROFILE, radial_profile
from ..solid_inputs import subedit_from_solid
from .buffers import CameraModel, SurfaceBuffer
from .emitters import PointEmitter, point_emitters
from .frame import (
    LightView,
    as_subedit,
    exitant_radiance_of,
    gather_frame,
    light_view,
    splat_frame,
)

#: Widest irradiance-buffer cone for a point light (degrees): a light inside the object's
#: bounding sphere sees only this cone of it.
MAX_LIGHT_FOV = 160.0
#: Margin of the irradiance buffer around the bounding sphere (no hit falls on its edge).
VIEW_MARGIN = 1.02


#: The indices of the objects the method renders: Dipole, SubEdit or solid.
translucent_objects = translucent_object_indices



def _bounding_sphere(mesh) -> tuple[np.ndarray, float]:
    """Return the centre of a mesh's bounding box and the radius about it that holds it."""
    centre = 0.5 * (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0))
    return centre, float(np.max(np.linalg.norm(mesh.vertices - centre, axis=1)))


def _surface_buffer(gbuffer_view, object_index: int, uv_values, footprint) -> SurfaceBuffer:
    valid = gbuffer_view.hit & (gbuffer_view.object_id == object_index)
    uv = gbuffer_view.interpolate(object_index, uv_values) if uv_values is not None else \
        np.zeros(valid.shape + (2,))
    depth = np.where(valid, gbuffer_view.depth, 0.0)
    return SurfaceBuffer(gbuffer_view.position, gbuffer_view.normal, uv, depth, valid,
                         np.where(valid, footprint, 0.0))


def _perspective_footprint(gbuffer_view) -> np.ndarray:
    """Pixel cross-section side at the hit: d (2 tan(fov/2) / W) cos^1.5 of the off-axis angle."""
    camera = gbuffer_view.camera
    pixel = 2.0 * math.tan(math.radians(camera.fov) / 2.0) / camera.width
    cosine = np.clip(-gbuffer_view.view_direction @ camera.forward, 0.0, 1.0)
    depth = np.where(gbuffer_view.hit, gbuffer_view.depth, 0.0)
    return depth * pixel * cosine**1.5


@dataclass(frozen=True, eq=False)
class RasterView:
    r"""What :func:`rasterize_view` saw: per pixel the first triangle of the scene.

    ``triangle`` (H, W) indexes the scene's faces, objects in order (-1: nothing);
    ``barycentric`` (H, W, 2) weighs its second and third vertices; ``depth`` (H, W) is
    the distance along the ray from the eye (perspective) or image plane (orthographic);
    ``footprint`` (H, W) the side of the pixel's cross-section at that depth, scene units.
    """

    triangle: np.ndarray
    barycentric: np.ndarray
    depth: np.ndarray
    footprint: np.ndarray
    face_offsets: np.ndarray

    def surface(self, scene, object_index: int) -> SurfaceBuffer:
        """Return one object's :class:`SurfaceBuffer` (invalid where another is in front)."""
        from .buffer_kernels import interpolate_surface

        mesh = scene.objects[object_index].mesh
        uv = mesh.uv if mesh.uv is not None else np.zeros((0, 2))
        valid, position, normal, uv, depth, footprint = interpolate_surface(
            self.triangle, self.barycentric, self.depth, self.footprint,
            int(self.face_offsets[object_index]), int(self.face_offsets[object_index + 1]),
            mesh.vertices, mesh.faces, mesh.normals, np.asarray(uv, dtype=np.float64))
        return SurfaceBuffer(position, normal, uv, depth, valid, footprint)


def rasterize_view(scene, *, camera=None, direction=None, size=None, centre=None,
                   extent=None) -> RasterView:
    """Render the G-buffer of a perspective ``camera`` or an orthographic light view.

    Buffer generation of Chen et al. 2012 (Sect. 4) by rasterisation, as the paper does:
    :func:`.buffer_kernels.rasterize` tests each pixel's own ray against the triangles
    of its projected bounding box, so the buffers are those of the ray queries of
    :func:`translucent.scenes.gbuffer.gbuffer` (perspective) and
    :func:`~translucent.scenes.gbuffer.gbuffer_orthographic` (``direction``, a square of
    ``size`` pixels and half-width ``extent`` around ``centre``, scene units) up to
    rounding, in milliseconds instead of seconds. The perspective footprint is
    :func:`.buffer_kernels.perspective_footprint`, computed at hit pixels only.
    """
    # the ray-cast G-buffers' own image frames, so that both kinds of buffer agree
    from ...scenes.gbuffer import camera_frame, default_up
    from ...scenes.raycast import NEAR_CLIP
    from .buffer_kernels import perspective_footprint, rasterize

    meshes = [item.mesh for item in scene.objects]
    vertex_offsets = np.cumsum([0] + [len(m.vertices) for m in meshes])
    face_offsets = np.cumsum([0] + [len(m.faces) for m in meshes])
    vertices = np.concatenate([m.vertices for m in meshes])
    faces = np.concatenate([m.faces + offset
                            for m, offset in zip(meshes, vertex_offsets[:-1], strict=True)])
    if camera is not None:
        forward, left, up = camera_frame(camera)
        tan_x = math.tan(math.radians(camera.fov) / 2.0)
        tan_y = tan_x * camera.height / camera.width
        width, height, eye, orthographic = camera.width, camera.height, camera.origin, False
    else:
        forward = np.asarray(direction, dtype=np.float64)
        forward = forward / np.linalg.norm(forward)
        left = np.cross(default_up(forward), forward)
        left /= np.linalg.norm(left)
        up = np.cross(forward, left)
        tan_x = tan_y = float(extent)
        width = height = int(size)
        lower, upper = vertices.min(axis=0), vertices.max(axis=0)
        behind = float(np.max(np.linalg.norm(vertices - centre, axis=1))) + \
            float(np.linalg.norm(centre - np.clip(centre, lower, upper))) + 1.0
        eye, orthographic = centre - forward * behind, True
    triangle, barycentric, depth = rasterize(
        vertices, faces, np.asarray(eye, np.float64), forward, left, up, tan_x, tan_y,
        width, height, NEAR_CLIP, orthographic)
    if orthographic:
        footprint = np.full((height, width), 2.0 * tan_x / width)
    else:
        footprint = perspective_footprint(triangle, depth, tan_x, tan_y)
    return RasterView(triangle, barycentric, depth, footprint, face_offsets)


@dataclass
class SplattingState:
    """What :func:`precompute` returns: the scene and knobs (no geometric state).

    ``render(lights=None, material=None, scene=None)`` renders a frame; ``scene`` replaces
    the geometry (a deformed mesh) without any precomputation.
    """

    scene: object
    knobs: dict
    log: StageLog = field(default_factory=StageLog)
    #: ``check_scene(scene)`` refuses a scene the method cannot render (the contract's
    #: ``applies_to``, given by :func:`precompute`): asked again of every frame's scene,
    #: whose lights or material may have changed
    check_scene: Callable[[object], None] | None = None
    #: the light the scene's diffuse surfaces bounce onto the objects (None: lights alone)
    indirect: IndirectLight | None = None
    #: each homogeneous object's geometry correction (fast.object_geometry), for the
    #: meshes given to precompute
    geometry: dict = field(default_factory=dict)

    def __post_init__(self):
        self._precompute_log = self.log
        self._ranged: dict = {}
        self._camera_weights: dict = {}  # object -> (its pixels' key, cluster weights)
        # the six axis views of each object the indirect light reaches: geometry only, made
        # with the precomputation, not in a frame
        self._indirect_views = {} if self.indirect is None else {
            self.scene.objects[i].name: self._axis_views(self.scene, i)
            for i in translucent_objects(self.scene)
            if self.scene.objects[i].name in self.indirect.gathers}

    def render_ground_truth(self, lights=None, material=None, *, scene=None) -> Image:
        """Render the brute-force ground truth of :meth:`render` (see :func:`gather_frame`).

        Same buffers and material; cost pixels x irradiance samples, so keep both small.
        """
        return self.render(lights, material, scene=scene, _ground_truth=True)

    def render(self, lights=None, material=None, *, scene=None, _ground_truth=False) -> Image:
        """Render one frame with Chen et al. 2012's four steps; see the module docstring.

        Parameters
        ----------
        lights : sequence of PointLight / SpotLight / DirectionalLight / area lights, optional
            Replace the scene's lights.
        material : SubEditProfiles or Dipole, optional
            Replace the material of every translucent object.
        scene : Scene, optional
            Render this scene (for example with a deformed mesh) instead of the one given
            to :func:`precompute`.
        """
        scene = self.scene if scene is None else scene
        if lights is not None:
            scene = scene.with_lights(lights)
        if material is not None:
            for index in translucent_objects(scene):
                scene = scene.with_material(scene.objects[index].name, material)
        if self.check_scene is not None:
            self.check_scene(scene)
        log = StageLog()
        log.notes["profile"] = self.knobs["profile"]
        log.notes.update(self._precompute_log.notes)
        log.skipped.extend(self._precompute_log.skipped)
        self.log = log  # the frame's: the indirect light notes what it does there
        start = time.perf_counter()
        camera_view = self._camera_view(scene)
        camera = CameraModel.from_camera(scene.camera)
        log.seconds["buffer generation"] = time.perf_counter() - start
        radiance = np.zeros((scene.camera.height, scene.camera.width, 3))
        for index in translucent_objects(scene):
            radiance += self._render_object(scene, index, camera_view, camera, log,
                                            _ground_truth)
        seconds = time.perf_counter() - start
        producer = "splatting ground truth" if _ground_truth else "splatting"
        return Image(radiance.astype(np.float32), metadata={
            "producer": producer, "knobs": self.knobs, "seconds": seconds,
            "stage_seconds": log.seconds, "notes": log.notes, "skipped": log.skipped})

    def buffers(self, lights=None, *, scene=None):
        """Return the buffers of a frame: the camera's :class:`SurfaceBuffer` and light views.

        For the first translucent object; what :meth:`render` splats, exposed so that a
        benchmark can evaluate the ground truth on a subset of the same pixels.

        Returns
        -------
        tuple
            ``(camera_buffer, camera_model, light_views, material, sphere_radius)``.
        """
        scene = self.scene if scene is None else scene
        if lights is not None:
            scene = scene.with_lights(lights)
        index = translucent_objects(scene)[0]
        camera_buffer, views, material, radius = self._object_buffers(
            scene, index, self._camera_view(scene))
        return camera_buffer, CameraModel.from_camera(scene.camera), views, material, radius

    def _camera_view(self, scene):
        """Return the camera's buffers: a :class:`RasterView` or a ray-cast G-buffer."""
        if self.knobs["buffers"] == "raster":
            return rasterize_view(scene, camera=scene.camera)
        from ...scenes.gbuffer import gbuffer

        return gbuffer(scene)

    def _object_buffers(self, scene, index, camera_view):
        item = scene.objects[index]
        material = self._with_range_energy(as_subedit(item.material, item.mesh,
                                                      self.knobs["profile"]))
        mesh = item.mesh
        if mesh.uv is None and not material.is_homogeneous:
            raise InputError("a textured SubEdit material needs a mesh with uv coordinates",
                             field=f"objects[{index}].mesh.uv", value=None)
        centre, radius = _bounding_sphere(mesh)
        if isinstance(camera_view, RasterView):
            camera_buffer = camera_view.surface(scene, index)
        else:
            camera_buffer = _surface_buffer(camera_view, index, mesh.uv,
                                            _perspective_footprint(camera_view))
        count = self.knobs["area_light_points"]
        views = [self._light_view(scene, index, emitter, centre, radius, material.eta)
                 for light in scene.lights
                 for emitter in ([light] if isinstance(light, DirectionalLight)
                                 else point_emitters(light, count, centre))]
        return camera_buffer, views + self._indirect_light_views(scene, index, material), \
            material, radius

    def _with_range_energy(self, material: SubEditProfiles) -> SubEditProfiles:
        """Return ``material`` with the knob's ``range_energy``, one copy per material kept."""
        fraction = self.knobs["range_energy"]
        if material.range_energy == fraction:
            return material
        held = self._ranged.get(id(material))
        if held is None or held[0] is not material:  # the copy keeps its cached ranges
            held = (material, material.with_range_energy(fraction))
            if len(self._ranged) >= 8:
                self._ranged.pop(next(iter(self._ranged)))
            self._ranged[id(material)] = held
        return held[1]

    def _bounces_for(self, scene) -> bool:
        """Return whether the precomputed indirect light holds for ``scene``'s geometry."""
        if self.indirect is None or len(scene.objects) != len(self.scene.objects):
            return False
        return all(a.mesh is b.mesh
                   for a, b in zip(scene.objects, self.scene.objects, strict=True))

    def _indirect_light_views(self, scene, index, material) -> list[LightView]:
        r"""Return the indirect light as six orthographic views of the object (+-x, y, z).

        The transmitted irradiance :math:`E_t` gathered at each triangle
        (:class:`~translucent.fast.indirect_light.IndirectLight`) enters view v with the
        weight :math:`\cos^2\theta_v` of the normal's angle to the view: a pixel of area
        :math:`s^2` covers :math:`s^2/\cos\theta_v` of the surface, so its flux is
        :math:`E_t\,s^2\cos\theta_v`, and because :math:`\sum_v \max(0, n\cdot d_v)^2 =
        |n|^2 = 1` for the six axes, every surface point that the views see unoccluded
        gets all of its :math:`E_t\,dA` once. Points the object hides from a view (inside
        a concave part) lose that view's share.
        """
        if self.indirect is None:
            return []
        if not self._bounces_for(scene):
            self.log.skip("indirect light left out: the frame's geometry is not the one its "
                          "gather was precomputed for")
            return []
        name = scene.objects[index].name
        if name not in self._indirect_views:
            return []
        reflectance = {}
        for other in translucent_objects(scene):
            item = scene.objects[other]
            subedit = material if other == index else \
                as_subedit(item.material, item.mesh, self.knobs["profile"])
            found = reflectance_of(subedit)
            if found is not None:
                reflectance[other] = found
        radiosity, facts = self.indirect.radiosity(scene, bounces=self.knobs["indirect_bounces"],
                                                   reflectance=reflectance)
        self.log.notes["indirect bounces"] = facts
        irradiance = self.indirect.irradiance(name, radiosity, material.eta)
        views = []
        for direction, buffer, triangle in self._indirect_views[name]:
            cosine = np.clip(-np.einsum("hwd,d->hw", buffer.normal, direction), 0.0, 1.0)
            power = np.where(buffer.valid[..., None],
                             irradiance[np.where(buffer.valid, triangle, 0)] * cosine[..., None],
                             0.0)
            views.append(light_view(buffer, -direction, power, 1.0))
        return views

    def _axis_views(self, scene, index) -> list:
        """Return the object alone seen along the six axes: (direction, buffer, triangles)."""
        from ...scenes.gbuffer import gbuffer_orthographic
        from ...scenes.scene import Scene

        item = scene.objects[index]
        centre, radius = _bounding_sphere(item.mesh)
        alone = Scene((item,), (), scene.camera, scene.mm_per_unit, scene.name)
        size = self.knobs["indirect_resolution"]
        views = []
        for axis in range(3):
            for sign in (1.0, -1.0):
                direction = np.zeros(3)
                direction[axis] = sign
                view = gbuffer_orthographic(alone, direction, size, center=centre,
                                            extent=radius * VIEW_MARGIN)
                footprint = np.full(view.shape, math.sqrt(view.pixel_area))
                views.append((direction, _surface_buffer(view, 0, item.mesh.uv, footprint),
                              view.triangle_id))
        return views

    def _render_object(self, scene, index, camera_view, camera, log, ground_truth):
        start = time.perf_counter()
        camera_buffer, views, material, radius = self._object_buffers(scene, index,
                                                                      camera_view)
        log.seconds["buffer generation"] += time.perf_counter() - start
        item = scene.objects[index]
        if self.knobs["profile"] != DEFAULT_PROFILE and \
                not isinstance(item.material, (Dipole, SolidMedium)):
            log.skip(f"profile {self.knobs['profile']!r}: object '{item.name}' keeps the "
                     f"profiles of its {type(item.material).__name__} material (the knob "
                     "converts Dipole and solid materials)")
        if isinstance(item.material, SolidMedium):
            log.notes.setdefault("solid medium", {})[item.name] = subedit_from_solid(
                item.material, item.mesh, profile=self.knobs["profile"]).note()
        if not camera_buffer.valid.any():
            log.skip(f"object '{scene.objects[index].name}' is out of view: nothing to splat")
            return np.zeros(camera_buffer.shape + (3,))
        if ground_truth:
            radiance = gather_frame(camera_buffer, camera, views, material,
                                    mm_per_unit=scene.mm_per_unit)
        else:
            radiance = splat_frame(camera_buffer, camera, views, material,
                                   mm_per_unit=scene.mm_per_unit, sphere_radius=radius,
                                   knobs=self.knobs, log=log)
        # an exitance: the walks' noise can take the sum below zero where both are dark
        return np.maximum(radiance + self._geometry_radiance(
            scene, index, camera_buffer, camera, views, material, log), 0.0)

    def _exit_weights(self, name: str, geometry, camera_buffer):
        """Return the camera pixels' cluster weights, kept while their surface points stay.

        A relighting or editing frame sees the same points: only a moved camera (or
        another image) maps them again.
        """
        valid = camera_buffer.valid
        position, normal = camera_buffer.position[valid], camera_buffer.normal[valid]
        key = hashlib.sha1(np.ascontiguousarray(position).tobytes()
                           + np.ascontiguousarray(normal).tobytes()).hexdigest()
        held = self._camera_weights.get(name)
        if held is None or held[0] != key:
            held = (key, geometry.weights(position, normal))
            self._camera_weights[name] = held
        return held[1]

    def _geometry_radiance(self, scene, index, camera_buffer, camera, views, material, log):
        """Radiance of the geometry correction (fast.object_geometry) at the object's pixels.

        Its entry points are the light views' texels with their flux (the same light the
        splats carry), its exit points the camera buffer's pixels; Eq. 7 turns it into
        radiance as the splats' exitance.
        """
        item = scene.objects[index]
        geometry = self.geometry.get(item.name)
        if geometry is None:
            return 0.0
        if item.mesh is not self.scene.object(item.name).mesh or \
                not isinstance(item.material, Dipole):
            log.skip(f"geometry: '{item.name}' is not the mesh and homogeneous material the "
                     "correction was made for: its profile is the half-space's this frame")
            return 0.0
        start = time.perf_counter()
        mm2 = scene.mm_per_unit**2
        points, normals, power = [], [], []
        for view in views:
            chosen, flux = _entry_blocks(view.buffer.valid, view.flux, ENTRY_BLOCK)
            points.append(view.buffer.position[chosen])
            normals.append(view.buffer.normal[chosen])
            power.append(flux * mm2)
        valid = camera_buffer.valid
        profile = None if self.knobs["profile"] == DEFAULT_PROFILE else \
            radial_profile(self.knobs["profile"], item.material)
        exitance = np.zeros(camera_buffer.shape + (3,))
        exitance[valid] = geometry.exitance(
            geometry.weights(np.concatenate(points), np.concatenate(normals)),
            np.concatenate(power), self._exit_weights(item.name, geometry, camera_buffer),
            item.material, profile)
        radiance = exitant_radiance_of(exitance, camera_buffer, camera, material.eta)
        log.seconds["geometry"] = log.seconds.get("geometry", 0.0) + time.perf_counter() - start
        return radiance

    def _light_view(self, scene, index, light, centre, radius, eta) -> LightView:
        from ...scenes.gbuffer import default_up, gbuffer_from_point, gbuffer_orthographic
        from ...scenes.scene import Camera

        size = self.knobs["irradiance_resolution"]
        raster = self.knobs["buffers"] == "raster"
        uv = scene.objects[index].mesh.uv
        if isinstance(light, PointEmitter):
            towards = centre - light.position
            distance = float(np.linalg.norm(towards))
            if distance <= radius * VIEW_MARGIN:
                fov = MAX_LIGHT_FOV
            else:
                fov = min(MAX_LIGHT_FOV,
                          2.0 * math.degrees(math.asin(radius * VIEW_MARGIN / distance)))
            if distance == 0:
                towards = np.array([0.0, 0.0, -1.0])
            towards = towards / np.linalg.norm(towards)
            if raster:
                buffer = rasterize_view(scene, camera=Camera(
                    light.position, light.position + towards, default_up(towards), fov, size,
                    size)).surface(scene, index)
            else:
                view = gbuffer_from_point(scene, light.position, towards, fov, size)
                buffer = _surface_buffer(view, index, uv, _perspective_footprint(view))
            from .buffer_kernels import light_flux

            flux, cosine = light_flux(
                buffer.position, buffer.normal, buffer.valid, buffer.footprint,
                np.reshape(np.asarray(light.position, np.float64), (1, 1, 3)),
                np.reshape(np.asarray(light.intensity, np.float64), (1, 1, 3)), float(eta),
                True)
            if light.falloff is not None:
                # the emitter's intensity towards each buffer pixel: a spot's fall-off in
                # angle, an area light patch's cosine
                leaving = buffer.position - light.position
                length = np.linalg.norm(leaving, axis=-1, keepdims=True)
                falloff = light.falloff(leaving / np.maximum(length, 1e-300))
                flux = flux * np.where(buffer.valid, falloff, 0.0)[..., None]
            return LightView(buffer, flux, cosine)
        else:
            if raster:
                buffer = rasterize_view(scene, direction=light.direction, size=size,
                                        centre=centre, extent=radius * VIEW_MARGIN
                                        ).surface(scene, index)
            else:
                view = gbuffer_orthographic(scene, light.direction, size, center=centre,
                                            extent=radius * VIEW_MARGIN)
                footprint = np.full(view.shape, math.sqrt(view.pixel_area))
                buffer = _surface_buffer(view, index, uv, footprint)
            to_light = -light.direction
            irradiance = light.irradiance
        return light_view(buffer, to_light, irradiance, eta)


#: Light-view texels per side of a block whose flux enters the geometry correction at one
#: texel: the correction's cluster weights vary on the clusters' spacing (about 2 mm on a
#: 10 mm sphere), a 2 x 2 block of a 512 x 512 view spans 0.08 mm there. It maps a quarter
#: of the texels to the clusters (the sphere's frame 215 -> 155 ms); the report's relative
#: MSE moves by at most 1 % (cornell_block 0.00774 -> 0.00782, its floor 0.00015). 4 x 4
#: blocks moved it by 3 %.
ENTRY_BLOCK = 2


def _entry_blocks(valid: np.ndarray, flux: np.ndarray, block: int):
    """Sum a light view's flux over ``block`` x ``block`` texels; each sum enters at one texel.

    Returns the (rows, columns) of the texels that stand for their blocks (each block's valid
    texel of the most flux, so that a block across a silhouette enters on the surface that
    carries most of its light) and the blocks' flux, shape (B, 3). The flux is kept whole;
    only where it enters moves, by less than a block.
    """
    height, width = valid.shape
    rows, cols = -(-height // block) * block, -(-width // block) * block
    padded_flux = np.zeros((rows, cols, 3))
    padded_flux[:height, :width] = np.where(valid[..., None], flux, 0.0)
    weight = padded_flux.sum(axis=2)
    weight[:height, :width][~valid] = -1.0
    weight[height:, :] = -1.0
    weight[:, width:] = -1.0
    blocks = (rows // block, block, cols // block, block)
    tiles = weight.reshape(blocks).transpose(0, 2, 1, 3).reshape(-1, block * block)
    best = tiles.argmax(axis=1)
    keep = tiles[np.arange(len(tiles)), best] >= 0.0
    sums = padded_flux.reshape(*blocks, 3).sum(axis=(1, 3)).reshape(-1, 3)[keep]
    tile_row, tile_col = np.divmod(np.flatnonzero(keep), cols // block)
    within_row, within_col = np.divmod(best[keep], block)
    row, col = tile_row * block + within_row, tile_col * block + within_col
    return (row, col), sums
