"""Ray queries: Embree (through ``embreex``) or Mitsuba 3 as a ray-intersection engine.

The meshes of a scene are merged into one triangle mesh (vertices that coincide in float32
welded) inside one acceleration structure; a batch of rays is one vectorised call (large
batches are cut into chunks of :data:`RAYS_PER_CALL` to bound memory). Both engines
intersect in float32; positions, normals and barycentrics are then evaluated in float64 on
the suite's own meshes.

Two engines answer the same queries with the same results (hit or miss identical except for
rays within float32 resolution of an edge): ``"embree"`` calls Embree directly through the
``embreex`` package (a compiled loop over the rays, a few ms per 64k shadow rays) and
``"mitsuba"`` goes through Mitsuba's ``ray_intersect_preliminary`` / ``ray_test`` (Dr.Jit
traces and compiles a kernel per call: tens of ms for the same batch). ``"auto"`` (the
default, or the environment variable ``TRANSLUCENT_RAY_ENGINE``) takes Embree when
``embreex`` is installed, Mitsuba otherwise.

One engine is built per geometry and cached (:func:`ray_engine`): scenes that share their
``Mesh`` objects (another light, another material, another camera) share it; a deformed
mesh is a new ``Mesh`` object and gets a new engine.

Conventions
-----------
* Lengths in scene units (multiply by ``scene.mm_per_unit`` for mm).
* Pixel ``(row, col)``: row 0 is the top of the image, column 0 its left; rays go through
  pixel centres, exactly as Mitsuba's ``perspective`` sensor with ``fov_axis = "x"`` and
  ``to_world = look_at(origin, target, up)`` (:func:`perspective_sensor_dict`), so that
  reference renders line up pixel for pixel. Like that sensor, camera rays start at the
  near clip plane (:data:`NEAR_CLIP` along the viewing axis); depths are measured from the
  eye.
* Barycentrics ``(b0, b1, b2)`` weight the triangle's vertices ``faces[t, 0..2]``.
* Normals: ``geometric_normal`` is the face normal (outward by the winding),
  ``shading_normal`` the interpolated vertex normal, both unit length.

Public API (stable): :func:`trace` -> :class:`RayHits`, :func:`visible`,
:func:`visibility_matrix`, :func:`perspective_sensor_dict`, :func:`to_mitsuba_mesh`,
:func:`ray_engine`, :class:`RayEngine`; the camera's view of the scene (G-buffers,
camera rays, projection) is :mod:`translucent.scenes.gbuffer`.
"""

from __future__ import annotations

import collections
import functools
import math
import os
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..errors import InputError, check_finite
from .scene import Camera, Mesh, Scene

__all__ = [
    "NEAR_CLIP",
    "RAY_ENGINES",
    "RAYS_PER_CALL",
    "RayEngine",
    "RayHits",
    "embree_available",
    "perspective_sensor_dict",
    "ray_engine",
    "to_mitsuba_mesh",
    "trace",
    "visibility_matrix",
    "visible",
]

#: Rays per Mitsuba call: about 100 MB of ray and hit data in flight at float32.
RAYS_PER_CALL = 1 << 21

#: Distance of the near clip plane along the viewing axis, scene units: Mitsuba's
#: ``perspective`` sensor default (``near_clip = 0.01``), which camera rays follow.
NEAR_CLIP = 1e-2

#: Distance of the far clip plane, scene units: Mitsuba's ``perspective`` default.
FAR_CLIP = 1e4

#: Default offset of shadow-ray end points, as a fraction of the scene's bounding-box
#: diagonal: float32 intersection has a relative error near 1e-7 of the coordinates, so
#: 1e-5 clears self-intersection with two orders of margin while staying far below any
#: feature of the built-in scenes.
OFFSET_FRACTION = 1e-5

#: Tilt (radians) of the second try of a ray that missed: far above float32 resolution of
#: a direction (6e-8), far below a pixel of any camera the suite uses (1e-3 rad at 1000
#: pixels across 60 degrees), so a ray that slipped through an edge finds the surface
#: while a true miss stays a miss.
CRACK_TILT = 1e-6

#: Engines kept alive (each holds its meshes, so their ids stay unique while cached).
ENGINE_CACHE_SIZE = 8

