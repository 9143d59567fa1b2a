r"""The translucent object's own shape in a method's radial profile, for every method.

PRT (Wang et al. 2008) and splatting (Chen et al. 2012) sum a radial profile
:math:`R(\lVert x_o - x_i\rVert)` over the entry points: the profile of a half-space,
whatever the object. On a thin wall or a small object that misses where the light
diffusing below the surface comes out: through the wall, round a convex surface, and how
much of it. This module adds what diffusion theory says the object's shape changes
(:mod:`translucent.scenes.object_diffusion`), as a knob of each method:

.. math:: J(x_o) = \sum_i R(\lVert x_o - x_i\rVert)\,E_i A_i
          + s\sum_m W^{exit}_{om} \sum_k C_{mk} \sum_i W^{entry}_{ik} E_i A_i,

with :math:`C` the correction between the object's surface clusters (solved once per
material), :math:`W` each point's weights over the clusters, and :math:`s` the ratio of
the method's profile's half-space total to the dipole's, per channel (the correction is
diffusion's, measured in the dipole's units; another profile carries its own energy). A
frame costs two sparse products and one K x K product per channel; a new material one
solve (:meth:`~translucent.scenes.object_diffusion.ObjectDiffusion.response`, kept per
material).

The knob ``geometry``: ``"diffusion"`` (the default) adds it, ``"half_space"`` is the
papers' profile alone. An open mesh (a sheet) has no inside to diffuse in: it keeps the
half-space, said in the method's log.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from ..materials.homogeneous import Dipole
from ..scenes.mesh_shape import closed_surface
from ..scenes.object_diffusion import (
    DEFAULT_CELLS,
    DEFAULT_CLUSTERS,
    ObjectDiffusion,
    object_diffusion,
    profile_scale,
)
from .knobs import Knob

__all__ = ["GEOMETRY", "QUICK_GEOMETRY_KNOBS", "ObjectGeometry", "geometry_knobs",
           "object_geometries"]

#: Values of the knob ``geometry``.
GEOMETRY = ("diffusion", "half_space")

#: Cheap geometry knobs for smoke runs and the conformance checks (a coarse grid and few
#: clusters: the correction in well under a second).
QUICK_GEOMETRY_KNOBS = {"geometry_cells": 1000, "geometry_clusters": 48}

def geometry_knobs() -> list[Knob]:
    """Return the knobs every method with the geometry correction declares.

    Not part of the cache key of a method's own precomputation (``keyed=False``): the
    correction is made beside it.
    """
    return [
        Knob("geometry", "diffusion", "the object's own shape in the profile: diffusion "
             "(the half-space profile plus diffusion's correction for the object's finite "
             "extent) or half_space (the profile alone, as the paper)", kind="choice",
             choices=GEOMETRY, keyed=False),
        Knob("geometry_cells", DEFAULT_CELLS, "finite-volume cells of the object's "
             "diffusion solve, about", kind="int", low=8, high=1 << 22, keyed=False),
        Knob("geometry_clusters", DEFAULT_CLUSTERS, "surface clusters the geometry "
             "correction is solved between", kind="int", low=1, high=4096, keyed=False,
             ladder=(32, 128)),
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

    def weights(self, points, normals) -> sparse.csr_matrix:
        """Each point's weights over the clusters (points in scene units), shape (P, K)."""
        return self.diffusion.weights(np.asarray(points, np.float64) * self.mm_per_unit,
                                      normals)

    def exitance(self, entry, entry_power, exit, material, profile_total=None) -> np.ndarray:
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
        profile_total : array_like, shape (3,), optional
            The method's profile's half-space total, when not the dipole's.

        Returns
        -------
        ndarray
            In the units of :math:`\sum_i R\,E_i A_i` (the profile in mm^-2).
        """
        response = self.diffusion.response(material.sigma_a, material.sigma_s_prime,
                                           material.eta)
        power = np.asarray(entry.T @ np.asarray(entry_power, dtype=np.float64))
        clusters = np.einsum("mkc,kc->mc", response, power)
        if profile_total is not None:
            clusters = clusters * profile_scale(material, profile_total)
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
        material = item.material
        diffusion.response(material.sigma_a, material.sigma_s_prime, material.eta)
        out[name] = ObjectGeometry(diffusion, mm)
        facts[name] = {"cells": diffusion.grid.cells,
                       "voxel_mm": round(diffusion.grid.voxel_size, 4),
                       "clusters": diffusion.clusters,
                       "cluster_spacing_mm": round(diffusion.spacing, 3)}
    if log is not None:
        log.seconds["geometry"] = time.perf_counter() - started
        if facts:
            log.notes["geometry"] = facts
    return out
