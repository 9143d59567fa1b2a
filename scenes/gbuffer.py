"""What a view sees: G-buffers of the first hits, camera rays and projection.

Built on the ray queries of :mod:`translucent.scenes.raycast`, with its conventions:
pixel ``(row, col)`` with row 0 at the top; rays through pixel centres exactly as
Mitsuba's ``perspective`` sensor (``fov_axis = "x"``), starting at the near clip plane;
lengths in scene units.

Public API (stable): :func:`gbuffer` -> :class:`GBuffer` (with
:meth:`GBuffer.interpolate`), :func:`gbuffer_from_point`, :func:`gbuffer_orthographic`,
:func:`camera_frame`, :func:`default_up`, :func:`camera_rays`, :func:`project`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..errors import InputError, check_finite
from .raycast import NEAR_CLIP, ray_engine
from .scene import Camera, Scene

__all__ = ["GBuffer", "camera_frame", "camera_rays", "default_up", "gbuffer",
           "gbuffer_from_point", "gbuffer_orthographic", "interior_pixels", "project"]


@dataclass(frozen=True, eq=False)
class GBuffer:
    """What each pixel of a view sees: the first surface along its ray.

    Arrays are ``(H, W, ...)``; row 0 is the top of the image.

    Parameters
    ----------
    hit : ndarray of bool, (H, W)
        The pixel sees a surface.
    position : ndarray of float64, (H, W, 3)
        Surface point, scene units (0 on background).
    normal : ndarray of float64, (H, W, 3)
        Unit shading normal (interpolated vertex normals; 0 on background).
    geometric_normal : ndarray of float64, (H, W, 3)
        Unit face normal (0 on background).
    depth : ndarray of float64, (H, W)
        Distance from the eye (perspective) or from the image plane (orthographic) to the
        surface along the pixel's ray, scene units; ``inf`` on background.
    triangle_id : ndarray of int64, (H, W)
        Triangle index within the object's mesh; -1 on background.
    barycentrics : ndarray of float64, (H, W, 3)
        Weights of the triangle's vertices; 0 on background.
    object_id : ndarray of int64, (H, W)
        Index into ``objects``; -1 on background.
    view_direction : ndarray of float64, (H, W, 3)
        Unit vector from the surface towards the eye (minus the ray direction), on every
        pixel: the outgoing direction of shading.
    object_names : tuple of str
        Names of the scene's objects, by ``object_id``.
    meshes : tuple of Mesh
        The objects' meshes (their faces drive :meth:`interpolate`).
    camera : Camera or None
        The perspective camera, or None for an orthographic view.
    pixel_area : float or None
        Orthographic views: area of the scene a pixel covers on the image plane, scene
        units squared (None for perspective views).
    """

    hit: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    geometric_normal: np.ndarray
    depth: np.ndarray
    triangle_id: np.ndarray
    barycentrics: np.ndarray
    object_id: np.ndarray
    view_direction: np.ndarray
    object_names: tuple
    meshes: tuple
    camera: Camera | None = None
    pixel_area: float | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` in pixels."""
        return self.hit.shape

    def _object_index(self, object_name) -> int:
        if isinstance(object_name, (int, np.integer)) and not isinstance(object_name, bool):
            if 0 <= object_name < len(self.object_names):
                return int(object_name)
        elif object_name in self.object_names:
            return self.object_names.index(object_name)
        raise InputError(f"no such object; objects: {', '.join(self.object_names)}",
                         field="object_name", value=object_name)

    def mask(self, object_name) -> np.ndarray:
        """Return the (H, W) mask of the pixels that see object ``object_name`` (or its index)."""
        return self.object_id == self._object_index(object_name)

    def interpolate(self, object_name, vertex_values, *, fill=0.0) -> np.ndarray:
        """Interpolate per-vertex values of one object across the pixels that see it.

        Barycentric (linear) interpolation over each pixel's triangle; exact for values
        that are a linear function of position on each triangle.

        Parameters
        ----------
        object_name : str or int
            The object (name or index into the scene's objects).
        vertex_values : array_like, (V, ...) or (V,)
            One value (scalar, RGB, ...) per vertex of the object's mesh, any units.
        fill : float
            Value of the pixels that do not see the object.

        Returns
        -------
        ndarray, (H, W, ...)
            float64 (or the values' complex/float dtype).
        """
        index = self._object_index(object_name)
        mesh = self.meshes[index]
        values = np.asarray(vertex_values)
        if values.shape[:1] != (len(mesh.vertices),):
            raise InputError(f"needs one value per vertex of '{self.object_names[index]}' "
                             f"({len(mesh.vertices)})", field="vertex_values",
                             value=values.shape)
        dtype = np.result_type(values.dtype, np.float64)
        out = np.full(self.shape + values.shape[1:], fill, dtype=dtype)
        where = self.object_id == index
        corners = mesh.faces[self.triangle_id[where]]
        weights = self.barycentrics[where]
        out[where] = np.einsum("nk,nk...->n...", weights, values[corners].astype(dtype))
        return out

    def interpolate_all(self, values_by_object: Mapping, *, fill=0.0) -> np.ndarray:
        """Interpolate per-vertex values of several objects into one image.

        Parameters
        ----------
        values_by_object : mapping of str (or int) to array_like (V, ...)
            Per-vertex values of each object to draw; all with the same trailing shape.
        fill : float
            Value of pixels that see none of them (background included).

        Returns
        -------
        ndarray, (H, W, ...)
        """
        out = None
        for name, values in values_by_object.items():
            image = self.interpolate(name, values, fill=0.0)
            if out is None:
                out = np.full(image.shape, fill, dtype=image.dtype)
            where = self.mask(name)
            out[where] = image[where]
        if out is None:
            raise InputError("give the values of at least one object",
                             field="values_by_object", value={})
        return out