#: Names of the ray engines (see the module docstring).
RAY_ENGINES = ("auto", "embree", "mitsuba")


@functools.lru_cache(maxsize=1)
def embree_available() -> bool:
    """Return True when the ``embreex`` package (Embree's Python binding) can be imported."""
    try:
        import embreex.mesh_construction  # noqa: F401
        import embreex.rtcore_scene  # noqa: F401
    except ImportError:
        return False
    return True


def _engine_name(name: str | None) -> str:
    """Resolve ``None``/``"auto"`` (or ``TRANSLUCENT_RAY_ENGINE``) to "embree" or "mitsuba"."""
    field = "engine"
    if name is None:
        name = os.environ.get("TRANSLUCENT_RAY_ENGINE") or "auto"
        field = "TRANSLUCENT_RAY_ENGINE"
    if name not in RAY_ENGINES:
        raise InputError(f"unknown ray engine; valid: {', '.join(RAY_ENGINES)}", field=field,
                         value=name)
    if name == "auto":
        return "embree" if embree_available() else "mitsuba"
    if name == "embree" and not embree_available():
        raise InputError("the embree ray engine needs the embreex package (pip install "
                         "embreex); or choose 'mitsuba'", field=field, value=name)
    return name


# ---------------------------------------------------------------------------------------
# Mitsuba meshes


def to_mitsuba_mesh(mesh: Mesh, name: str | None = None, *, props: dict | None = None,
                    with_normals: bool = True, with_uv: bool = True):
    """Build a Mitsuba ``Mesh`` shape from a suite :class:`Mesh` (float32, same indices).

    Parameters
    ----------
    mesh : Mesh
        Positions in scene units.
    name : str, optional
        Mitsuba's name for it (default ``mesh.name``).
    props : dict, optional
        Plugins to attach, for example ``{"bsdf": {"type": "diffuse"}}`` or
        ``{"interior": medium_dict}``: dicts are loaded with ``mi.load_dict``, other values
        (already loaded plugins, numbers) are set as they are.
    with_normals, with_uv : bool
        Pass the vertex normals (smooth shading in Mitsuba) and texture coordinates.

    Returns
    -------
    mitsuba.Mesh
    """
    return _mitsuba_mesh(name or mesh.name, mesh.vertices, mesh.faces,
                         mesh.normals if with_normals else None,
                         mesh.uv if with_uv else None, props)


def _mitsuba_mesh(name, vertices, faces, normals=None, uv=None, props=None):
    from ..backend import mitsuba

    mi = mitsuba()
    properties = mi.Properties()
    for key, value in (props or {}).items():
        properties[key] = mi.load_dict(value) if isinstance(value, dict) else value
    shape = mi.Mesh(name, len(vertices), len(faces), properties,
                    has_vertex_normals=normals is not None, has_vertex_texcoords=uv is not None)
    params = mi.traverse(shape)
    params["vertex_positions"] = mi.Float(np.asarray(vertices, dtype=np.float32).ravel())
    params["faces"] = mi.UInt32(np.asarray(faces, dtype=np.uint32).ravel())
    if normals is not None:
        params["vertex_normals"] = mi.Float(np.asarray(normals, dtype=np.float32).ravel())
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(np.asarray(uv, dtype=np.float32).ravel())
    params.update()
    return shape


def perspective_sensor_dict(camera: Camera, *, spp: int = 1, rfilter: str = "box",
                            sampler: str = "independent", seed: int = 0,
                            frame_scale: float = 1.0) -> dict:
    """Return the Mitsuba ``perspective`` sensor whose pixels are those of :func:`gbuffer`.

    Parameters
    ----------
    camera : Camera
        ``fov`` is the horizontal field of view (``fov_axis = "x"``).
    spp : int
        Samples per pixel of the sampler.
    rfilter : str
        Reconstruction filter plugin; ``"box"`` keeps each pixel's samples inside it.
    sampler : str
        Sampler plugin name.
    seed : int
        Sampler seed (independent passes use different seeds).
    frame_scale : float
        ``camera`` is in a frame of this many units per scene unit
        (:class:`~translucent.scenes.frame.Frame`): the clip planes, :data:`NEAR_CLIP` and
        :data:`FAR_CLIP` scene units, scale with it.

    Returns
    -------
    dict
        For ``mi.load_dict`` (as the ``sensor`` of a scene dict).
    """
    from ..backend import mitsuba

    mi = mitsuba()
    return {
        "type": "perspective",
        "fov": float(camera.fov),
        "fov_axis": "x",
        "near_clip": NEAR_CLIP * frame_scale,
        "far_clip": FAR_CLIP * frame_scale,
        "to_world": mi.ScalarTransform4f().look_at(origin=camera.origin.tolist(),
                                                   target=camera.target.tolist(),
                                                   up=camera.up.tolist()),
        "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height,
                 "rfilter": {"type": rfilter}, "pixel_format": "rgb"},
        "sampler": {"type": sampler, "sample_count": int(spp), "seed": int(seed)},
    }


