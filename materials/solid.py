r"""Solid heterogeneous media: coefficients that vary in space over an object's volume.

A :class:`SolidMedium` is the physical counterpart of a SubEdit texture (Chen et al. 2012)
and of radiosity's labelled faces (Sheng et al. 2014, Eq. 16): a voxel grid of absorption
:math:`\sigma_a(x)` and reduced scattering :math:`\sigma'_s(x)` (mm^-1, RGB) over a box in
scene units, with one boundary index ``eta`` for the object. The grid *is* the medium:
a point takes the value of the voxel it lies in (nearest lookup, voxel ``i`` of ``N``
covering ``[i/N, (i+1)/N)`` of the box along its axis), exactly as Mitsuba's
``gridvolume`` with ``filter_type = "nearest"`` reads it, so the volumetric reference and
the fast methods' derived inputs see the same medium.

Procedural fields are sampled onto that grid when they are built, at a resolution that
resolves their finest feature: a 3D checker of two media (one voxel per cell, exact),
veins of a second medium in a base from 3D turbulence, a gradient, a uniform medium (the
homogeneous limit). A grid can also be loaded from a ``.npz`` file
(docs/solid-format.md).

The coefficients are reduced ones (:math:`g = 0`), as in the measured table of Jensen et
al. 2001: the path tracer scatters isotropically with :math:`\sigma_s = \sigma'_s`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..atomic import atomic_path
from ..errors import InputError, check_count, check_finite
from .catalogue import measured_medium
from .homogeneous import Dipole

__all__ = [
    "SolidMedium",
    "MediaQuantisation",
    "SOLID_FIELDS",
    "DEFAULT_BOUNDS",
    "solid_from_spec",
    "load_solid",
    "save_solid",
    "uniform_solid",
    "checker_solid",
    "veined_solid",
    "gradient_solid",
    "quantise_media",
]

FORMAT_NAME = "translucent-solid-medium"
FORMAT_VERSION = 1

#: The box a procedural field fills when the scene file gives none: the unit cube about
#: the origin, which holds the catalogue's unit spheres.
DEFAULT_BOUNDS = ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))

#: Largest number of voxels a grid may hold (a 256^3 grid of 2 x RGB float64 is 800 MB).
MAX_VOXELS = 256 ** 3

#: A vertex may lie this far outside the box (relative to its diagonal) and count as in:
#: the mesh's floating-point surface on a box drawn to touch it.
COVER_TOLERANCE = 1e-9


def _bounds(value, *, file=None, field: str = "bounds") -> np.ndarray:
    box = check_finite(value, field, file=file)
    if box.shape != (2, 3):
        raise InputError("must be [[x_min, y_min, z_min], [x_max, y_max, z_max]] in scene "
                         "units", file=file, field=field, value=np.asarray(value).tolist())
    if not np.all(box[1] > box[0]):
        raise InputError("each maximum must exceed its minimum", file=file, field=field,
                         value=box.tolist())
    box = box.copy()
    box.flags.writeable = False
    return box


def _coefficient_grid(value, field: str, *, file=None) -> np.ndarray:
    grid = np.asarray(value, dtype=np.float64)
    if grid.ndim != 4 or grid.shape[3] != 3 or min(grid.shape[:3]) < 1:
        raise InputError("must have shape (Z, Y, X, 3): RGB per voxel", file=file,
                         field=field, value=grid.shape)
    if grid.shape[0] * grid.shape[1] * grid.shape[2] > MAX_VOXELS:
        raise InputError(f"more than {MAX_VOXELS} voxels", file=file, field=field,
                         value=grid.shape)
    bad = ~np.isfinite(grid)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise InputError(f"must be finite; voxel (z, y, x, channel) = {where} holds "
                         f"{grid[where]}", file=file, field=field, value=float(grid[where]))
    if (grid < 0).any():
        where = tuple(int(i) for i in np.argwhere(grid < 0)[0])
        raise InputError(f"must be >= 0 mm^-1; voxel (z, y, x, channel) = {where}",
                         file=file, field=field, value=float(grid[where]))
    grid = grid.copy()
    grid.flags.writeable = False
    return grid


@dataclass(frozen=True, eq=False)
class SolidMedium:
    r"""A translucent object whose medium varies in space: a voxel grid of coefficients.

    Parameters
    ----------
    sigma_a, sigma_s_prime : array_like, shape (Z, Y, X, 3)
        Absorption and reduced scattering per voxel and RGB channel, mm^-1, >= 0, with
        :math:`\sigma_a + \sigma'_s > 0` in every voxel and channel. Index ``[z, y, x]``;
        x varies fastest in memory (Mitsuba's ``VolumeGrid`` layout).
    bounds : array_like, shape (2, 3)
        The box the grid fills, ``[[x_min, y_min, z_min], [x_max, y_max, z_max]]`` in
        scene units; it must cover the object's mesh (:meth:`check_covers`).
    eta : float
        Relative index of refraction of the object's boundary, in [1, 3] (1: index-matched).
    name : str
    description : str
        How the field was made (for headers and reports).

    Raises
    ------
    InputError
        A grid of the wrong shape, a NaN, Inf or negative coefficient (the message names
        the voxel), a voxel of zero extinction, bad bounds or eta.
    """

    sigma_a: np.ndarray
    sigma_s_prime: np.ndarray
    bounds: np.ndarray = DEFAULT_BOUNDS
    eta: float = 1.0
    name: str = ""
    description: str = ""
    source: str | None = None

    def __post_init__(self):
        file = self.source
        sigma_a = _coefficient_grid(self.sigma_a, "sigma_a", file=file)
        sigma_s_prime = _coefficient_grid(self.sigma_s_prime, "sigma_s_prime", file=file)
        if sigma_a.shape != sigma_s_prime.shape:
            raise InputError(f"must have the shape of sigma_a {sigma_a.shape}", file=file,
                             field="sigma_s_prime", value=sigma_s_prime.shape)
        empty = sigma_a + sigma_s_prime <= 0
        if empty.any():
            where = tuple(int(i) for i in np.argwhere(empty)[0])
            raise InputError("sigma_a + sigma_s_prime must be > 0 (a voxel of vacuum); "
                             f"voxel (z, y, x, channel) = {where}", file=file,
                             field="sigma_s_prime", value=0.0)
        object.__setattr__(self, "sigma_a", sigma_a)
        object.__setattr__(self, "sigma_s_prime", sigma_s_prime)
        object.__setattr__(self, "bounds", _bounds(self.bounds, file=file))
        eta = float(check_finite(self.eta, "eta", file=file))
        if not 1.0 <= eta <= 3.0:
            raise InputError("must be in [1, 3]", file=file, field="eta", value=self.eta)
        object.__setattr__(self, "eta", eta)

    # ---------------------------------------------------------------- layout
    @property
    def shape(self) -> tuple[int, int, int]:
        """Voxels along (z, y, x)."""
        return self.sigma_a.shape[:3]

    @property
    def voxel_size(self) -> np.ndarray:
        """Edge of a voxel along (x, y, z), scene units."""
        return (self.bounds[1] - self.bounds[0]) / np.array(self.shape[::-1])

    @property
    def g(self) -> float:
        """Scattering anisotropy: 0, the coefficients are reduced ones."""
        return 0.0

    @property
    def sigma_t(self) -> np.ndarray:
        r""":math:`\sigma_t = \sigma_a + \sigma'_s` per voxel, mm^-1 (g = 0)."""
        return self.sigma_a + self.sigma_s_prime

    @property
    def albedo(self) -> np.ndarray:
        r"""Single-scattering albedo :math:`\sigma'_s / \sigma_t` per voxel."""
        return self.sigma_s_prime / self.sigma_t

    @property
    def is_uniform(self) -> bool:
        """True when every voxel holds the same coefficients (a homogeneous medium)."""
        return bool(np.all(self.sigma_a == self.sigma_a[0, 0, 0])
                    and np.all(self.sigma_s_prime == self.sigma_s_prime[0, 0, 0]))

    def voxel_index(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return the (z, y, x) voxel of each point (scene units), clamped into the grid."""
        points = np.asarray(points, dtype=np.float64)
        fraction = (points - self.bounds[0]) / (self.bounds[1] - self.bounds[0])
        sizes = np.array(self.shape[::-1])
        index = np.clip(np.floor(fraction * sizes).astype(np.int64), 0, sizes - 1)
        return index[..., 2], index[..., 1], index[..., 0]

    def voxel_centres(self) -> np.ndarray:
        """Return the centre of every voxel (scene units), shape (Z * Y * X, 3), [z, y, x] order.

        Row ``(z * Y + y) * X + x`` is voxel ``[z, y, x]``: labels of these points reshape
        to :attr:`shape`.
        """
        z, y, x = np.meshgrid(*(np.arange(n) for n in self.shape), indexing="ij")
        index = np.stack([x, y, z], axis=-1).reshape(-1, 3)
        return self.bounds[0] + (index + 0.5) * self.voxel_size

    def coefficients_at(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(sigma_a, sigma_s_prime)`` at ``points`` (shape (..., 3)), mm^-1 RGB.

        The voxel a point lies in (points outside the box take the nearest border voxel,
        as Mitsuba's clamped lookup does).
        """
        z, y, x = self.voxel_index(points)
        return self.sigma_a[z, y, x], self.sigma_s_prime[z, y, x]

    def in_frame(self, origin, scale: float) -> SolidMedium:
        """Return this medium with its box in the scene units ``(x - origin) * scale``."""
        bounds = (self.bounds - np.asarray(origin, dtype=np.float64)) * float(scale)
        return replace(self, bounds=bounds)

    def check_covers(self, points, *, file=None, field: str = "bounds") -> None:
        """Raise :class:`InputError` unless the box holds every point (a mesh's vertices)."""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        slack = COVER_TOLERANCE * float(np.linalg.norm(self.bounds[1] - self.bounds[0]))
        outside = np.any((points < self.bounds[0] - slack) | (points > self.bounds[1] + slack),
                         axis=1)
        if outside.any():
            low, high = points.min(axis=0), points.max(axis=0)
            raise InputError(f"the medium's grid does not cover the object: the mesh spans "
                             f"{np.round(low, 6).tolist()} to {np.round(high, 6).tolist()}, "
                             f"the grid {self.bounds.tolist()} ({int(outside.sum())} vertices "
                             "outside)", file=file or self.source, field=field,
                             value=self.bounds.tolist())

    def dipole(self, index: tuple = (0, 0, 0)) -> Dipole:
        """Return the homogeneous medium of voxel ``(z, y, x)`` as a :class:`Dipole`."""
        return Dipole(self.sigma_a[index], self.sigma_s_prime[index], eta=self.eta, g=0.0,
                      name=self.name)

    def describe(self, units_per_scene_unit: float = 1.0) -> str:
        """One line: what the field is, its grid and voxel size.

        ``units_per_scene_unit``: the box is in a frame of that many units per scene unit
        (a rendering frame, :mod:`translucent.scenes.frame`); the line speaks in scene units.
        """
        z, y, x = self.shape
        size = ", ".join(f"{s / units_per_scene_unit:.4g}" for s in self.voxel_size)
        what = self.description or self.name or "solid medium"
        return f"{what}; grid {x} x {y} x {z} voxels of ({size}) scene units, eta {self.eta:g}"

    def cache_key(self) -> dict:
        """Return what identifies this material in content hashes."""
        return {"type": "solid", "sigma_a": self.sigma_a, "sigma_s_prime": self.sigma_s_prime,
                "bounds": self.bounds, "eta": self.eta}


# -------------------------------------------------------------------- quantisation
class MediaQuantisation(NamedTuple):
    """Samples of a field reduced to a few homogeneous media, and the error made.

    Attributes
    ----------
    media : tuple of Dipole
        The distinct media.
    labels : ndarray of int64
        For each sample, the index of its medium.
    max_relative_error : float
        Largest relative difference between a sample's coefficients and its medium's
        (0 when every sample is exactly one of the media).
    """

    media: tuple
    labels: np.ndarray
    max_relative_error: float


#: Default ceiling on distinct media handed to a fast method (each costs a conversion).
DEFAULT_MAX_MEDIA = 16


def quantise_media(solid: SolidMedium, points, *, max_media: int = DEFAULT_MAX_MEDIA
                   ) -> MediaQuantisation:
    """Reduce the medium at ``points`` to at most ``max_media`` homogeneous media.

    Exact (``max_relative_error`` 0) when the points see at most ``max_media`` distinct
    voxel values (a checker); otherwise farthest-point clustering in log-coefficient
    space (media that occur in the field), with the largest relative deviation reported.
    """
    max_media = check_count(max_media, "max_media")
    sigma_a, sigma_s_prime = solid.coefficients_at(np.asarray(points).reshape(-1, 3))
    values = np.concatenate([sigma_a, sigma_s_prime], axis=1)
    distinct, labels = np.unique(values, axis=0, return_inverse=True)
    labels = labels.reshape(-1)
    if len(distinct) > max_media:
        distinct, labels = _farthest_points(values, max_media)
    media = tuple(Dipole(row[:3], row[3:], eta=solid.eta, g=0.0,
                         name=f"{solid.name or 'solid'}[{k}]")
                  for k, row in enumerate(distinct))
    with np.errstate(divide="ignore", invalid="ignore"):
        deviation = np.abs(values - distinct[labels]) / np.where(values > 0, values, 1.0)
    return MediaQuantisation(media, labels.astype(np.int64), float(deviation.max(initial=0.0)))


def _farthest_points(values: np.ndarray, clusters: int):
    """Pick ``clusters`` of the rows as media, each next one the row farthest from all so far.

    Gonzalez's farthest-point clustering in log-coefficient space with the max-norm: it
    keeps the largest relative error of any row within twice the best possible with that
    many media, which a mean-squared clustering (k-means) does not bound. The media are
    rows of ``values`` (media that occur in the field).
    """
    logs = np.log(np.maximum(values, 1e-12))
    median = np.median(logs, axis=0)
    chosen = [int(np.argmin(np.abs(logs - median).max(axis=1)))]
    distance = np.abs(logs - logs[chosen[0]]).max(axis=1)
    labels = np.zeros(len(values), dtype=np.int64)
    while len(chosen) < clusters and distance.max() > 0:
        new = int(np.argmax(distance))
        to_new = np.abs(logs - logs[new]).max(axis=1)
        closer = to_new < distance
        labels[closer] = len(chosen)
        distance = np.minimum(distance, to_new)
        chosen.append(new)
    return values[chosen], labels


# -------------------------------------------------------------------- procedural fields
def _medium(name, field: str) -> Dipole:
    """Return a measured medium by name, or a :class:`Dipole` given as it is."""
    if isinstance(name, Dipole):
        return name
    try:
        return measured_medium(name)
    except InputError as error:
        raise InputError(error.reason, field=field, value=name) from error


def _voxel_centres(bounds: np.ndarray, resolution: tuple[int, int, int]):
    """Centres (x, y, z) of a (Z, Y, X) grid over ``bounds``, each of shape (Z, Y, X)."""
    z_count, y_count, x_count = resolution
    axes = [bounds[0, a] + (np.arange(n) + 0.5) / n * (bounds[1, a] - bounds[0, a])
            for a, n in enumerate((x_count, y_count, z_count))]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return x, y, z


def _mix(first: Dipole, second: Dipole, weight: np.ndarray):
    """Coefficients of a volume mixture: linear in the fraction ``weight`` of ``second``."""
    t = weight[..., None]
    return ((1.0 - t) * first.sigma_a + t * second.sigma_a,
            (1.0 - t) * first.sigma_s_prime + t * second.sigma_s_prime)


def _eta(eta, first: Dipole) -> float:
    return first.eta if eta is None else eta


def uniform_solid(medium: str = "Skin1", *, bounds=DEFAULT_BOUNDS, eta: float | None = None,
                  resolution: int = 1) -> SolidMedium:
    """Fill the box with one measured medium: the homogeneous limit of every field.

    ``resolution`` voxels per axis (1 is enough; more tests the grid lookup).
    """
    material = _medium(medium, "medium")
    resolution = check_count(resolution, "resolution")
    shape = (resolution,) * 3 + (3,)
    return SolidMedium(np.broadcast_to(material.sigma_a, shape),
                       np.broadcast_to(material.sigma_s_prime, shape), bounds,
                       _eta(eta, material), f"uniform({material.name})",
                       f"uniform {material.name}")


def checker_solid(first: str = "Skin1", second: str = "Ketchup", *, cells: int = 4,
                  bounds=DEFAULT_BOUNDS, eta: float | None = None) -> SolidMedium:
    """Build a 3D checker of two media, ``cells`` cubes along each side of the box.

    ``first`` and ``second`` are measured-media names (Jensen et al. 2001) or
    :class:`Dipole` media.

    Cell ``(i, j, k)`` holds ``second`` when ``i + j + k`` is odd. One voxel a cell: the
    grid is the field exactly. The solid version of Chen et al. 2012's marble chessboard
    and of Sheng et al. 2014's checkerboard block.
    """
    a, b = _medium(first, "first"), _medium(second, "second")
    cells = check_count(cells, "cells")
    if cells ** 3 > MAX_VOXELS:
        raise InputError(f"at most {round(MAX_VOXELS ** (1 / 3))} cells a side",
                         field="cells", value=cells)
    k, j, i = np.meshgrid(*(np.arange(cells),) * 3, indexing="ij")
    sigma_a, sigma_s_prime = _mix(a, b, ((i + j + k) % 2).astype(np.float64))
    return SolidMedium(sigma_a, sigma_s_prime, bounds, _eta(eta, a),
                       f"checker({a.name},{b.name})",
                       f"3D checker of {a.name} and {b.name}, {cells} cells a side")


def _value_noise_3d(x, y, z, frequency: int, rng) -> np.ndarray:
    """Smooth value noise on the unit cube: random lattice values, smoothstep-interpolated."""
    lattice = rng.random((frequency + 1,) * 3)
    coordinates = [np.clip(c, 0.0, 1.0) * frequency for c in (x, y, z)]
    cells = [np.minimum(c.astype(int), frequency - 1) for c in coordinates]
    weights = [c - n for c, n in zip(coordinates, cells, strict=True)]
    smooth = [w * w * (3.0 - 2.0 * w) for w in weights]
    value = np.zeros_like(coordinates[0])
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                corner = lattice[cells[0] + dx, cells[1] + dy, cells[2] + dz]
                factor = ((smooth[0] if dx else 1 - smooth[0])
                          * (smooth[1] if dy else 1 - smooth[1])
                          * (smooth[2] if dz else 1 - smooth[2]))
                value += factor * corner
    return value


def veined_solid(base: str = "Skin2", vein: str = "Ketchup", *, seed: int = 7,
                 resolution: int = 48, stripes: float = 2.0, bounds=DEFAULT_BOUNDS,
                 eta: float | None = None) -> SolidMedium:
    r"""Build veins of a second medium through a base, from 3D turbulence (solid marble).

    The vein fraction is :math:`1 - |\sin(2\pi s (3x + 2y + z)/6 + 6 T(x))|^{1/4}` over
    the box mapped to the unit cube, with :math:`T` four octaves of seeded 3D value noise
    and ``stripes`` the number of vein periods across the box; the coefficients mix
    linearly by that fraction. ``resolution`` voxels a side resolve the veins: the
    narrowest vein (where the fraction exceeds 1/2) is about 1/16 of a period wide.
    """
    a, b = _medium(base, "base"), _medium(vein, "vein")
    seed = check_count(seed, "seed", 0)
    resolution = check_count(resolution, "resolution", 2)
    if resolution ** 3 > MAX_VOXELS:
        raise InputError("at most 256 voxels a side", field="resolution", value=resolution)
    stripes = float(check_finite(stripes, "stripes"))
    if stripes <= 0:
        raise InputError("must be > 0", field="stripes", value=stripes)
    box = _bounds(bounds)
    x, y, z = _voxel_centres(np.array([[0.0] * 3, [1.0] * 3]), (resolution,) * 3)
    rng = np.random.default_rng(seed)
    turbulence = sum(_value_noise_3d(x, y, z, 2 * 2 ** octave, rng) / 2 ** octave
                     for octave in range(4))
    phase = 2.0 * np.pi * stripes * (3.0 * x + 2.0 * y + z) / 6.0 + 6.0 * turbulence
    weight = 1.0 - np.abs(np.sin(phase)) ** 0.25
    sigma_a, sigma_s_prime = _mix(a, b, weight)
    return SolidMedium(sigma_a, sigma_s_prime, box, _eta(eta, a),
                       f"veined({a.name},{b.name})",
                       f"{b.name} veins in {a.name} (seed {seed}, {stripes:g} periods)")


_AXES = {"x": 0, "y": 1, "z": 2}


def gradient_solid(first: str = "Skin1", second: str = "Skin2", *, axis: str = "y",
                   resolution: int = 32, bounds=DEFAULT_BOUNDS, eta: float | None = None
                   ) -> SolidMedium:
    """Build a linear gradient from ``first`` (box minimum) to ``second`` along ``axis``."""
    a, b = _medium(first, "first"), _medium(second, "second")
    if axis not in _AXES:
        raise InputError("must be x, y or z", field="axis", value=axis)
    resolution = check_count(resolution, "resolution", 2)
    if resolution > 4096:
        raise InputError("must be <= 4096", field="resolution", value=resolution)
    shape = [1, 1, 1]
    shape[2 - _AXES[axis]] = resolution
    weight = ((np.arange(resolution) + 0.5) / resolution).reshape(shape)
    sigma_a, sigma_s_prime = _mix(a, b, weight)
    return SolidMedium(sigma_a, sigma_s_prime, bounds, _eta(eta, a),
                       f"gradient({a.name},{b.name})",
                       f"gradient from {a.name} to {b.name} along {axis}")


#: Procedural fields: name -> constructor taking the scene-file options as keywords.
SOLID_FIELDS = {
    "uniform": uniform_solid,
    "checker": checker_solid,
    "veins": veined_solid,
    "gradient": gradient_solid,
}


# -------------------------------------------------------------------- file format
def save_solid(path, solid: SolidMedium) -> Path:
    """Write ``solid`` as an uncompressed NumPy ``.npz`` (docs/solid-format.md), atomically."""
    if not isinstance(solid, SolidMedium):
        raise InputError("expected a SolidMedium", file=path, field="solid",
                         value=type(solid).__name__)
    path = Path(path)
    with atomic_path(path, suffix=".npz") as tmp, open(tmp, "wb") as handle:
        np.savez(handle, format=np.array(FORMAT_NAME), version=np.array(FORMAT_VERSION),
                 sigma_a=solid.sigma_a, sigma_s_prime=solid.sigma_s_prime,
                 bounds=solid.bounds, eta=np.array(solid.eta), name=np.array(solid.name))
    return path


def load_solid(path) -> SolidMedium:
    """Read a solid medium written by :func:`save_solid` (or by hand, docs/solid-format.md).

    Raises
    ------
    InputError
        A missing or unreadable file, a missing array, a grid of the wrong shape, a NaN or
        negative coefficient (naming the voxel), bounds that are not a box.
    """
    from ..atomic import check_input_file
    from ..resources import check_npz_memory

    path = check_input_file(path, "path", what="file")
    check_npz_memory(path, field="sigma_a")  # before an array is read
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {key: data[key] for key in data.files}
    except (OSError, ValueError, EOFError) as error:
        raise InputError(f"not a readable .npz file ({error})", file=path, field="path",
                         value=str(path)) from error
    if "format" in fields and str(fields["format"]) != FORMAT_NAME:
        raise InputError(f"must be {FORMAT_NAME!r}", file=path, field="format",
                         value=str(fields["format"]))
    if "version" in fields and int(fields["version"]) > FORMAT_VERSION:
        raise InputError(f"written by a newer version; this one reads <= {FORMAT_VERSION}",
                         file=path, field="version", value=int(fields["version"]))
    for key in ("sigma_a", "sigma_s_prime", "bounds"):
        if key not in fields:
            raise InputError("missing array", file=path, field=key, value=None)
    return SolidMedium(fields["sigma_a"], fields["sigma_s_prime"], fields["bounds"],
                       float(fields.get("eta", 1.0)), str(fields.get("name", path.stem)),
                       f"grid from {path.name}", source=str(path))


@functools.lru_cache(maxsize=16)
def _procedural_cached(field: str, options: tuple) -> SolidMedium:
    return SOLID_FIELDS[field](**dict(options))


def solid_from_spec(spec: dict, *, file=None) -> SolidMedium:
    """Build a solid medium from a scene-file table.

    Accepted: ``{type = "solid", field = "checker", first = "Skin1", second = "Ketchup",
    cells = 4, bounds = [[-1, -1, -1], [1, 1, 1]], eta = 1.0}`` (any of
    :data:`SOLID_FIELDS` with its options) or ``{type = "solid", file = "grid.npz"}``
    (relative to the scene file's folder; ``eta`` may replace the file's).
    """
    spec = dict(spec)
    spec.pop("type", None)
    sources = [key for key in ("field", "file") if key in spec]
    if len(sources) != 1:
        raise InputError("a solid material needs exactly one of field, file", file=file,
                         field="material", value=sorted(spec))
    if "file" in spec:
        value = spec.pop("file")
        eta = spec.pop("eta", None)
        if spec:
            raise InputError("a solid file takes no option but eta", file=file,
                             field="material", value=sorted(spec))
        from .factory import spec_file_path

        path = spec_file_path(value, file, "a .npz grid")
        solid = load_solid(path)
        if eta is not None:
            solid = SolidMedium(solid.sigma_a, solid.sigma_s_prime, solid.bounds, eta,
                                solid.name, solid.description, solid.source)
        return solid
    name = spec.pop("field")
    if name not in SOLID_FIELDS:
        raise InputError(f"unknown field; valid: {', '.join(SOLID_FIELDS)}", file=file,
                         field="field", value=name)
    if "bounds" in spec:
        spec["bounds"] = tuple(map(tuple, _bounds(spec["bounds"], file=file).tolist()))
    try:
        return _procedural_cached(name, tuple(sorted(spec.items())))
    except TypeError as error:
        raise InputError(f"bad option for field '{name}' ({error})", file=file,
                         field="material", value=sorted(spec)) from error
    except InputError as error:
        raise InputError(error.reason, file=file, field=error.field,
                         value=error.value) from error


#: Keys a scene-file table of type "solid" may hold.
SPEC_KEYS = ("field", "file", "bounds", "eta", "medium", "first", "second", "base", "vein",
             "cells", "seed", "resolution", "stripes", "axis")


def _register() -> None:
    from .factory import register_spec_type

    register_spec_type("solid", solid_from_spec, SolidMedium, keys=SPEC_KEYS,
                       path_keys=("file",),
                       save_hint="this solid medium was made in code: save it with "
                       "save_solid and refer to it as {type = \"solid\", file = \"...\"}")


_register()