def camera_rays(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Return the eye position and the unit ray directions through the pixel centres.

    The convention of Mitsuba's ``perspective`` sensor (``fov_axis = "x"``,
    ``look_at``): the image's left edge is towards ``cross(up, forward)``, its top
    towards ``up``; ``tan`` of the half-angles are ``tan(fov/2)`` horizontally and
    ``tan(fov/2) * H / W`` vertically.

    Parameters
    ----------
    camera : Camera

    Returns
    -------
    origin : ndarray, (3,)
        The eye, scene units.
    directions : ndarray, (H, W, 3)
        Unit directions, row 0 at the top.
    """
    forward, left, up = camera_frame(camera)
    tan_x = math.tan(math.radians(camera.fov) / 2.0)
    tan_y = tan_x * camera.height / camera.width
    sx = (np.arange(camera.width) + 0.5) / camera.width
    sy = (np.arange(camera.height) + 0.5) / camera.height
    x = tan_x * (1.0 - 2.0 * sx)
    y = tan_y * (1.0 - 2.0 * sy)
    directions = forward + x[None, :, None] * left + y[:, None, None] * up
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    return camera.origin.copy(), directions


def camera_frame(camera: Camera):
    """Return the camera's unit axes ``(forward, left, up)``, ``up`` from ``camera.up``."""
    forward = camera.forward
    left = np.cross(camera.up, forward)
    left /= np.linalg.norm(left)
    return forward, left, np.cross(forward, left)