# ---------------------------------------------------------------------------------------
# the engine


@dataclass(frozen=True, eq=False)
class RayHits:
    """What a batch of rays hit; arrays of length N (the number of rays).

    Parameters
    ----------
    hit : ndarray of bool, (N,)
    t : ndarray of float64, (N,)
        Distance along the unit ray direction, scene units; ``inf`` where nothing was hit.
    position : ndarray of float64, (N, 3)
        Hit point (barycentric combination of the triangle's vertices); 0 on a miss.
    geometric_normal, shading_normal : ndarray of float64, (N, 3)
        Unit face normal and unit interpolated vertex normal; 0 on a miss.
    object_id : ndarray of int64, (N,)
        Index into ``scene.objects``; -1 on a miss.
    triangle_id : ndarray of int64, (N,)
        Index into that object's ``mesh.faces``; -1 on a miss.
    barycentrics : ndarray of float64, (N, 3)
        Weights of the triangle's three vertices (sum 1); 0 on a miss.
    """

    hit: np.ndarray
    t: np.ndarray
    position: np.ndarray
    geometric_normal: np.ndarray
    shading_normal: np.ndarray
    object_id: np.ndarray
    triangle_id: np.ndarray
    barycentrics: np.ndarray


class RayEngine:
    """The meshes of a scene, merged into one triangle mesh, answering batched ray queries.

    Parameters
    ----------
    meshes : sequence of Mesh
        In the order of ``scene.objects``; object ``k`` is ``meshes[k]``.
    engine : {"auto", "embree", "mitsuba"}, optional
        Who intersects (see the module docstring); default ``TRANSLUCENT_RAY_ENGINE`` or
        ``"auto"``.

    Attributes
    ----------
    engine : str
        ``"embree"`` or ``"mitsuba"``: the engine that answers :meth:`trace` and
        :meth:`occluded`.
    mi, scene
        The Mitsuba module and an ``mi.Scene`` of the merged mesh, built on first access
        (for callers that trace through Mitsuba themselves), whatever the engine.
    """

    def __init__(self, meshes: Sequence[Mesh], engine: str | None = None):
        self.engine = _engine_name(engine)
        self.meshes = tuple(meshes)
        if not self.meshes:
            raise InputError("a ray engine needs at least one mesh", field="meshes", value=[])
        vertex_offsets = np.cumsum([0] + [len(m.vertices) for m in self.meshes])
        self.face_offsets = np.cumsum([0] + [len(m.faces) for m in self.meshes])
        self.vertices = np.concatenate([m.vertices for m in self.meshes])
        self.faces = np.concatenate([m.faces + offset
                                     for m, offset in zip(self.meshes, vertex_offsets[:-1],
                                                          strict=True)])
        self.normals = np.concatenate([m.normals for m in self.meshes])
        lower, upper = self.vertices.min(axis=0), self.vertices.max(axis=0)
        self.bounds = (lower, upper)
        self.diagonal = float(np.linalg.norm(upper - lower))
        # Weld vertices that coincide in float32 (the seam between a wall and the floor):
        # the watertight triangle test then lets no ray slip between neighbouring meshes.
        welded, index = np.unique(self.vertices.astype(np.float32), axis=0, return_inverse=True)
        self._welded = (welded, index.reshape(-1)[self.faces])
        self._mitsuba_scene = None
        self._embree_scene = None
        if self.engine == "embree":
            from embreex import mesh_construction, rtcore_scene

            # robust mode: Embree's watertight test, so no ray slips through a shared edge
            self._embree_scene = rtcore_scene.EmbreeScene(robust=True)
            # the scene keeps the geometry alive; the handle itself is not needed
            self._embree_mesh = mesh_construction.TriangleMesh(
                self._embree_scene, np.ascontiguousarray(welded, dtype=np.float32),
                np.ascontiguousarray(self._welded[1], dtype=np.int32))
        else:
            self.scene  # noqa: B018 - build the Mitsuba scene now, as the engine

    @property
    def mi(self):
        """The Mitsuba module (:func:`translucent.backend.mitsuba`)."""
        from ..backend import mitsuba

        return mitsuba()

    @property
    def scene(self):
        """An ``mi.Scene`` holding the merged mesh (built on first access)."""
        if self._mitsuba_scene is None:
            shape = _mitsuba_mesh("geometry", *self._welded)
            self._mitsuba_scene = self.mi.load_dict({"type": "scene", "geometry": shape})
        return self._mitsuba_scene

    def _rays(self, origins, directions, tmax):
        mi = self.mi
        ray = mi.Ray3f(mi.Point3f(np.ascontiguousarray(origins.T, dtype=np.float32)),
                       mi.Vector3f(np.ascontiguousarray(directions.T, dtype=np.float32)))
        # the (o, d, maxt) constructor does not exist: a third argument would be the time
        ray.maxt = mi.Float(np.ascontiguousarray(tmax, dtype=np.float32))
        return ray

    def _embree_run(self, origins, directions, tmax, **query):
        """One Embree query on a chunk of rays (float32, C-contiguous; no copy if already)."""
        return self._embree_scene.run(np.ascontiguousarray(origins, dtype=np.float32),
                                      np.ascontiguousarray(directions, dtype=np.float32),
                                      dists=np.ascontiguousarray(tmax, dtype=np.float32),
                                      **query)

    def trace(self, origins, directions, tmax=np.inf) -> RayHits:
        """Closest hits of rays ``origins + t directions``, ``0 <= t <= tmax``.

        See :func:`trace` (the same, for a scene).
        """
        origins, directions, tmax = _ray_batch(origins, directions, tmax)
        t, global_triangle, uv = self._closest(origins, directions, tmax)
        missed = np.flatnonzero(global_triangle < 0)
        if len(missed):
            # Mitsuba does not run Embree in its robust mode: a ray exactly through an
            # edge can pass between the two triangles. Retry misses tilted by CRACK_TILT
            # (with either engine, so that both give the same answers).
            tilted = directions[missed] + CRACK_TILT * _tilt_directions(directions[missed])
            retry = self._closest(origins[missed], tilted / np.linalg.norm(tilted, axis=1,
                                                                            keepdims=True),
                                  tmax[missed])
            found = retry[1] >= 0
            t[missed[found]] = retry[0][found]
            global_triangle[missed[found]] = retry[1][found]
            uv[missed[found]] = retry[2][found]
        return self._hits(t, global_triangle, uv)

    def _closest(self, origins, directions, tmax):
        count = len(origins)
        t = np.full(count, np.inf)
        global_triangle = np.full(count, -1, dtype=np.int64)
        uv = np.zeros((count, 2))
        for start in range(0, count, RAYS_PER_CALL):
            stop = min(count, start + RAYS_PER_CALL)
            chunk = slice(start, stop)
            if self._embree_scene is not None:
                found = self._embree_run(origins[chunk], directions[chunk], tmax[chunk],
                                         output=True)
                primitive = found["primID"].astype(np.int64)
                valid = primitive >= 0
                t[chunk] = np.where(valid, found["tfar"], np.inf)
                global_triangle[chunk] = np.where(valid, primitive, -1)
                uv[chunk] = np.where(valid[:, None], np.stack([found["u"], found["v"]], 1), 0.0)
                continue
            ray = self._rays(origins[chunk], directions[chunk], tmax[chunk])
            found = self.scene.ray_intersect_preliminary(ray)
            valid = found.is_valid().numpy().astype(bool)
            t[chunk] = np.where(valid, found.t.numpy(), np.inf)
            global_triangle[chunk] = np.where(valid, found.prim_index.numpy().astype(np.int64),
                                              -1)
            uv[chunk] = np.where(valid[:, None], found.prim_uv.numpy().T, 0.0)
        return t, global_triangle, uv

    def _hits(self, t, global_triangle, uv) -> RayHits:
        hit = global_triangle >= 0
        count = len(t)
        object_id = np.full(count, -1, dtype=np.int64)
        triangle_id = np.full(count, -1, dtype=np.int64)
        barycentrics = np.zeros((count, 3))
        position = np.zeros((count, 3))
        geometric = np.zeros((count, 3))
        shading = np.zeros((count, 3))
        rows = np.flatnonzero(hit)
        if len(rows):
            triangles = global_triangle[rows]
            owner = np.searchsorted(self.face_offsets, triangles, side="right") - 1
            object_id[rows] = owner
            triangle_id[rows] = triangles - self.face_offsets[owner]
            b1, b2 = uv[rows, 0], uv[rows, 1]
            b0 = 1.0 - b1 - b2
            barycentrics[rows, 0], barycentrics[rows, 1], barycentrics[rows, 2] = b0, b1, b2
            corners = self.faces[triangles]
            p0, p1, p2 = (self.vertices[corners[:, k]] for k in range(3))
            position[rows] = b0[:, None] * p0 + b1[:, None] * p1 + b2[:, None] * p2
            cross = np.cross(p1 - p0, p2 - p0)
            face_normal = cross / np.linalg.norm(cross, axis=1, keepdims=True)
            geometric[rows] = face_normal
            smooth = (b0[:, None] * self.normals[corners[:, 0]]
                      + b1[:, None] * self.normals[corners[:, 1]]
                      + b2[:, None] * self.normals[corners[:, 2]])
            length = np.linalg.norm(smooth, axis=1, keepdims=True)
            # opposite vertex normals can cancel inside a triangle: fall back to the face
            shading[rows] = np.where(length > 1e-12, smooth / np.maximum(length, 1e-300),
                                     face_normal)
        return RayHits(hit, t, position, geometric, shading, object_id, triangle_id,
                       barycentrics)

    def occluded(self, origins, directions, tmax) -> np.ndarray:
        """Return True where a ray hits anything with ``t <= tmax`` (any hit; cheaper)."""
        return self.occluded_unit(*_ray_batch(origins, directions, tmax))

    def occluded_unit(self, origins, directions, tmax) -> np.ndarray:
        """:meth:`occluded` for a batch already checked: no validation, no copies.

        For callers that trace shadow rays every frame (:func:`visible`, relighting).

        Parameters
        ----------
        origins, directions : ndarray, (N, 3)
            Finite; directions of unit length. float32 C-contiguous arrays are passed to
            the engine as they are, others are converted.
        tmax : ndarray, (N,)
            Scene units, ``0 <= tmax`` and finite.

        Returns
        -------
        ndarray of bool, (N,)
        """
        blocked = np.zeros(len(origins), dtype=bool)
        for start in range(0, len(origins), RAYS_PER_CALL):
            chunk = slice(start, min(len(origins), start + RAYS_PER_CALL))
            if self._embree_scene is not None:
                geometry = self._embree_run(origins[chunk], directions[chunk], tmax[chunk],
                                            query="OCCLUDED")
                blocked[chunk] = geometry >= 0
                continue
            ray = self._rays(origins[chunk], directions[chunk], tmax[chunk])
            blocked[chunk] = self.scene.ray_test(ray).numpy().astype(bool)
        return blocked


