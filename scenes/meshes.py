"""Procedural meshes (the files they are read from and written to: :mod:`.mesh_files`).

Every generator returns a :class:`~translucent.scenes.Mesh` (or, for the Cornell box, a
dict of named parts) in scene units, with counter-clockwise faces seen from outside
(normals point out) and analytic vertex normals where the surface is smooth. Closed
meshes are watertight: flat-sided ones (box, slab) keep a separate set of vertices per
side so that each side has flat normals, and become one closed surface when coincident
vertices are merged (as ``trimesh`` does on load).

Each generator has one resolution knob, ``subdivisions`` (``frequency`` also for the
icosphere), whose vertex count is given in its docstring; :func:`mesh_with_vertices`
picks the knob that gives about the number of vertices or patches a method asks for.

Public API (stable): :func:`icosphere`, :func:`box`, :func:`slab`, :func:`plane`,
:func:`torus`, :func:`bowl`, :func:`cornell_box`, :func:`geometry_image`,
:func:`load_mesh`, :func:`rotation_matrix`, :func:`mesh_with_vertices`,
:data:`MESH_GENERATORS`.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError, check_finite
from .mesh_files import MESH_FILE_SUFFIXES, load_mesh, save_mesh
from .scene import Mesh, vector3

__all__ = [
    "MESH_GENERATORS",
    "bowl",
    "box",
    "cornell_box",
    "geometry_image",
    "icosphere",
    "load_mesh",
    "save_mesh",
    "mesh_with_vertices",
    "plane",
    "rotation_matrix",
    "slab",
    "torus",
    "CORNELL_BOX_PARTS",
    "MESH_FILE_SUFFIXES",
]

#: Largest resolution knob accepted (a guard against asking for millions of vertices by
#: mistake; 2048 segments on a box side is 25 million vertices).
MAX_SEGMENTS = 2048

#: Largest icosphere frequency (655362 vertices).
MAX_FREQUENCY = 256

#: Names of the Cornell box parts, in the order :func:`cornell_box` returns them.
CORNELL_BOX_PARTS = ("floor", "ceiling", "back_wall", "left_wall", "right_wall")


# ---------------------------------------------------------------------------------------
# argument checks


def _positive(value, field: str) -> float:
    number = float(check_finite(value, field))
    if number <= 0:
        raise InputError("must be > 0", field=field, value=value)
    return number


def _count(value, field: str, minimum: int = 1, maximum: int = MAX_SEGMENTS) -> int:
    if isinstance(value, bool) or not float(value).is_integer() \
            or not minimum <= int(value) <= maximum:
        raise InputError(f"must be an integer in [{minimum}, {maximum}]", field=field,
                         value=value)
    return int(value)


def _proportional_segments(lengths, subdivisions: int) -> list[int]:
    """Segments per edge so that cells are near square: ``subdivisions`` on the longest."""
    longest = max(lengths)
    return [max(1, round(subdivisions * length / longest)) for length in lengths]


def _oriented_outward(faces: np.ndarray, vertices: np.ndarray,
                      normals: np.ndarray) -> np.ndarray:
    """Flip faces whose winding disagrees with the analytic normals at their corners."""
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    cross = np.cross(v1 - v0, v2 - v0)
    agree = np.einsum("ij,ij->i", cross, normals[faces].sum(axis=1))
    faces = faces.copy()
    faces[agree < 0] = faces[agree < 0][:, ::-1]
    return faces


# ---------------------------------------------------------------------------------------
# spheres


def _icosahedron() -> tuple[np.ndarray, np.ndarray]:
    phi = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = np.array([
        [-1, phi, 0], [1, phi, 0], [-1, -phi, 0], [1, -phi, 0],
        [0, -1, phi], [0, 1, phi], [0, -1, -phi], [0, 1, -phi],
        [phi, 0, -1], [phi, 0, 1], [-phi, 0, -1], [-phi, 0, 1],
    ], dtype=np.float64)
    faces = np.array([
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
        [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
        [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ], dtype=np.int64)
    return vertices / np.linalg.norm(vertices, axis=1, keepdims=True), faces


def _triangle_lattice(frequency: int) -> tuple[np.ndarray, np.ndarray]:
    """Split a triangle ``frequency`` times per edge.

    Returns the integer barycentric weights (P, 3) of the lattice points and the
    (frequency^2, 3) sub-triangles as indices into them (same winding).
    """
    i, j = np.meshgrid(np.arange(frequency + 1), np.arange(frequency + 1), indexing="ij")
    keep = i + j <= frequency
    i, j = i[keep], j[keep]
    weights = np.stack([frequency - i - j, i, j], axis=1)
    index = -np.ones((frequency + 1, frequency + 1), dtype=np.int64)
    index[i, j] = np.arange(len(i))
    up_i, up_j = np.nonzero(np.add.outer(np.arange(frequency), np.arange(frequency))
                            < frequency)
    up = np.stack([index[up_i, up_j], index[up_i + 1, up_j], index[up_i, up_j + 1]], axis=1)
    down_i, down_j = np.nonzero(np.add.outer(np.arange(frequency), np.arange(frequency))
                                < frequency - 1)
    down = np.stack([index[down_i + 1, down_j], index[down_i + 1, down_j + 1],
                     index[down_i, down_j + 1]], axis=1)
    return weights, np.concatenate([up, down])


def icosphere(subdivisions: int = 3, radius: float = 1.0, center=(0.0, 0.0, 0.0), *,
              frequency: int | None = None, name: str = "icosphere") -> Mesh:
    """Build a geodesic sphere: an icosahedron with each edge split, pushed onto the sphere.

    Parameters
    ----------
    subdivisions : int
        Recursive halvings of the icosahedron's edges, in [0, 8]: ``10 * 4**n + 2``
        vertices and ``20 * 4**n`` faces (n = 4: 2562 vertices; n = 6: 40962).
    radius : float
        Scene units, > 0.
    center : (3,) array_like
        Scene units.
    frequency : int, optional
        Segments per icosahedron edge, in [1, 256]; overrides ``subdivisions`` (which is
        ``frequency = 2**subdivisions``) and gives any count ``10 f^2 + 2`` in between
        (f = 46: 21162 vertices).
    name : str

    Returns
    -------
    Mesh
        Closed, outward; vertex normals are the exact sphere normals.
    """
    radius = _positive(radius, "radius")
    center = vector3(center, "center")
    if frequency is None:
        frequency = 2 ** _count(subdivisions, "subdivisions", 0, 8)
    frequency = _count(frequency, "frequency", 1, MAX_FREQUENCY)
    corners, coarse = _icosahedron()
    weights, lattice = _triangle_lattice(frequency)
    # Each lattice point is an integer combination of icosahedron corners; points shared by
    # neighbouring faces have the same combination, which welds them exactly. The key is
    # the (corner, weight) pairs sorted by corner, with corner 12 standing for weight 0.
    corner_ids = np.broadcast_to(coarse[:, None, :], (len(coarse), len(weights), 3))
    corner_ids = np.where(weights[None] > 0, corner_ids, len(corners)).reshape(-1, 3)
    corner_weights = np.broadcast_to(weights[None], (len(coarse),) + weights.shape)
    corner_weights = corner_weights.reshape(-1, 3)
    order = np.argsort(corner_ids, axis=1)
    keys = np.stack([np.take_along_axis(corner_ids, order, 1),
                     np.take_along_axis(corner_weights, order, 1)], axis=2).reshape(-1, 6)
    unique_keys, inverse = np.unique(keys, axis=0, return_inverse=True)
    padded = np.concatenate([corners, np.zeros((1, 3))])
    directions = sum(unique_keys[:, 2 * k + 1, None] * padded[unique_keys[:, 2 * k]]
                     for k in range(3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    offsets = (np.arange(len(coarse)) * len(weights))[:, None, None]
    faces = inverse.reshape(-1)[(lattice[None, :, :] + offsets).reshape(-1, 3)]
    return Mesh(center + radius * directions, faces, directions, name=name)


# ---------------------------------------------------------------------------------------
# flat-sided meshes


def _grid_patch(origin, u_edge, v_edge, u_segments: int, v_segments: int):
    """Build a (v_segments+1) x (u_segments+1) row-major vertex grid over origin + s u + t v.

    Faces are wound so that their normal is ``cross(u_edge, v_edge)``; uv is (s, t).
    """
    s = np.linspace(0.0, 1.0, u_segments + 1)
    t = np.linspace(0.0, 1.0, v_segments + 1)
    tt, ss = np.meshgrid(t, s, indexing="ij")
    vertices = (np.asarray(origin, dtype=np.float64) + ss[..., None] * np.asarray(u_edge)
                + tt[..., None] * np.asarray(v_edge)).reshape(-1, 3)
    row, col = np.meshgrid(np.arange(v_segments), np.arange(u_segments), indexing="ij")
    a = (row * (u_segments + 1) + col).ravel()
    b, c, d = a + 1, a + u_segments + 2, a + u_segments + 1
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    uv = np.stack([ss.ravel(), tt.ravel()], axis=1)
    return vertices, faces, uv


def box(size=(1.0, 1.0, 1.0), center=(0.0, 0.0, 0.0), subdivisions: int = 1, *,
        name: str = "box") -> Mesh:
    """Build an axis-aligned box, each side a regular grid of near-square cells.

    Parameters
    ----------
    size : float or (3,) array_like
        Edge lengths along x, y, z, scene units, > 0.
    center : (3,) array_like
        Scene units.
    subdivisions : int
        Segments along the longest edge, in [1, 2048]; the other edges get proportional
        counts (at least 1). With ``(nx, ny, nz)`` segments the box has
        ``2 [(nx+1)(ny+1) + (ny+1)(nz+1) + (nz+1)(nx+1)]`` vertices (a cube with
        ``subdivisions = 60``: 22326).
    name : str

    Returns
    -------
    Mesh
        Closed and outward once coincident edge vertices are merged; each side keeps its
        own vertices, so the vertex normals are the flat side normals.
    """
    given = size
    size = np.broadcast_to(np.asarray(check_finite(size, "size")), (3,)).copy()
    if (size <= 0).any():
        raise InputError("each edge must be > 0", field="size", value=given)
    center = vector3(center, "center")
    segments = _proportional_segments(size, _count(subdivisions, "subdivisions"))
    half = size / 2.0
    parts = []
    for axis in range(3):
        u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
        for sign in (1.0, -1.0):
            u_edge = np.zeros(3)
            v_edge = np.zeros(3)
            u_edge[u_axis] = size[u_axis]
            v_edge[v_axis] = size[v_axis]
            origin = -half.copy()
            origin[axis] = sign * half[axis]
            nu, nv = segments[u_axis], segments[v_axis]
            if sign < 0:  # swap the edges so that cross(u, v) points along -axis
                u_edge, v_edge, nu, nv = v_edge, u_edge, nv, nu
            vertices, faces, _ = _grid_patch(origin, u_edge, v_edge, nu, nv)
            normal = np.zeros(3)
            normal[axis] = sign
            parts.append((vertices, faces, np.broadcast_to(normal, vertices.shape)))
    return _concatenate(parts, center, name)


def _concatenate(parts, center, name: str) -> Mesh:
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    vertices = np.concatenate([p[0] for p in parts]) + center
    faces = np.concatenate([p[1] + offset for p, offset in zip(parts, offsets, strict=True)])
    normals = np.concatenate([p[2] for p in parts])
    return Mesh(vertices, faces, normals, name=name)


def slab(width: float = 1.0, depth: float = 1.0, thickness: float = 0.1,
         center=(0.0, 0.0, 0.0), subdivisions: int = 16, *, name: str = "slab") -> Mesh:
    """Build a thick flat plate: a box ``width`` (x) by ``thickness`` (y) by ``depth`` (z).

    Its top side faces +y (where a beam from above lands).

    Parameters
    ----------
    width, depth, thickness : float
        Scene units, > 0.
    center : (3,) array_like
        The slab's centre, scene units (the top side is at ``center[1] + thickness / 2``).
    subdivisions : int
        Segments along the longer of width and depth, in [1, 2048] (see :func:`box` for
        the vertex count).
    name : str

    Returns
    -------
    Mesh
        Closed, outward (see :func:`box`).
    """
    return box((width, thickness, depth), center, subdivisions, name=name)


def plane(width: float = 1.0, depth: float = 1.0, center=(0.0, 0.0, 0.0),
          subdivisions: int = 1, *, normal: str = "+y", name: str = "plane") -> Mesh:
    """Build a one-sided axis-aligned rectangle as a regular vertex grid (a geometry image).

    Parameters
    ----------
    width, depth : float
        Extents along the first and second of the two in-plane axes (x and z for a
        normal along y; y and z for x; x and y for z), scene units, > 0.
    center : (3,) array_like
        Scene units.
    subdivisions : int
        Segments along the longer edge, in [1, 2048]: ``(n_w + 1)(n_d + 1)`` vertices.
    normal : {"+x", "-x", "+y", "-y", "+z", "-z"}
        The side it faces.
    name : str

    Returns
    -------
    Mesh
        Open; ``grid_shape`` and ``uv`` set.
    """
    axes = {"x": 0, "y": 1, "z": 2}
    if not isinstance(normal, str) or len(normal) != 2 or normal[0] not in "+-" \
            or normal[1] not in axes:
        raise InputError("must be one of +x, -x, +y, -y, +z, -z", field="normal", value=normal)
    width = _positive(width, "width")
    depth = _positive(depth, "depth")
    center = vector3(center, "center")
    axis = axes[normal[1]]
    sign = 1.0 if normal[0] == "+" else -1.0
    first, second = sorted({0, 1, 2} - {axis})
    n_width, n_depth = _proportional_segments((width, depth), _count(subdivisions,
                                                                     "subdivisions"))
    u_edge = np.zeros(3)
    v_edge = np.zeros(3)
    u_edge[first] = width
    v_edge[second] = depth
    want = np.zeros(3)
    want[axis] = sign
    nu, nv = n_width, n_depth
    if np.dot(np.cross(u_edge, v_edge), want) < 0:
        u_edge, v_edge, nu, nv = v_edge, u_edge, nv, nu
    vertices, faces, uv = _grid_patch(-(u_edge + v_edge) / 2.0, u_edge, v_edge, nu, nv)
    return Mesh(vertices + center, faces, np.broadcast_to(want, vertices.shape), uv,
                (nv + 1, nu + 1), name)


def cornell_box(size: float = 2.0, subdivisions: int = 8, *, center=(0.0, 0.0, 0.0)
                ) -> dict[str, Mesh]:
    """Build the walls, floor and ceiling of a Cornell box, open at the front (+z).

    The box spans ``x, z`` in ``[-size/2, size/2]`` and ``y`` in ``[0, size]`` around
    ``center``; every part faces into the box.

    Parameters
    ----------
    size : float
        Edge length, scene units, > 0.
    subdivisions : int
        Segments along each edge of each part, in [1, 2048]: ``(n + 1)^2`` vertices each.
    center : (3,) array_like
        The centre of the floor, scene units.

    Returns
    -------
    dict of str to Mesh
        ``floor`` (+y), ``ceiling`` (-y), ``back_wall`` (+z), ``left_wall`` (+x),
        ``right_wall`` (-x), in the order of :data:`CORNELL_BOX_PARTS`; open grids with
        ``grid_shape`` and ``uv``.
    """
    size = _positive(size, "size")
    center = vector3(center, "center")
    half = size / 2.0
    placement = {
        "floor": ((0.0, 0.0, 0.0), "+y"),
        "ceiling": ((0.0, size, 0.0), "-y"),
        "back_wall": ((0.0, half, -half), "+z"),
        "left_wall": ((-half, half, 0.0), "+x"),
        "right_wall": ((half, half, 0.0), "-x"),
    }
    return {part: plane(size, size, center + np.asarray(offset), subdivisions, normal=normal,
                        name=part)
            for part, (offset, normal) in placement.items()}


# ---------------------------------------------------------------------------------------
# surfaces of revolution


def _revolve(profile: np.ndarray, profile_normals: np.ndarray, segments: int,
             *, periodic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Revolve a (rho, y) profile about the y axis.

    A non-periodic profile must start and end on the axis (rho = 0): those two points
    become single pole vertices. Returns vertices, faces (outward by the profile normals)
    and unit normals.
    """
    angles = 2.0 * np.pi * np.arange(segments) / segments
    cos, sin = np.cos(angles), np.sin(angles)

    def ring(point):
        return np.stack([point[0] * cos, np.full(segments, point[1]), -point[0] * sin], axis=1)

    rings = profile if periodic else profile[1:-1]
    ring_normals = profile_normals if periodic else profile_normals[1:-1]
    count = len(rings)
    xyz = np.stack([ring(point) for point in rings])
    nxyz = np.stack([ring(normal) for normal in ring_normals])
    vertices = xyz.reshape(-1, 3)
    normals = nxyz.reshape(-1, 3)
    k, j = np.meshgrid(np.arange(count if periodic else count - 1), np.arange(segments),
                       indexing="ij")
    a = (k * segments + j).ravel()
    b = (k * segments + (j + 1) % segments).ravel()
    c = (((k + 1) % count) * segments + (j + 1) % segments).ravel()
    d = (((k + 1) % count) * segments + j).ravel()
    faces = [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    if not periodic:
        start, end = len(vertices), len(vertices) + 1
        vertices = np.concatenate([vertices, [[0.0, profile[0, 1], 0.0],
                                              [0.0, profile[-1, 1], 0.0]]])
        normals = np.concatenate([normals, [[0.0, profile_normals[0, 1], 0.0],
                                            [0.0, profile_normals[-1, 1], 0.0]]])
        j = np.arange(segments)
        last = (count - 1) * segments
        faces.append(np.stack([np.full(segments, start), (j + 1) % segments, j], 1))
        faces.append(np.stack([np.full(segments, end), last + j, last + (j + 1) % segments],
                              1))
    faces = np.concatenate(faces)
    return vertices, _oriented_outward(faces, vertices, normals), normals


def torus(major_radius: float = 1.0, minor_radius: float = 0.3, center=(0.0, 0.0, 0.0),
          subdivisions: int = 48, *, name: str = "torus") -> Mesh:
    """Build a ring torus around the y axis.

    Parameters
    ----------
    major_radius : float
        Distance from the centre to the tube's centre line, scene units, > minor_radius.
    minor_radius : float
        Tube radius, scene units, > 0.
    center : (3,) array_like
        Scene units.
    subdivisions : int
        Segments around the ring, in [3, 2048]; the tube gets
        ``max(3, ceil(subdivisions * minor_radius / major_radius))``: their product is the
        vertex count (``subdivisions = 256``, ratio 0.3: 19712).
    name : str

    Returns
    -------
    Mesh
        Closed, outward, exact normals; ``grid_shape = (ring, tube)`` (the grid wraps
        around in both directions) and ``uv`` in [0, 1).
    """
    major_radius = _positive(major_radius, "major_radius")
    minor_radius = _positive(minor_radius, "minor_radius")
    if minor_radius >= major_radius:
        raise InputError(f"must be < major_radius = {major_radius} (a ring torus)",
                         field="minor_radius", value=minor_radius)
    center = vector3(center, "center")
    segments = _count(subdivisions, "subdivisions", 3)
    tube = max(3, math.ceil(segments * minor_radius / major_radius))
    psi = 2.0 * np.pi * np.arange(tube) / tube
    profile_normals = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    profile = np.array([major_radius, 0.0]) + minor_radius * profile_normals
    vertices, faces, normals = _revolve(profile, profile_normals, segments, periodic=True)
    # _revolve lays rings out profile-major; reorder to (ring, tube) row-major for the grid
    order = np.arange(len(vertices)).reshape(tube, segments).T.ravel()
    inverse = np.empty_like(order)
    inverse[order] = np.arange(len(order))
    uv = np.stack(np.meshgrid(np.arange(segments) / segments, np.arange(tube) / tube,
                              indexing="ij"), axis=-1).reshape(-1, 2)
    return Mesh(vertices[order] + center, inverse[faces], normals[order], uv,
                (segments, tube), name)


def bowl(radius: float = 1.0, thickness: float = 0.15, center=(0.0, 0.0, 0.0),
         subdivisions: int = 48, *, name: str = "bowl") -> Mesh:
    """Build a thick hemispherical bowl opening upwards (+y), with a rounded rim.

    The outer surface is the lower hemisphere of ``radius`` about ``center``, the inner
    one of ``radius - thickness``; a half-round lip of diameter ``thickness`` joins them,
    its top at ``center[1] + thickness / 2``. One smooth closed surface of revolution, so
    the vertex normals are exact everywhere.

    Parameters
    ----------
    radius : float
        Outer radius, scene units, > 0.
    thickness : float
        Wall thickness, scene units, in (0, radius).
    center : (3,) array_like
        Centre of the hemispheres, scene units.
    subdivisions : int
        Segments around the y axis, in [3, 2048]; the profile is split into near-square
        cells, giving about ``subdivisions^2 / 2`` vertices for a thin wall
        (``subdivisions = 210``, thickness 0.15: 22052).
    name : str

    Returns
    -------
    Mesh
        Closed, outward (into the cavity on the inside), concave.
    """
    radius = _positive(radius, "radius")
    thickness = _positive(thickness, "thickness")
    if thickness >= radius:
        raise InputError(f"must be < radius = {radius}", field="thickness", value=thickness)
    center = vector3(center, "center")
    segments = _count(subdivisions, "subdivisions", 3)
    inner = radius - thickness
    lip = thickness / 2.0
    spacing = 2.0 * np.pi * radius / segments

    def arc(length):
        return max(2, math.ceil(length / spacing))

    theta_out = np.linspace(0.0, np.pi / 2, arc(radius * np.pi / 2) + 1)
    phi = np.linspace(0.0, np.pi, arc(lip * np.pi) + 1)[1:-1]
    theta_in = np.linspace(np.pi / 2, 0.0, arc(inner * np.pi / 2) + 1)
    outward = np.stack([np.sin(theta_out), -np.cos(theta_out)], axis=1)
    lip_normal = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    inward = np.stack([np.sin(theta_in), -np.cos(theta_in)], axis=1)
    profile = np.concatenate([radius * outward, np.array([radius - lip, 0.0]) + lip * lip_normal,
                              inner * inward])
    normals = np.concatenate([outward, lip_normal, -inward])
    vertices, faces, vertex_normals = _revolve(profile, normals, segments, periodic=False)
    return Mesh(vertices + center, faces, vertex_normals, name=name)


# ---------------------------------------------------------------------------------------
# geometry images


def geometry_image(rows: int = 65, cols: int | None = None, shape: str = "sphere",
                   radius: float = 1.0, center=(0.0, 0.0, 0.0), *, width: float = 2.0,
                   depth: float = 2.0, bend: float = 90.0, name: str = "geometry_image"
                   ) -> Mesh:
    """Build a surface stored as a regular ``rows x cols`` vertex grid (a geometry image).

    ``shape = "sphere"``: the octahedral spherical parameterisation (the square folded
    onto an octahedron whose faces are pushed onto the sphere); the square's border is
    mirrored onto itself, so border vertices appear twice, as in any spherical geometry
    image. Quads are split along the octahedron's edges, so no triangle straddles a fold.
    ``shape = "sheet"``: a ``width x depth`` sheet bent about the z axis through
    ``bend`` degrees (0: flat) into part of a cylinder, facing +y.

    Parameters
    ----------
    rows, cols : int
        Grid size, in [2, 4097] (the sphere needs ``rows = cols`` and odd, >= 3; ``cols``
        defaults to ``rows``): ``rows * cols`` vertices (151 x 151: 22801).
    shape : {"sphere", "sheet"}
    radius : float
        Sphere radius, scene units, > 0.
    center : (3,) array_like
        Scene units.
    width, depth : float
        Sheet extents (arc length along x, straight along z), scene units, > 0.
    bend : float
        Sheet bend, degrees in [0, 360).
    name : str

    Returns
    -------
    Mesh
        ``grid_shape = (rows, cols)``, ``uv`` = (column, row) / (cols - 1, rows - 1).
    """
    rows = _count(rows, "rows", 2, 4097)
    cols = rows if cols is None else _count(cols, "cols", 2, 4097)
    center = vector3(center, "center")
    v, u = np.meshgrid(np.linspace(0.0, 1.0, rows), np.linspace(0.0, 1.0, cols),
                       indexing="ij")
    uv = np.stack([u.ravel(), v.ravel()], axis=1)
    row, col = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
    a = (row * cols + col).ravel()
    b, c, d = a + 1, a + cols + 1, a + cols
    if shape == "sphere":
        if rows != cols or rows % 2 == 0 or rows < 3:
            raise InputError("the sphere geometry image needs rows = cols, odd and >= 3",
                             field="rows", value=(rows, cols))
        radius = _positive(radius, "radius")
        s, t = 2.0 * uv[:, 0] - 1.0, 2.0 * uv[:, 1] - 1.0
        z = 1.0 - np.abs(s) - np.abs(t)
        fold = z < 0
        x = np.where(fold, np.sign(s) * (1.0 - np.abs(t)), s)
        y = np.where(fold, np.sign(t) * (1.0 - np.abs(s)), t)
        directions = np.stack([x, z, -y], axis=1)  # the square's centre is the +y pole
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        # split each cell along the octahedron edge through it (slope -1 where s t > 0)
        cell_s = (2.0 * (col.ravel() + 0.5) / (cols - 1)) - 1.0
        cell_t = (2.0 * (row.ravel() + 0.5) / (rows - 1)) - 1.0
        anti = cell_s * cell_t > 0
        faces = np.concatenate([
            np.where(anti[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1)),
            np.where(anti[:, None], np.stack([b, c, d], 1), np.stack([a, c, d], 1)),
        ])
        faces = _oriented_outward(faces, directions, directions)
        return Mesh(center + radius * directions, faces, directions, uv, (rows, cols), name)
    if shape == "sheet":
        width = _positive(width, "width")
        depth = _positive(depth, "depth")
        angle = float(check_finite(bend, "bend"))
        if not 0.0 <= angle < 360.0:
            raise InputError("must be in [0, 360) degrees", field="bend", value=bend)
        arc = (uv[:, 0] - 0.5) * width
        along = (uv[:, 1] - 0.5) * depth
        if angle == 0.0:
            positions = np.stack([arc, np.zeros_like(arc), along], axis=1)
            normals = np.broadcast_to([0.0, 1.0, 0.0], positions.shape)
        else:
            bend_radius = width / math.radians(angle)
            theta = arc / bend_radius
            normals = np.stack([np.sin(theta), np.cos(theta), np.zeros_like(theta)], axis=1)
            positions = bend_radius * normals - [0.0, bend_radius, 0.0]
            positions[:, 2] = along
        faces = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])
        faces = _oriented_outward(faces, positions, normals)
        return Mesh(positions + center, faces, normals, uv, (rows, cols), name)
    raise InputError("unknown geometry image shape; valid: sphere, sheet", field="shape",
                     value=shape)