def project(camera: Camera, points) -> tuple[np.ndarray, np.ndarray]:
    """Project points onto the image of ``camera``: continuous pixel coordinates.

    The inverse of :func:`camera_rays`: the centre of pixel ``(row, col)`` projects to
    ``(col + 0.5, row + 0.5)``.

    Parameters
    ----------
    camera : Camera
    points : array_like, (..., 3)
        Scene units.

    Returns
    -------
    xy : ndarray, (..., 2)
        ``(x, y)`` in pixels from the image's top-left corner (x to the right, y down).
    in_front : ndarray of bool, (...)
        The point lies in front of the eye (beyond the near clip plane).
    """
    forward, left, up = camera_frame(camera)
    relative = np.asarray(points, dtype=np.float64) - camera.origin
    z = relative @ forward
    tan_x = math.tan(math.radians(camera.fov) / 2.0)
    tan_y = tan_x * camera.height / camera.width
    with np.errstate(divide="ignore", invalid="ignore"):
        x = (relative @ left) / z
        y = (relative @ up) / z
    col = (1.0 - x / tan_x) / 2.0 * camera.width
    row = (1.0 - y / tan_y) / 2.0 * camera.height
    return np.stack([col, row], axis=-1), z > NEAR_CLIP


def _gbuffer_from_rays(scene: Scene, origins, directions, start, shape, *, camera,
                       pixel_area) -> GBuffer:
    """Trace one ray per pixel; ``start`` is the distance already travelled from the eye."""
    engine = ray_engine(scene)
    hits = engine.trace(origins.reshape(-1, 3) + start.reshape(-1, 1)
                        * directions.reshape(-1, 3), directions.reshape(-1, 3))
    height, width = shape

    def image(array):
        return array.reshape((height, width) + array.shape[1:])

    return GBuffer(
        hit=image(hits.hit),
        position=image(hits.position),
        normal=image(hits.shading_normal),
        geometric_normal=image(hits.geometric_normal),
        depth=image(hits.t + start.reshape(-1)),
        triangle_id=image(hits.triangle_id),
        barycentrics=image(hits.barycentrics),
        object_id=image(hits.object_id),
        view_direction=-np.broadcast_to(directions, (height, width, 3)).copy(),
        object_names=tuple(o.name for o in scene.objects),
        meshes=engine.meshes,
        camera=camera,
        pixel_area=pixel_area,
    )


def gbuffer(scene: Scene, camera: Camera | None = None) -> GBuffer:
    """Return the G-buffer of a pinhole camera: the first surface seen through each pixel.

    Parameters
    ----------
    scene : Scene
    camera : Camera, optional
        Default ``scene.camera``. Its pixels are those of a Mitsuba render through
        :func:`perspective_sensor_dict` (pixel centres; see the module docstring).

    Returns
    -------
    GBuffer
    """
    camera = scene.camera if camera is None else camera
    origin, directions = camera_rays(camera)
    # Like Mitsuba's sensor, start at the near clip plane (NEAR_CLIP along the axis)
    start = NEAR_CLIP / (directions @ camera.forward)
    origins = np.broadcast_to(origin, directions.shape)
    return _gbuffer_from_rays(scene, origins, directions, start, directions.shape[:2],
                              camera=camera, pixel_area=None)


def _size(size) -> tuple[int, int]:
    """``size`` as ``(width, height)`` from an int or a pair."""
    pair = (size, size) if np.ndim(size) == 0 else tuple(size)
    if len(pair) != 2 or any(isinstance(n, bool) or int(n) != n or not 1 <= int(n) <= 16384
                             for n in pair):
        raise InputError("must be an integer in [1, 16384] or a (width, height) pair",
                         field="size", value=size)
    return int(pair[0]), int(pair[1])


def default_up(direction: np.ndarray) -> np.ndarray:
    """Return an up vector not parallel to ``direction``: +y, or +z looking along y."""
    up = np.array([0.0, 1.0, 0.0])
    return np.array([0.0, 0.0, 1.0]) if abs(direction @ up) > 0.99 else up


