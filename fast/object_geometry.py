r"""The translucent object's own shape in a method's radial profile, for every method.

PRT (Wang et al. 2008) and splatting (Chen et al. 2012) sum a radial profile
:math:`R(\lVert x_o - x_i\rVert)` over the entry points: the profile of a half-space,
whatever the object. On a thin wall or a small object that misses where the light
diffusing below the surface comes out: through the wall, round a convex surface, and how
much of it. This module adds what the object's shape changes, as a knob of each method:

.. math:: J(x_o) = \sum_i R(\lVert x_o - x_i\rVert)\,E_i A_i
          + \sum_m W^{exit}_{om} \sum_k C_{mk} \sum_i W^{entry}_{ik} E_i A_i,

with :math:`C` the correction between the object's surface clusters (made once per
material and profile), :math:`W` each point's weights over the clusters. Two models of
:math:`C`, the knob ``geometry``:

- ``"walk"`` (the default): photon random walks in the object's mesh, less the profile
  summed on its surface (:mod:`translucent.scenes.object_walk`): at the clusters' scale the
  object returns transport's light (through a thin wall, round a convex surface, and the
  energy the profile's own model misses), below it the profile's shape.
- ``"diffusion"``: diffusion's solve in the object, less the dipole's half-space field
  (:mod:`translucent.scenes.object_diffusion`), scaled by the method's profile's
  half-space total over the dipole's (the profile keeps its own energy); zero where a wall
  is thinner than diffusion describes.
- ``"half_space"``: the papers' profile alone.

A frame costs two sparse products and one K x K product per channel; a new material one
solve or one set of walks (kept per material). An open mesh (a sheet) has no inside to
diffuse in: it keeps the half-space, said in the method's log.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..materials.homogeneous import Dipole
from ..materials.profiles import profile as named_profile
from ..scenes.mesh_shape import closed_surface
from ..scenes.object_diffusion import (
    DEFAULT_CELLS,
    DEFAULT_CLUSTERS,
    ObjectDiffusion,
    object_diffusion,
    profile_scale,
)
from ..scenes.object_walk import DEFAULT_WALKS, walk_response
from .knobs import DEFAULT_PROFILE, Knob, radial_profile

__all__ = ["GEOMETRY", "QUICK_GEOMETRY_KNOBS", "ObjectGeometry", "geometry_knobs",
           "object_geometries"]

#: Values of the knob ``geometry``.
GEOMETRY = ("walk", "diffusion", "half_space")

#: Cheap geometry knobs for smoke runs and the conformance checks (a coarse grid and few
#: clusters: the correction in well under a second).
QUICK_GEOMETRY_KNOBS = {"geometry_cells": 1000, "geometry_clusters": 48,
                        "geometry_walks": 2048}

def geometry_knobs(default: str = "walk") -> list[Knob]:
    """Return the knobs every method with the geometry correction declares.

    Not part of the cache key of a method's own precomputation (``keyed=False``): the
    correction is made beside it. ``default``: the method's value of ``geometry``.
    """
    return [
        Knob("geometry", default, "the object's own shape in the profile: walk (the "
             "profile plus what photon random walks in the object's mesh return beyond it, "
             "at the scale of the surface clusters), diffusion (the profile plus diffusion's "
             "correction for the object's finite extent) or half_space (the profile alone, "
             "as the paper)", kind="choice", choices=GEOMETRY, keyed=False),
        Knob("geometry_cells", DEFAULT_CELLS, "finite-volume cells of the object's "
             "diffusion solve, about", kind="int", low=8, high=1 << 22, keyed=False),
        Knob("geometry_clusters", DEFAULT_CLUSTERS, "surface clusters the geometry "
             "correction is solved between", kind="int", low=1, high=4096, keyed=False,
             ladder=(32, 128)),
        Knob("geometry_walks", DEFAULT_WALKS, "photon random walks per channel of the "
             "walk geometry's correction", kind="int", low=8, high=1 << 24, keyed=False),
    ]


@dataclass(eq=False)
class ObjectGeometry:
    """One translucent object's geometry correction as a method applies it.

    Parameters
    ----------
    diffusion : ObjectDiffusion
        The object's grid and clusters (mm).
    mm_per_unit : float
        The scene's scale: points come in scene units.
    """

    diffusion: ObjectDiffusion
    mm_per_unit: float
    model: str = "diffusion"
    triangles: np.ndarray | None = None
    walks: int = DEFAULT_WALKS
    seed: int = 0

    def response(self, material, profile=None) -> np.ndarray:
        """Return the correction between the clusters for ``profile``, mm^-2, (K, K, 3).

        ``profile``: the method's radial profile of ``material`` (None: the classical
        dipole). Diffusion's correction is scaled by its half-space total over the
        dipole's; the walks' is measured beyond the profile itself.
        """
        if self.model == "walk":
            if profile is None:
                profile = named_profile("dipole", material)
            return walk_response(self.diffusion, self.triangles, material, profile,
                                 walks=self.walks, seed=self.seed)
        response = self.diffusion.response(material.sigma_a, material.sigma_s_prime,
                                           material.eta)
        if profile is None:
            return response
        return response * profile_scale(material, profile.total())[None, None, :]

    def weights(self, points, normals) -> sparse.csr_matrix:
        """Each point's weights over the clusters (points in scene units), shape (P, K)."""
        return self.diffusion.weights(np.asarray(points, np.float64) * self.mm_per_unit,
                                      normals)

    def exitance(self, entry, entry_power, exit, material, profile=None) -> np.ndarray:
        r"""Return the correction's exitance at the exit points, shape (V, 3).

        Parameters
        ----------
        entry : scipy.sparse.csr_matrix, shape (N, K)
            The entry points' :meth:`weights`.
        entry_power : ndarray, shape (N, 3)
            :math:`E_i A_i` at the entry points: irradiance into the medium (after the
            entry Fresnel term) times the area each stands for, in mm^2.
        exit : scipy.sparse.csr_matrix, shape (V, K)
            The exit points' :meth:`weights`.
        material : Dipole
            Its coefficients (mm^-1) and eta.
        profile : RadialProfile, optional
            The method's profile of ``material``, when not the classical dipole.

        Returns
        -------
        ndarray
            In the units of :math:`\sum_i R\,E_i A_i` (the profile in mm^-2).
        """
        power = np.asarray(entry.T @ np.asarray(entry_power, dtype=np.float64))
        clusters = np.einsum("mkc,kc->mc", self.response(material, profile), power)
        return np.asarray(exit @ clusters)