# ---------------------------------------------------------------------------------------
# files, transforms, resolution


def rotation_matrix(degrees) -> np.ndarray:
    """Rotation about x, then y, then z (fixed axes), angles in degrees; (3, 3) float64."""
    rx, ry, rz = np.radians(vector3(degrees, "rotate"))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), \
        np.sin(rz)
    about_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    about_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    about_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return about_z @ about_y @ about_x


#: name -> generator, the ``type`` of a procedural mesh in a scene file
MESH_GENERATORS = {
    "icosphere": icosphere,
    "box": box,
    "slab": slab,
    "plane": plane,
    "torus": torus,
    "bowl": bowl,
    "geometry_image": geometry_image,
}

#: the knob :func:`mesh_with_vertices` turns for each generator, and its search range
_RESOLUTION_KNOB = {
    "icosphere": ("frequency", 1, MAX_FREQUENCY),
    "box": ("subdivisions", 1, MAX_SEGMENTS),
    "slab": ("subdivisions", 1, MAX_SEGMENTS),
    "plane": ("subdivisions", 1, MAX_SEGMENTS),
    "torus": ("subdivisions", 3, MAX_SEGMENTS),
    "bowl": ("subdivisions", 3, MAX_SEGMENTS),
    "geometry_image": ("rows", 3, 4097),
}