def _tilt_directions(directions: np.ndarray) -> np.ndarray:
    """Return unit vectors perpendicular to each direction, at an angle no edge favours."""
    helper = np.where(np.abs(directions[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(directions, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    second = np.cross(directions, first)
    angle = 0.6435  # atan(3/4): not a multiple of 45 degrees
    return math.cos(angle) * first + math.sin(angle) * second


def _ray_batch(origins, directions, tmax):
    """Validate and broadcast a batch; directions normalised."""
    arrays = {}
    for name, value in (("origins", origins), ("directions", directions), ("tmax", tmax)):
        try:
            arrays[name] = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise InputError("must be numbers (an array of shape (N, 3), or (N,) for tmax)",
                             field=name, value=value) from error
    origins, directions, tmax = arrays["origins"], arrays["directions"], arrays["tmax"]
    if origins.shape[-1:] != (3,) or directions.shape[-1:] != (3,):
        raise InputError("origins and directions must be arrays of shape (N, 3)",
                         field="origins", value=(origins.shape, directions.shape))
    origins, directions = np.broadcast_arrays(np.atleast_2d(origins), np.atleast_2d(directions))
    origins, directions = origins.reshape(-1, 3), directions.reshape(-1, 3)
    check_finite(origins, "origins")
    check_finite(directions, "directions")
    length = np.linalg.norm(directions, axis=1, keepdims=True)
    if (length == 0).any():
        raise InputError("ray directions must be non-zero", field="directions",
                         value=int(np.flatnonzero(length[:, 0] == 0)[0]))
    if tmax.size != 1 and tmax.shape != (len(origins),):
        raise InputError(f"tmax must be one value, or one per ray ({len(origins)})",
                         field="tmax", value=tmax.shape)
    tmax = np.broadcast_to(tmax.reshape(-1) if tmax.size == 1 else tmax, (len(origins),))
    if np.isnan(tmax).any() or (tmax < 0).any():
        raise InputError("tmax must be >= 0 (inf for unbounded)", field="tmax",
                         value=float(tmax[np.isnan(tmax) | (tmax < 0)][0]))
    # float32 holds up to 3.4e38; Mitsuba treats that as unbounded
    tmax = np.minimum(tmax, np.finfo(np.float32).max)
    return origins, directions / length, tmax


_ENGINES: collections.OrderedDict = collections.OrderedDict()


def ray_engine(scene_or_meshes, engine: str | None = None) -> RayEngine:
    """Return the cached :class:`RayEngine` of a scene's geometry (built on first use).

    Parameters
    ----------
    scene_or_meshes : Scene or sequence of Mesh
        Scenes holding the same ``Mesh`` objects in the same order share one engine.
    engine : {"auto", "embree", "mitsuba"}, optional
        Default ``TRANSLUCENT_RAY_ENGINE`` or ``"auto"`` (Embree when ``embreex`` is
        installed).

    Returns
    -------
    RayEngine

    Raises
    ------
    InputError
        An unknown engine, or ``"embree"`` without the ``embreex`` package.
    """
    name = _engine_name(engine)
    meshes = tuple(o.mesh for o in scene_or_meshes.objects) \
        if isinstance(scene_or_meshes, Scene) else tuple(scene_or_meshes)
    key = (name,) + tuple(id(mesh) for mesh in meshes)
    if key in _ENGINES:
        _ENGINES.move_to_end(key)
        return _ENGINES[key]
    engine = RayEngine(meshes, name)
    _ENGINES[key] = engine  # the engine holds the meshes, so these ids are not reused
    while len(_ENGINES) > ENGINE_CACHE_SIZE:
        _ENGINES.popitem(last=False)
    return engine


def trace(scene: Scene, origins, directions, tmax=np.inf) -> RayHits:
    """Intersect a batch of rays with a scene's meshes: the closest hit of each.

    Parameters
    ----------
    scene : Scene
    origins : array_like, (N, 3) or (3,)
        Ray origins, scene units.
    directions : array_like, (N, 3) or (3,)
        Ray directions (normalised here; need not be unit), broadcast against origins.
    tmax : float or array_like (N,)
        Largest distance along each ray, scene units (``inf``: unbounded).

    Returns
    -------
    RayHits
        Per ray: hit mask, distance, position, geometric and shading normal, object index,
        triangle index (within the object), barycentrics.
    """
    return ray_engine(scene).trace(origins, directions, tmax)


# ---------------------------------------------------------------------------------------
# visibility


def _offset_points(points, normals, towards, offset):
    """Move ``points`` by ``offset`` along their normals, to the side facing ``towards``."""
    if normals is None:
        return points
    normals = np.broadcast_to(np.asarray(normals, dtype=np.float64), points.shape)
    side = np.sign(np.einsum("...d,...d->...", normals, towards - points))
    side = np.where(side == 0, 1.0, side)
    length = np.linalg.norm(normals, axis=-1)
    return points + (offset * side / np.where(length > 0, length, 1.0))[..., None] * normals


def visible(scene: Scene, points_a, points_b, *, normals_a=None, normals_b=None,
            offset: float | None = None) -> np.ndarray:
    """Test whether each pair of points sees the other (nothing in between).

    Each end is first moved by ``offset`` along its normal, to the side facing the other
    point (surface points would otherwise hit their own triangle); without normals the
    ends are moved ``offset`` along the segment instead. Pairs closer than twice the
    offset count as visible.

    Parameters
    ----------
    scene : Scene
    points_a, points_b : array_like, (N, 3) or (3,)
        End points, scene units; broadcast against each other.
    normals_a, normals_b : array_like, (N, 3) or (3,), optional
        Surface normals at the end points (any length, any side).
    offset : float, optional
        Scene units; default :data:`OFFSET_FRACTION` times the diagonal of the scene's
        bounding box.

    Returns
    -------
    ndarray of bool, (N,)
        True where the segment between the (offset) end points is free. Which side of
        its surface each point faces is not tested: two points on a convex object see
        each other through its inside (form factors check the cosines themselves).
    """
    engine = ray_engine(scene)
    arrays = [np.asarray(points_a, dtype=np.float64), np.asarray(points_b, dtype=np.float64)]
    arrays += [np.asarray(n, dtype=np.float64) for n in (normals_a, normals_b) if n is not None]
    arrays = [array.reshape(-1, 3) for array in np.broadcast_arrays(*arrays)] \
        if all(array.shape[-1:] == (3,) for array in arrays) else None
    if arrays is None:
        raise InputError("points and normals must be arrays of shape (N, 3)",
                         field="points_a", value=np.shape(points_a))
    a, b = arrays[:2]
    rest = iter(arrays[2:])
    normals_a = None if normals_a is None else next(rest)
    normals_b = None if normals_b is None else next(rest)
    check_finite(a, "points_a")
    check_finite(b, "points_b")
    offset = engine.diagonal * OFFSET_FRACTION if offset is None else \
        float(check_finite(offset, "offset"))
    a_moved = _offset_points(a, normals_a, b, offset)
    b_moved = _offset_points(b, normals_b, a, offset)
    segment = b_moved - a_moved
    length = np.linalg.norm(segment, axis=1)
    close = length <= 2.0 * offset
    direction = segment / np.where(close, 1.0, length)[:, None]
    direction[close] = (0.0, 0.0, 1.0)
    # stop short of the far end too, and start a little along the segment
    start = a_moved + (offset if normals_a is None else 0.0) * direction
    reach = length - offset - (offset if normals_a is None else 0.0)
    reach = np.where(close, 0.0, np.maximum(reach, 0.0))
    # the batch is checked and its directions are unit vectors: skip occluded()'s checks
    blocked = engine.occluded_unit(start, direction,
                                   np.minimum(reach, np.finfo(np.float32).max))
    return ~blocked | close


def visibility_matrix(scene: Scene, points_a, points_b, *, normals_a=None, normals_b=None,
                      offset: float | None = None) -> np.ndarray:
    """Test every point of ``points_a`` against every point of ``points_b``.

    Parameters
    ----------
    scene : Scene
    points_a : array_like, (N, 3)
    points_b : array_like, (M, 3)
        Scene units.
    normals_a : array_like, (N, 3), optional
    normals_b : array_like, (M, 3), optional
        As in :func:`visible`.
    offset : float, optional
        As in :func:`visible`.

    Returns
    -------
    ndarray of bool, (N, M)
        Computed in blocks of about :data:`RAYS_PER_CALL` pairs.
    """
    a = np.atleast_2d(np.asarray(points_a, dtype=np.float64))
    b = np.atleast_2d(np.asarray(points_b, dtype=np.float64))
    rows_per_block = max(1, RAYS_PER_CALL // max(1, len(b)))
    out = np.zeros((len(a), len(b)), dtype=bool)
    for start in range(0, len(a), rows_per_block):
        stop = min(len(a), start + rows_per_block)
        block_normals = None if normals_a is None else \
            np.asarray(normals_a, dtype=np.float64)[start:stop, None, :]
        out[start:stop] = visible(
            scene, a[start:stop, None, :], b[None, :, :],
            normals_a=block_normals,
            normals_b=None if normals_b is None else np.asarray(normals_b)[None, :, :],
            offset=offset).reshape(stop - start, len(b))
    return out