def object_geometries(scene, names, knobs: dict, log=None) -> dict:
    """Build the geometry correction of each named translucent object.

    Parameters
    ----------
    scene : Scene
    names : iterable of str
        The objects a method renders with a radial profile.
    knobs : dict
        The method's resolved knobs (those of :func:`geometry_knobs`; ``seed`` if any).
    log : StageLog, optional
        Notes: the seconds, the grid and clusters; what was left a half-space and why.

    Returns
    -------
    dict
        Name -> :class:`ObjectGeometry`, for the objects that have one (none where the
        knob is ``"half_space"``). The scene's own material of each is solved here, so
        that the first frame does not pay for it.
    """
    if knobs["geometry"] == "half_space":
        return {}
    started = time.perf_counter()
    out, facts = {}, {}
    mm = float(scene.mm_per_unit)
    for name in names:
        item = scene.object(name)
        if not isinstance(item.material, Dipole):
            continue
        mesh = item.mesh
        if not closed_surface(mesh.faces, mesh.vertices):
            if log is not None:
                log.skip(f"geometry: '{name}' is an open surface, with no inside to "
                         "diffuse in: its profile stays the half-space's")
            continue
        triangles = np.ascontiguousarray(mesh.vertices[mesh.faces] * mm, dtype=np.float64)
        # the disk cache keeps the grid, the clusters and the material's response
        diffusion = object_diffusion(triangles, cells=int(knobs["geometry_cells"]),
                                     clusters=int(knobs["geometry_clusters"]),
                                     seed=int(knobs.get("seed", 0)))
        walks = int(knobs.get("geometry_walks", DEFAULT_WALKS))
        out[name] = ObjectGeometry(diffusion, mm, knobs["geometry"], triangles, walks,
                                   int(knobs.get("seed", 0)))
        # the scene's own material is made here, so that the first frame does not pay
        method_profile = knobs.get("profile", DEFAULT_PROFILE)
        out[name].response(item.material, None if method_profile == DEFAULT_PROFILE
                           else radial_profile(method_profile, item.material))
        facts[name] = {"cells": diffusion.grid.cells,
                       "voxel_mm": round(diffusion.grid.voxel_size, 4),
                       "clusters": diffusion.clusters,
                       "cluster_spacing_mm": round(diffusion.spacing, 3)}
    if log is not None:
        log.seconds["geometry"] = time.perf_counter() - started
        if facts:
            log.notes["geometry"] = facts
    return out
