r"""The fast methods' inputs derived from a solid heterogeneous medium, not made by hand.

Splatting (Chen et al. 2012) takes a SubEdit texture over the surface's uv and radiosity
(Sheng et al. 2014) a homogeneous profile per face label; both are surface models of a
medium that varies in the volume. From a :class:`~translucent.materials.solid.SolidMedium`
each gets what the volumetric reference renders, read at the surface:

* **splatting**: each texel's centre is mapped through the mesh's uv to a point on the
  surface, the medium there is read (:meth:`SolidMedium.coefficients_at`), reduced to at
  most ``max_media`` distinct media (:func:`~translucent.materials.solid.quantise_media`,
  exact for a checker), and each medium -> dipole -> SubEdit profile
  (:func:`~translucent.materials.subedit.convert_media`, one shared ``r_s``);
* **radiosity**: every voxel is given one of at most ``max_media`` media, each face the
  label of the voxel at its centroid, giving
  :class:`~translucent.materials.profiles.MixedProfiles` whose Eq. 16 fractions are read
  through the voxels along each segment (the distance light travels in each material,
  where the paper, without a volume, takes the nearest labelled face).

What both assume, and what the volumetric reference does not: the medium at a surface
point stands for the whole column below it (a texel's profile is the semi-infinite
dipole of its surface value), and between two points the profiles are mixed by a
heuristic (Chen et al. 2012, Eq. 8: :math:`R_d = \sqrt{P_{x_i}(r) P_{x_o}(r)}`; Sheng et
al. 2014, Eq. 16). The errors this conversion makes (quantisation, the SubEdit fit of each
dipole) are recorded in :class:`SurfaceConversion`.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from ..cache import content_hash
from ..errors import InputError, check_count
from ..materials.profiles import RULE_MAX_MEDIA, MixedProfiles
from ..materials.solid import SolidMedium, quantise_media
from ..materials.subedit import DEFAULT_SEGMENTS, SubEditProfiles, convert_media
from .knobs import DEFAULT_PROFILE, radial_profile

__all__ = ["SurfaceConversion", "SURFACE_ASSUMPTIONS", "SPLATTING_MAX_MEDIA", "RADIOSITY_MAX_MEDIA",
           "DEFAULT_TEXTURE_RESOLUTION", "subedit_from_solid", "mixed_profiles_from_solid",
           "surface_scene", "texel_positions", "VoxelLabels"]

#: What each method assumes when it renders a solid medium from the surface (the report
#: prints it beside the method's result on such a scene).
SURFACE_ASSUMPTIONS = {
    "splatting": "the medium at each surface point stands for the column below it (each "
                 "texel's profile is the semi-infinite dipole of its surface value), and "
                 "light between two points follows Eq. 8 of Chen et al. 2012, "
                 "R_d = sqrt(P(x_i, r) P(x_o, r))",
    "radiosity": "each face's profile is the semi-infinite dipole of the medium at its "
                 "centroid, and light between two patches follows Eq. 16 of Sheng et al. "
                 "2014, mixing the media by the fraction of the straight segment in each",
}

#: Distinct media a SubEdit texture is made from (a texture lookup per texel: many are cheap).
SPLATTING_MAX_MEDIA = RULE_MAX_MEDIA["geometric_mean"]
#: Distinct media of radiosity's labels (Eq. 16 multiplies one factor per medium per pair).
RADIOSITY_MAX_MEDIA = RULE_MAX_MEDIA["segment_mix"]
#: Texels along each side of the derived SubEdit texture.
DEFAULT_TEXTURE_RESOLUTION = 128


class SurfaceConversion(NamedTuple):
    """A surface material derived from a solid medium, and what the derivation cost.

    Attributes
    ----------
    material : SubEditProfiles or MixedProfiles
    media : int
        Distinct homogeneous media it was made from.
    quantisation_error : float
        Largest relative coefficient difference between a surface point's medium and the
        medium it was given (0: exact).
    profile_error : float
        Largest relative L1 error (energy-weighted) of a SubEdit profile against its dipole
        (:func:`~translucent.materials.subedit.subedit_from_dipole`); 0 for radiosity,
        which evaluates the dipoles themselves.
    """

    material: object
    media: int
    quantisation_error: float
    profile_error: float

    def note(self) -> dict:
        """Return what a method's log records about the conversion."""
        return {"media": self.media, "quantisation_error": self.quantisation_error,
                "profile_error": self.profile_error}


