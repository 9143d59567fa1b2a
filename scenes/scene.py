"""Where things are: meshes, objects, lights, the camera and the scene that holds them.

Positions are in scene units; ``Scene.mm_per_unit`` converts to the mm of the materials.
Every type is immutable and validated on construction: bad input raises
:class:`~translucent.errors.InputError` naming the field and value.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from ..errors import InputError, check_finite
from ..materials.homogeneous import rgb_field

__all__ = [
    "Mesh",
    "SceneObject",
    "PointLight",
    "SpotLight",
    "DirectionalLight",
    "RectangularAreaLight",
    "SphereAreaLight",
    "ConstantEnvironment",
    "ImageEnvironment",
    "Light",
    "Camera",
    "Scene",
    "moved_lights",
    "vector3",
]

#: A face whose area is below this fraction of the mesh's mean face area squared-length
#: scale is degenerate (collinear or repeated vertices).
DEGENERATE_AREA_FRACTION = 1e-12

#: The largest vertex coordinate a mesh may have: the renderers hold positions as float32,
#: and a larger one would become infinite there.
FLOAT32_MAX = float(np.finfo(np.float32).max)

#: Vertex normals within this of unit length are kept as given (normalising them again
#: would change their last bits); others are normalised.
UNIT_NORMAL_TOLERANCE = 1e-12


def vector3(value, field_name: str, *, unit: bool = False, file=None) -> np.ndarray:
    """Validate a finite 3-vector (normalised when ``unit``) and return it read-only."""
    try:
        array = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):  # text, ragged lists, huge integers
        array = None
    if array is None or array.shape != (3,):
        raise InputError("must be a 3-vector [x, y, z] of numbers", file=file, field=field_name,
                         value=value)
    check_finite(array, field_name, file=file)
    if unit:
        length = np.linalg.norm(array)
        if length == 0:
            raise InputError("must be a non-zero direction", file=file, field=field_name,
                             value=value)
        array = array / length
    array = array.copy()
    array.flags.writeable = False
    return array


def _readonly(array: np.ndarray) -> np.ndarray:
    array = np.ascontiguousarray(array)
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh.

    Parameters
    ----------
    vertices : ndarray, shape (V, 3), float64
        Positions in scene units.
    faces : ndarray, shape (F, 3), int64
        Vertex indices, counter-clockwise seen from outside (normals point out).
    normals : ndarray, shape (V, 3), optional
        Unit vertex normals; area-weighted face normals when omitted.
    uv : ndarray, shape (V, 2), optional
        Texture coordinates in [0, 1] (SubEdit textures, geometry images).
    grid_shape : tuple of int, optional
        ``(rows, cols)`` when the vertices are a regular grid in row-major order (a
        geometry image: its square parameterisation is used for spatial compression).
    name : str
        Label used in error messages.

    Raises
    ------
    InputError
        Non-finite vertices or ones beyond float32's range (:data:`FLOAT32_MAX`), indices
        out of range, or zero-area (degenerate) faces.
    """

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray | None = None
    uv: np.ndarray | None = None
    grid_shape: tuple[int, int] | None = None
    name: str = "mesh"

    def __post_init__(self):
        vertices = np.asarray(self.vertices, dtype=np.float64)
        faces = np.asarray(self.faces)
        where = f"mesh '{self.name}'"
        if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 3:
            raise InputError("must be an array of shape (V >= 3, 3)", file=where,
                             field="vertices", value=vertices.shape)
        bad = ~np.isfinite(vertices).all(axis=1)
        if bad.any():
            index = int(np.flatnonzero(bad)[0])
            raise InputError(f"{int(bad.sum())} vertices are NaN or Inf (first: vertex {index})",
                             file=where, field=f"vertices[{index}]", value=vertices[index].tolist())
        beyond = (np.abs(vertices) > FLOAT32_MAX).any(axis=1)
        if beyond.any():
            index = int(np.flatnonzero(beyond)[0])
            raise InputError(f"{int(beyond.sum())} vertices are beyond float32's range "
                             f"(+-{FLOAT32_MAX:.7g}), where the renderers hold positions "
                             f"(first: vertex {index})", file=where, field=f"vertices[{index}]",
                             value=vertices[index].tolist())
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise InputError("must be an array of shape (F >= 1, 3)", file=where,
                             field="faces", value=faces.shape)
        if not np.issubdtype(faces.dtype, np.integer):
            raise InputError("indices must be integers", file=where, field="faces",
                             value=str(faces.dtype))
        faces = faces.astype(np.int64)
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise InputError(f"indices must lie in [0, {len(vertices) - 1}]", file=where,
                             field="faces", value=[int(faces.min()), int(faces.max())])
        cross = self._face_cross(vertices, faces)
        doubled_area = np.linalg.norm(cross, axis=1)
        scale = np.ptp(vertices, axis=0).max() ** 2
        degenerate = doubled_area <= DEGENERATE_AREA_FRACTION * max(scale, 1e-300)
        if degenerate.any():
            index = int(np.flatnonzero(degenerate)[0])
            raise InputError(f"{int(degenerate.sum())} faces have zero area (first: face "
                             f"{index})", file=where, field=f"faces[{index}]",
                             value=faces[index].tolist())
        if self.normals is None:
            normals = np.zeros_like(vertices)
            for corner in range(3):
                np.add.at(normals, faces[:, corner], cross)
        else:
            normals = np.asarray(self.normals, dtype=np.float64)
            if normals.shape != vertices.shape:
                raise InputError(f"must have the shape of vertices {vertices.shape}", file=where,
                                 field="normals", value=normals.shape)
            check_finite(normals, "normals", file=where)
        length = np.linalg.norm(normals, axis=1, keepdims=True)
        # leave unit normals bit for bit as given, so that a saved mesh loads back identical
        unit = np.abs(length - 1.0) <= UNIT_NORMAL_TOLERANCE
        normals = np.where(unit, normals,
                           np.where(length > 0, normals / np.where(length > 0, length, 1.0),
                                    [0, 0, 1.0]))
        if self.uv is not None:
            uv = np.asarray(self.uv, dtype=np.float64)
            if uv.shape != (len(vertices), 2):
                raise InputError(f"must have shape ({len(vertices)}, 2)", file=where, field="uv",
                                 value=uv.shape)
            check_finite(uv, "uv", file=where)
            object.__setattr__(self, "uv", _readonly(uv))
        if self.grid_shape is not None:
            rows, cols = (int(n) for n in self.grid_shape)
            if rows * cols != len(vertices):
                raise InputError(f"rows x cols must equal the vertex count {len(vertices)}",
                                 file=where, field="grid_shape", value=self.grid_shape)
            object.__setattr__(self, "grid_shape", (rows, cols))
        object.__setattr__(self, "vertices", _readonly(vertices))
        object.__setattr__(self, "faces", _readonly(faces))
        object.__setattr__(self, "normals", _readonly(normals))

    @staticmethod
    def _face_cross(vertices, faces):
        v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
        return np.cross(v1 - v0, v2 - v0)

    @property
    def face_areas(self) -> np.ndarray:
        """Triangle areas in scene units squared, shape (F,)."""
        return 0.5 * np.linalg.norm(self._face_cross(self.vertices, self.faces), axis=1)

    @property
    def face_normals(self) -> np.ndarray:
        """Unit face normals, shape (F, 3)."""
        cross = self._face_cross(self.vertices, self.faces)
        return cross / np.linalg.norm(cross, axis=1, keepdims=True)

    @property
    def face_centroids(self) -> np.ndarray:
        """Triangle centroids in scene units, shape (F, 3)."""
        return self.vertices[self.faces].mean(axis=1)

    @property
    def area(self) -> float:
        """Total surface area in scene units squared."""
        return float(self.face_areas.sum())

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box ``(lower, upper)`` in scene units."""
        return self.vertices.min(axis=0), self.vertices.max(axis=0)

    def transformed(self, matrix=None, *, translate=(0, 0, 0), scale=1.0) -> Mesh:
        """Return a copy moved by a 3x3 ``matrix``, then scaled by ``scale``, then translated."""
        linear = np.eye(3) if matrix is None else np.asarray(matrix, dtype=np.float64)
        linear = linear * float(scale)
        vertices = self.vertices @ linear.T + np.asarray(translate, dtype=np.float64)
        normals = self.normals @ np.linalg.inv(linear)
        return Mesh(vertices, self.faces, normals, self.uv, self.grid_shape, self.name)

    def cache_key(self) -> dict:
        """Return what identifies this mesh in content hashes."""
        return {"vertices": self.vertices, "faces": self.faces, "normals": self.normals,
                "uv": self.uv, "grid_shape": self.grid_shape}


@dataclass(frozen=True, eq=False)
class SceneObject:
    """A named mesh with a material.

    ``material`` is a :class:`~translucent.materials.Dipole` (homogeneous translucent), a
    :class:`~translucent.materials.Lambertian` (opaque diffuse), an analytic BRDF or a
    heterogeneous SubEdit material (see :mod:`translucent.materials`).
    """

    name: str
    mesh: Mesh
    material: Any

    def cache_key(self) -> dict:
        """Return what identifies this object in content hashes."""
        material_key = self.material.cache_key() if hasattr(self.material, "cache_key") \
            else repr(self.material)
        return {"name": self.name, "mesh": self.mesh.cache_key(), "material": material_key}


@dataclass(frozen=True)
class PointLight:
    """An isotropic point light.

    Parameters
    ----------
    position : (3,) scene units
    intensity : float or RGB, W sr^-1 (radiant intensity)
    """

    position: np.ndarray
    intensity: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "position", vector3(self.position, "position"))
        object.__setattr__(self, "intensity", rgb_field(self.intensity, "intensity"))


@dataclass(frozen=True)
class SpotLight:
    """A spot light: a point light restricted to a cone.

    Parameters
    ----------
    position : (3,) scene units
    direction : (3,) unit vector, the cone axis
    intensity : float or RGB, W sr^-1 on the axis
    cutoff_angle : float, degrees in (0, 90], the cone half-angle
    beam_width : float, degrees in (0, cutoff_angle], where the fall-off begins
    """

    position: np.ndarray
    direction: np.ndarray
    intensity: np.ndarray
    cutoff_angle: float = 20.0
    beam_width: float | None = None

    def __post_init__(self):
        object.__setattr__(self, "position", vector3(self.position, "position"))
        object.__setattr__(self, "direction", vector3(self.direction, "direction", unit=True))
        object.__setattr__(self, "intensity", rgb_field(self.intensity, "intensity"))
        cutoff = float(check_finite(self.cutoff_angle, "cutoff_angle"))
        if not 0 < cutoff <= 90:
            raise InputError("must be in (0, 90] degrees", field="cutoff_angle",
                             value=self.cutoff_angle)
        width = cutoff * 0.75 if self.beam_width is None else float(self.beam_width)
        if not 0 < width <= cutoff:
            raise InputError(f"must be in (0, cutoff_angle = {cutoff}] degrees",
                             field="beam_width", value=self.beam_width)
        object.__setattr__(self, "cutoff_angle", cutoff)
        object.__setattr__(self, "beam_width", width)

    def falloff(self, directions) -> np.ndarray:
        """Mitsuba's ``spot`` profile: 1 inside the beam, linear in angle to 0 at the cutoff.

        Parameters
        ----------
        directions : (..., 3) unit vectors leaving the light

        Returns
        -------
        ndarray, shape (...)
            Intensity relative to the axis, in [0, 1].
        """
        cos_theta = np.clip(np.asarray(directions) @ self.direction, -1.0, 1.0)
        angle = np.degrees(np.arccos(cos_theta))
        ramp = (self.cutoff_angle - angle) / max(self.cutoff_angle - self.beam_width, 1e-12)
        return np.where(angle <= self.beam_width, 1.0,
                        np.where(angle < self.cutoff_angle, ramp, 0.0))


@dataclass(frozen=True)
class DirectionalLight:
    """A distant light.

    Parameters
    ----------
    direction : (3,) unit vector along which the light travels
    irradiance : float or RGB, W m^-2 on a surface facing the light
    """

    direction: np.ndarray
    irradiance: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "direction", vector3(self.direction, "direction", unit=True))
        object.__setattr__(self, "irradiance", rgb_field(self.irradiance, "irradiance"))


@dataclass(frozen=True)
class RectangularAreaLight:
    """A one-sided rectangular emitter.

    Parameters
    ----------
    center : (3,) scene units
    u_axis, v_axis : (3,) scene units; half-edge vectors: corners at center +- u +- v;
        it emits towards ``cross(u_axis, v_axis)``
    radiance : float or RGB, W sr^-1 m^-2
    """

    center: np.ndarray
    u_axis: np.ndarray
    v_axis: np.ndarray
    radiance: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "center", vector3(self.center, "center"))
        object.__setattr__(self, "u_axis", vector3(self.u_axis, "u_axis"))
        object.__setattr__(self, "v_axis", vector3(self.v_axis, "v_axis"))
        if np.linalg.norm(np.cross(self.u_axis, self.v_axis)) == 0:
            raise InputError("u_axis and v_axis must span a rectangle", field="v_axis",
                             value=self.v_axis.tolist())
        object.__setattr__(self, "radiance", rgb_field(self.radiance, "radiance"))

    @property
    def normal(self) -> np.ndarray:
        """Unit emission direction."""
        n = np.cross(self.u_axis, self.v_axis)
        return n / np.linalg.norm(n)

    @property
    def area(self) -> float:
        """Area in scene units squared."""
        return float(4.0 * np.linalg.norm(np.cross(self.u_axis, self.v_axis)))


@dataclass(frozen=True)
class SphereAreaLight:
    """A spherical emitter of uniform radiance.

    Parameters
    ----------
    center : (3,) scene units
    radius : float, scene units, > 0
    radiance : float or RGB, W sr^-1 m^-2
    """

    center: np.ndarray
    radius: float
    radiance: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "center", vector3(self.center, "center"))
        radius = float(check_finite(self.radius, "radius"))
        if radius <= 0:
            raise InputError("must be > 0", field="radius", value=self.radius)
        object.__setattr__(self, "radius", radius)
        object.__setattr__(self, "radiance", rgb_field(self.radiance, "radiance"))


@dataclass(frozen=True)
class ConstantEnvironment:
    """Uniform radiance from every direction (W sr^-1 m^-2, float or RGB)."""

    radiance: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "radiance", rgb_field(self.radiance, "radiance"))


@dataclass(frozen=True, eq=False)
class ImageEnvironment:
    """Image-based environment lighting in the latitude-longitude layout Mitsuba uses.

    Parameters
    ----------
    radiance : ndarray, shape (H >= 3, W, 3), W sr^-1 m^-2, or a path to an EXR
    scale : float, >= 0, multiplies the radiance
    """

    radiance: Any
    scale: float = 1.0

    def __post_init__(self):
        value = self.radiance
        if not isinstance(value, np.ndarray):
            from ..image import read_exr

            value = read_exr(value).rgb
        value = np.asarray(value, dtype=np.float32)
        if value.ndim != 3 or value.shape[2] != 3:
            raise InputError("must be an H x W x 3 radiance map", field="radiance",
                             value=value.shape)
        if value.shape[0] < 3 or value.shape[1] < 1:
            # Mitsuba's envmap puts row i at polar angle pi i / (H - 1): one row has no
            # angle, and a map of two rows it interpolates otherwise (measured: as if row 1
            # were at pi / 2), so the fast methods could not see the reference's light
            raise InputError("must have at least 3 rows (the poles and one between) and 1 "
                             "column", field="radiance", value=value.shape)
        check_finite(value, "radiance")
        if (value < 0).any():
            raise InputError("radiance must be >= 0", field="radiance", value=float(value.min()))
        scale = float(check_finite(self.scale, "scale"))
        if scale < 0:
            raise InputError("must be >= 0 (it multiplies the radiance)", field="scale",
                             value=self.scale)
        object.__setattr__(self, "radiance", _readonly(value))
        object.__setattr__(self, "scale", scale)


Light = Union[PointLight, SpotLight, DirectionalLight, RectangularAreaLight, SphereAreaLight,
              ConstantEnvironment, ImageEnvironment]


@dataclass(frozen=True)
class Camera:
    """A pinhole perspective camera.

    Parameters
    ----------
    origin, target : (3,) scene units
    up : (3,) direction
    fov : float, horizontal field of view in degrees, in (0, 180)
    width, height : int, pixels
    """

    origin: np.ndarray
    target: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    fov: float = 40.0
    width: int = 128
    height: int = 128

    def __post_init__(self):
        object.__setattr__(self, "origin", vector3(self.origin, "camera.origin"))
        object.__setattr__(self, "target", vector3(self.target, "camera.target"))
        object.__setattr__(self, "up", vector3(self.up, "camera.up", unit=True))
        if np.allclose(self.origin, self.target):
            raise InputError("camera looks nowhere: target equals origin", field="camera.target",
                             value=self.target.tolist())
        forward = self.forward
        if np.linalg.norm(np.cross(forward, self.up)) < 1e-9:
            raise InputError("camera.up must not be parallel to the viewing direction",
                             field="camera.up", value=self.up.tolist())
        fov = check_finite(self.fov, "camera.fov")
        if fov.shape != () or not 0 < float(fov) < 180:
            raise InputError("must be in (0, 180) degrees", field="camera.fov",
                             value=self.fov)
        object.__setattr__(self, "fov", float(fov))
        for name in ("width", "height"):
            value = getattr(self, name)
            # compared before any conversion: an integer of hundreds of digits is no float
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)) \
                    or not 1 <= value <= 16384 or int(value) != value:
                raise InputError("must be an integer in [1, 16384]", field=f"camera.{name}",
                                 value=value)
            object.__setattr__(self, name, int(value))

    @property
    def forward(self) -> np.ndarray:
        """Unit viewing direction."""
        d = self.target - self.origin
        return d / np.linalg.norm(d)

    def cache_key(self) -> dict:
        """Return what identifies this camera in content hashes."""
        return {"origin": self.origin.tolist(), "target": self.target.tolist(),
                "up": self.up.tolist(), "fov": self.fov, "width": self.width,
                "height": self.height}


def _light_key(light) -> dict:
    out = {"type": type(light).__name__}
    for name, value in vars(light).items():
        out[name] = value.tolist() if isinstance(value, np.ndarray) and value.size <= 16 else value
    return out


@dataclass(frozen=True, eq=False)
class Scene:
    """Objects, lights and a camera.

    Parameters
    ----------
    objects : tuple of SceneObject
    lights : tuple of Light
    camera : Camera
    mm_per_unit : float
        Millimetres per scene unit (> 0): material coefficients (mm^-1) meet geometry here.
    name : str
    description : str
        One line for ``translucent scenes``.
    source : str, optional
        The file the scene was loaded from (error messages).
    """

    objects: tuple
    lights: tuple
    camera: Camera
    mm_per_unit: float = 1.0
    name: str = "scene"
    description: str = ""
    source: str | None = None

    def __post_init__(self):
        object.__setattr__(self, "objects", tuple(self.objects))
        object.__setattr__(self, "lights", tuple(self.lights))
        if not self.objects:
            raise InputError("a scene needs at least one object", file=self.source,
                             field="objects", value=[])
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise InputError("object names must be unique", file=self.source, field="objects",
                             value=names)
        mm = float(check_finite(self.mm_per_unit, "mm_per_unit", file=self.source))
        if mm <= 0:
            raise InputError("must be > 0", file=self.source, field="mm_per_unit",
                             value=self.mm_per_unit)
        object.__setattr__(self, "mm_per_unit", mm)
        for index, obj in enumerate(self.objects):
            covers = getattr(obj.material, "check_covers", None)
            if covers is not None:  # a medium defined over a box (materials.solid)
                covers(obj.mesh.vertices, file=self.source,
                       field=f"objects[{index}].material.bounds")

    def object(self, name: str) -> SceneObject:
        """Return the object called ``name``; an unknown name lists the valid ones."""
        for candidate in self.objects:
            if candidate.name == name:
                return candidate
        raise InputError(f"no such object; objects: {', '.join(o.name for o in self.objects)}",
                         file=self.source, field="object", value=name)

    def with_lights(self, lights) -> Scene:
        """Return a copy with other lights (the camera and objects unchanged)."""
        return Scene(self.objects, tuple(lights), self.camera, self.mm_per_unit, self.name,
                     self.description, self.source)

    def with_material(self, object_name: str, material) -> Scene:
        """Return a copy in which object ``object_name`` has ``material``."""
        self.object(object_name)
        objects = tuple(SceneObject(o.name, o.mesh, material) if o.name == object_name else o
                        for o in self.objects)
        return Scene(objects, self.lights, self.camera, self.mm_per_unit, self.name,
                     self.description, self.source)

    def with_camera(self, camera: Camera) -> Scene:
        """Return a copy seen through ``camera``."""
        return Scene(self.objects, self.lights, camera, self.mm_per_unit, self.name,
                     self.description, self.source)

    def cache_key(self) -> dict:
        """Return what identifies this scene in content hashes (all but name and source)."""
        return {"objects": [o.cache_key() for o in self.objects],
                "lights": [_light_key(light) for light in self.lights],
                "camera": self.camera.cache_key(), "mm_per_unit": self.mm_per_unit}

    def geometry_key(self) -> dict:
        """Geometry alone (no lights, no materials): what precomputations depend on."""
        return {"meshes": [o.mesh.cache_key() for o in self.objects],
                "mm_per_unit": self.mm_per_unit}


def moved_lights(lights, offset: float) -> list:
    """Return ``lights`` moved by ``offset``: new lights, the same kind and power.

    Positions and centres move ``offset`` scene units along x; directions turn by about
    ``offset`` radians about the axis they are least aligned with; environments stay as
    they are (nothing to move). Used to relight without changing what is lit.

    Examples
    --------
    >>> [light.position.tolist() for light in moved_lights([PointLight([0, 1, 2], 1.0)], 0.5)]
    [[0.5, 1.0, 2.0]]
    """
    from dataclasses import replace

    moved = []
    for light in lights:
        if hasattr(light, "position"):
            light = replace(light, position=light.position + [offset, 0.0, 0.0])
        elif hasattr(light, "center"):
            light = replace(light, center=light.center + [offset, 0.0, 0.0])
        elif hasattr(light, "direction"):
            axis = np.eye(3)[int(np.argmin(np.abs(light.direction)))]
            turned = light.direction + offset * axis
            light = replace(light, direction=turned / np.linalg.norm(turned))
        moved.append(light)
    return moved