def gbuffer_from_point(scene: Scene, position, direction, fov: float, size, *,
                       up=None) -> GBuffer:
    """Return the G-buffer seen from a point: a light's view (shadow maps, light sampling).

    Parameters
    ----------
    scene : Scene
    position : (3,) array_like
        The eye (a point or spot light's position), scene units.
    direction : (3,) array_like
        Viewing direction (a spot light's axis).
    fov : float
        Horizontal field of view, degrees in (0, 180) (twice a spot's cutoff angle).
    size : int or (int, int)
        Image width and height in pixels (one int: square).
    up : (3,) array_like, optional
        Image up direction (default +y, or +z when looking nearly along y).

    Returns
    -------
    GBuffer
        With ``camera`` set to the equivalent :class:`Camera`.
    """
    from .scene import vector3

    position = vector3(position, "position")
    direction = vector3(direction, "direction", unit=True)
    width, height = _size(size)
    camera = Camera(position, position + direction,
                    default_up(direction) if up is None else up, fov, width, height)
    return gbuffer(scene, camera)


def gbuffer_orthographic(scene: Scene, direction, size, *, center=None, extent=None,
                         up=None) -> GBuffer:
    """Return an orthographic G-buffer along ``direction``: a directional light's view.

    Parallel rays travel along ``direction`` from an image plane in front of the scene.
    By default the square image covers the bounding sphere of the scene's meshes.

    Parameters
    ----------
    scene : Scene
    direction : (3,) array_like
        Direction the rays travel (a directional light's ``direction``).
    size : int or (int, int)
        Image width and height in pixels.
    center : (3,) array_like, optional
        Point the image is centred on, scene units (default: bounding-box centre).
    extent : float, optional
        Half the image width, scene units (default: the bounding sphere's radius); the
        height follows the aspect ratio.
    up : (3,) array_like, optional
        Image up direction (default +y, or +z for near-vertical directions).

    Returns
    -------
    GBuffer
        ``camera`` None; ``pixel_area`` the area one pixel covers, scene units squared;
        ``depth`` measured from the image plane.
    """
    from .scene import vector3

    direction = vector3(direction, "direction", unit=True)
    width, height = _size(size)
    engine = ray_engine(scene)
    lower, upper = engine.bounds
    middle = (lower + upper) / 2.0 if center is None else vector3(center, "center")
    radius = float(np.max(np.linalg.norm(engine.vertices - middle, axis=1)))
    half_width = radius if extent is None else float(check_finite(extent, "extent"))
    if half_width <= 0:
        raise InputError("must be > 0", field="extent", value=extent)
    half_height = half_width * height / width
    up = default_up(direction) if up is None else vector3(up, "up", unit=True)
    left = np.cross(up, direction)
    if np.linalg.norm(left) < 1e-9:
        raise InputError("up must not be parallel to direction", field="up", value=up.tolist())
    left /= np.linalg.norm(left)
    image_up = np.cross(direction, left)
    x = half_width * (1.0 - 2.0 * (np.arange(width) + 0.5) / width)
    y = half_height * (1.0 - 2.0 * (np.arange(height) + 0.5) / height)
    behind = radius + float(np.linalg.norm(middle - np.clip(middle, lower, upper))) + 1.0
    plane_origin = middle - direction * behind
    origins = plane_origin + x[None, :, None] * left + y[:, None, None] * image_up
    directions = np.broadcast_to(direction, origins.shape)
    pixel_area = (2.0 * half_width / width) * (2.0 * half_height / height)
    return _gbuffer_from_rays(scene, origins, directions, np.zeros((height, width)),
                              (height, width), camera=None, pixel_area=pixel_area)


def interior_pixels(scene: Scene, camera: Camera | None = None) -> np.ndarray:
    """Return the pixels whose 3 x 3 neighbourhood sees one object, and an object.

    Edges are anti-aliased by a reference's pixel filter but not by a one-ray G-buffer:
    metrics over these pixels leave that difference out.
    """
    ids = gbuffer(scene, camera).object_id
    padded = np.pad(ids, 1, mode="edge")
    same = np.ones(ids.shape, dtype=bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            same &= padded[1 + dy:1 + dy + ids.shape[0], 1 + dx:1 + dx + ids.shape[1]] == ids
    return same & (ids >= 0)