def texel_positions(mesh, resolution: int) -> np.ndarray:
    """Surface points (scene units) at the centres of a ``resolution^2`` texture over uv.

    On a geometry image (``grid_shape`` set, ``uv = (col, row) / (cols - 1, rows - 1)``)
    the vertex grid is interpolated bilinearly; on another mesh with uv each texel takes
    the vertex nearest to it in uv.

    Returns
    -------
    ndarray, shape (resolution, resolution, 3)
        Row j, column i is the texel covering v in [j/R, (j+1)/R), u in [i/R, (i+1)/R).
    """
    resolution = check_count(resolution, "resolution")
    if mesh.uv is None:
        raise InputError("a solid medium for splatting needs a mesh with uv coordinates",
                         field="mesh.uv", value=None)
    centres = (np.arange(resolution) + 0.5) / resolution
    v, u = np.meshgrid(centres, centres, indexing="ij")
    if mesh.grid_shape is not None:
        rows, cols = mesh.grid_shape
        grid = np.asarray(mesh.vertices).reshape(rows, cols, 3)
        x, y = u * (cols - 1), v * (rows - 1)
        i = np.minimum(x.astype(int), cols - 2)
        j = np.minimum(y.astype(int), rows - 2)
        fx, fy = (x - i)[..., None], (y - j)[..., None]
        return ((1 - fy) * ((1 - fx) * grid[j, i] + fx * grid[j, i + 1])
                + fy * ((1 - fx) * grid[j + 1, i] + fx * grid[j + 1, i + 1]))
    from scipy.spatial import cKDTree

    _, nearest = cKDTree(np.asarray(mesh.uv)).query(np.stack([u, v], axis=-1).reshape(-1, 2))
    return np.asarray(mesh.vertices)[nearest].reshape(resolution, resolution, 3)


_CONVERSIONS: dict[str, SurfaceConversion] = {}


def _remembered(key: str, build) -> SurfaceConversion:
    if key not in _CONVERSIONS:
        _CONVERSIONS[key] = build()
    return _CONVERSIONS[key]


def subedit_from_solid(solid: SolidMedium, mesh, *,
                       resolution: int = DEFAULT_TEXTURE_RESOLUTION,
                       max_media: int = SPLATTING_MAX_MEDIA,
                       segments: int = DEFAULT_SEGMENTS,
                       profile: str = DEFAULT_PROFILE) -> SurfaceConversion:
    """Derive splatting's SubEdit texture from the medium at the surface (module docstring).

    A uniform medium gives a 1 x 1 texture: the homogeneous SubEdit conversion of its
    dipole, so the homogeneous limit renders as the homogeneous material does.
    ``profile`` (a value of the ``profile`` knob): the radial profile of each medium that
    is converted, the dipole by default.
    """
    def converted(media):
        profiles = None if profile == DEFAULT_PROFILE else \
            [radial_profile(profile, medium) for medium in media]
        return convert_media(media, segments=segments, profiles=profiles)

    def build() -> SurfaceConversion:
        if solid.is_uniform:
            conversion = converted([solid.dipole()])[0]
            return SurfaceConversion(conversion.profiles.with_name(solid.name), 1, 0.0,
                                     float(np.max(conversion.relative_error)))
        points = texel_positions(mesh, resolution)
        quantised = quantise_media(solid, points, max_media=max_media)
        conversions = converted(quantised.media)
        tables = np.stack([c.profiles.log_profile[0, 0] for c in conversions])
        texture = tables[quantised.labels].reshape(resolution, resolution, segments + 1, 3)
        profiles = SubEditProfiles(texture, conversions[0].profiles.r_s, solid.eta,
                                   solid.name)
        return SurfaceConversion(profiles, len(quantised.media), quantised.max_relative_error,
                                 float(max(np.max(c.relative_error) for c in conversions)))

    return _remembered(content_hash("subedit_from_solid", solid, mesh.cache_key(), resolution,
                                    max_media, segments, profile), build)