def mesh_with_vertices(kind: str, vertices: int, **params) -> Mesh:
    """Build the mesh of generator ``kind`` whose vertex count is closest to ``vertices``.

    Searches the generator's resolution knob (``frequency`` for the icosphere,
    ``rows = cols`` for geometry images, ``subdivisions`` otherwise) by bisection; the
    other parameters are passed through.

    Parameters
    ----------
    kind : str
        A key of :data:`MESH_GENERATORS`.
    vertices : int
        Wanted vertex count, >= 1 (for example 20000 for a method's patch budget).
    **params
        Other arguments of the generator (``radius``, ``center``, ...).

    Returns
    -------
    Mesh
    """
    if kind not in _RESOLUTION_KNOB:
        raise InputError(f"unknown mesh type; valid: {', '.join(MESH_GENERATORS)}",
                         field="kind", value=kind)
    target = _count(vertices, "vertices", 1, 10**8)
    knob, low, limit = _RESOLUTION_KNOB[kind]
    generator = MESH_GENERATORS[kind]

    def build(value):
        if kind == "geometry_image":
            if params.get("shape", "sphere") == "sphere" and value % 2 == 0:
                value += 1
            return generator(**{**params, "rows": value, "cols": value})
        return generator(**{**params, knob: value})

    # grow until the count reaches the target, then bisect: never build far past it
    high = low
    while high < limit and len(build(high).vertices) < target:
        low, high = high, min(limit, 2 * high)
    while high - low > 1:  # invariant: build(low) is short of the target, build(high) not
        middle = (low + high) // 2
        if len(build(middle).vertices) < target:
            low = middle
        else:
            high = middle
    candidates = [build(low), build(high)]
    return min(candidates, key=lambda mesh: abs(len(mesh.vertices) - target))