class VoxelLabels:
    """The medium label of the voxel a point (scene units) lies in: Eq. 16's volume lookup."""

    def __init__(self, solid: SolidMedium, labels: np.ndarray):
        self.solid = solid
        self.labels = np.asarray(labels, dtype=np.int64).reshape(solid.shape)

    def __call__(self, points) -> np.ndarray:
        """Return the label at each point, shape ``points.shape[:-1]``."""
        return self.labels[self.solid.voxel_index(points)]

    def counts_along(self, ends, first, second, points: int, labels: int, *,
                     scale: float = 1.0) -> np.ndarray:
        """Count the labels at ``points`` midpoints of each segment (Eq. 16's fractions).

        Segment p runs from ``ends[first[p]]`` to ``ends[second[p]]``; its points sit at
        ``t = (i + 0.5) / points`` and are looked up as :meth:`__call__` does, at
        ``point / scale`` (ends in mm, ``scale`` mm per scene unit).

        Returns
        -------
        ndarray of uint8, shape (segments, labels)
        """
        if not 1 <= points <= 255:
            raise InputError("must be 1..255 (counts are bytes)", field="points",
                             value=points)
        solid = self.solid
        return _compiled_counts_along()(
            np.ascontiguousarray(ends, dtype=np.float64),
            np.ascontiguousarray(first, dtype=np.int64),
            np.ascontiguousarray(second, dtype=np.int64), int(points), int(labels),
            float(scale), np.ascontiguousarray(self.labels), solid.bounds[0].astype(np.float64),
            (solid.bounds[1] - solid.bounds[0]).astype(np.float64),
            np.array(solid.shape[::-1], dtype=np.int64))


@functools.lru_cache(maxsize=1)
def _compiled_counts_along():
    import numba

    @numba.njit(cache=True)
    def counts_along(ends, first, second, points, labels, scale, grid, lower, extent,
                     sizes):  # pragma: no cover - compiled
        counts = np.zeros((len(first), labels), np.uint8)
        index = np.empty(3, np.int64)
        for segment in range(len(first)):
            a, b = first[segment], second[segment]
            for i in range(points):
                t = (i + 0.5) / points
                for d in range(3):
                    x = (ends[a, d] + t * (ends[b, d] - ends[a, d])) / scale
                    cell = math.floor((x - lower[d]) / extent[d] * sizes[d])
                    index[d] = min(max(cell, 0), sizes[d] - 1)
                counts[segment, grid[index[2], index[1], index[0]]] += 1
        return counts

    return counts_along


def mixed_profiles_from_solid(solid: SolidMedium, mesh, *,
                              max_media: int = RADIOSITY_MAX_MEDIA) -> SurfaceConversion:
    """Derive radiosity's labelled profiles from the medium, voxel by voxel.

    Every voxel is given one of at most ``max_media`` media; a face takes the label of
    the voxel holding its centroid, and Eq. 16's fractions are read along each segment
    through the voxels (:class:`VoxelLabels`). A uniform medium gives its
    :class:`~translucent.materials.Dipole` (the homogeneous limit).
    """
    def build() -> SurfaceConversion:
        if solid.is_uniform:
            return SurfaceConversion(solid.dipole(), 1, 0.0, 0.0)
        quantised = quantise_media(solid, solid.voxel_centres(), max_media=max_media)
        volume = VoxelLabels(solid, quantised.labels)
        material = MixedProfiles(quantised.media, volume(mesh.face_centroids),
                                 name=solid.name, volume_labels=volume,
                                 volume_key=solid.cache_key())
        return SurfaceConversion(material, len(quantised.media), quantised.max_relative_error,
                                 0.0)

    return _remembered(content_hash("mixed_profiles_from_solid", solid, mesh.cache_key(),
                                    max_media), build)


def surface_scene(scene, derive) -> tuple:
    """Return ``scene`` with every solid medium replaced by its derived surface material.

    Parameters
    ----------
    scene : Scene
    derive : callable
        ``derive(solid, mesh) -> SurfaceConversion`` (:func:`subedit_from_solid` or
        :func:`mixed_profiles_from_solid`).

    Returns
    -------
    (Scene, dict)
        The scene, and each converted object's :meth:`SurfaceConversion.note` by name.
    """
    notes = {}
    for obj in scene.objects:
        if isinstance(obj.material, SolidMedium):
            conversion = derive(obj.material, obj.mesh)
            scene = scene.with_material(obj.name, conversion.material)
            notes[obj.name] = conversion.note()
    return scene, notes
