r"""The object's shape in a model reference: the geometry correction rendered by Mitsuba.

A fast method with the knob ``geometry = "walk"`` or ``"diffusion"`` renders its profile
plus the correction of :mod:`translucent.scenes.object_walk` or
:mod:`translucent.scenes.object_diffusion` (:mod:`translucent.fast.object_geometry`):

.. math:: J(x_o) = \int R(\lVert x_o - x_i\rVert) E_t(x_i)\,dA_i
          + s\sum_m W_m(x_o) \sum_k C_{mk} \int W_k(x_i) E_t(x_i)\,dA_i.

The BSSRDF path tracer (:mod:`.bssrdf_path`) renders the first term exactly. This module
renders the second with the same light: :math:`E_t(x_i)`, the irradiance that enters the
object (each direction weighted by the Fresnel transmittance of its boundary), is
estimated by Mitsuba at points drawn uniformly over each object's surface, from the
scene's emitters (next-event estimation, every kind) and from cosine-distributed rays
traced by the BSSRDF path tracer itself (the light the rest of the scene, and the object
through its own profile, sends there), the two combined by the power heuristic as the
tracer combines them at its entry points. The exitance leaves each pixel's surface point
as the tracer's does, :math:`F_t(\eta, \cos\theta_o) / (\pi (1 - F_{dr}))`. So the model
reference of a method with the geometry is the tracer's image plus this one: the same
model, its light transported by code that shares nothing with the methods' lighting.

Each call of :meth:`GeometryTerm.sample` is one independent estimate (its own points and
rays): added to each pass of the tracer, the passes' spread carries its noise.
"""

from __future__ import annotations

import math

import numpy as np

from ..backend import mitsuba
from ..errors import InputError
from ..materials.fresnel import fresnel_transmittance
from ..materials.homogeneous import Dipole
from ..materials.profiles import profile as named_profile
from ..scenes.mesh_shape import closed_surface, stratified_surface_points
from ..scenes.object_diffusion import (
    CACHE_FORMAT,
    DEFAULT_CELLS,
    DEFAULT_CLUSTERS,
    object_diffusion,
    profile_scale,
)
from ..scenes.object_walk import DEFAULT_WALKS, WALK_FORMAT, walk_response
from .bssrdf_tables import exit_normalisation

__all__ = ["GeometryTerm", "geometry_settings"]

#: Surface points per object and estimate.
POINTS = 2048

#: Cosine-distributed rays per point and estimate.
RAYS = 16

#: Ray origins leave the surface by this fraction of the rendering frame's bounding radius.
ORIGIN_OFFSET = 1e-5


def geometry_settings(model: str = "diffusion") -> dict:
    """Return what a model reference with the geometry ``model`` was rendered with.

    Its header's ``geometry``; ``model`` is ``"diffusion"`` or ``"walk"`` (the knob
    ``geometry`` of the methods).
    """
    if model == "walk":
        # the walks are read on object_diffusion's clusters: their version counts too
        return {"model": "walk", "version": WALK_FORMAT, "clusters_version": CACHE_FORMAT,
                "cells": DEFAULT_CELLS, "clusters": DEFAULT_CLUSTERS, "walks": DEFAULT_WALKS,
                "seed": 0, "points": POINTS, "rays": RAYS}
    return {"model": "diffusion", "version": CACHE_FORMAT, "cells": DEFAULT_CELLS,
            "clusters": DEFAULT_CLUSTERS, "points": POINTS, "rays": RAYS}


def _rgb(values, count: int) -> np.ndarray:
    """Return a Dr.Jit colour array of ``count`` lanes as float64, shape (count, 3)."""
    array = np.array(values, dtype=np.float64)
    if array.shape == (3, count):
        array = array.T
    return np.broadcast_to(array, (count, 3)).copy()


class GeometryTerm:
    """The geometry correction's image of a scene, estimated anew by each :meth:`sample`.

    Parameters
    ----------
    scene : Scene
        In the user's units.
    conversion : MitsubaConversion
        The tracer's conversion of ``scene`` (its rendering frame).
    mitsuba_scene
        The loaded Mitsuba scene, whose integrator is the BSSRDF path tracer.
    profile : str
        The tracer's profile: diffusion's correction is scaled by its half-space total
        over the dipole's, and the walks' is measured beyond it, as the methods do.
    model : {"diffusion", "walk"}
        The geometry model.
    points, rays : int
        Per object and estimate.
    """

    def __init__(self, scene, conversion, mitsuba_scene, profile: str, *,
                 model: str = "diffusion", points: int = POINTS, rays: int = RAYS):
        from ..scenes.gbuffer import gbuffer

        self.scene = scene
        self.frame = conversion.frame
        self.mitsuba_scene = mitsuba_scene
        self.points, self.rays = int(points), int(rays)
        mm = float(scene.mm_per_unit)
        view = gbuffer(scene)
        self.shape = view.shape
        self.objects = []
        for item in scene.objects:
            if not isinstance(item.material, Dipole) or \
                    not closed_surface(item.mesh.faces, item.mesh.vertices):
                continue
            material = item.material
            where = view.mask(item.name)
            if not where.any():
                continue
            triangles = item.mesh.vertices[item.mesh.faces] * mm
            diffusion = object_diffusion(triangles, cells=DEFAULT_CELLS,
                                         clusters=DEFAULT_CLUSTERS)
            radial = named_profile(profile, material)
            if model == "walk":
                response = walk_response(diffusion, triangles, material, radial,
                                         walks=DEFAULT_WALKS, seed=0)
            else:
                response = diffusion.response(material.sigma_a, material.sigma_s_prime,
                                              material.eta)
                response = response * profile_scale(material, radial.total())[None, None, :]
            cosine = np.clip(np.einsum("...d,...d->...", view.normal, view.view_direction)
                             [where], 0.0, 1.0)
            exit_factor = fresnel_transmittance(material.eta, cosine) / float(
                exit_normalisation(material.eta))
            self.objects.append({
                "mesh": item.mesh, "eta": float(material.eta), "diffusion": diffusion,
                "response": response, "pixels": np.flatnonzero(where.ravel()),
                "exit": diffusion.weights(view.position[where] * mm, view.normal[where]),
                "exit_factor": exit_factor, "mm": mm})

    @property
    def empty(self) -> bool:
        """Whether no object of the scene has a geometry correction in view."""
        return not self.objects

    def sample(self, seed: int) -> np.ndarray:
        """Return one estimate of the correction's radiance, float64 ``H x W x 3``."""
        height, width = self.shape
        image = np.zeros((height * width, 3))
        rng = np.random.default_rng([int(seed), 0x6E0])
        for index, item in enumerate(self.objects):
            points, normals, total = stratified_surface_points(item["mesh"], self.points,
                                                               rng)
            irradiance = self._irradiance(points, normals, item["eta"],
                                          int(seed) * 64 + index, rng)
            power = irradiance * (total / self.points) * item["mm"] ** 2
            diffusion = item["diffusion"]
            entry = diffusion.weights(points * item["mm"], normals)
            clusters = np.einsum("mkc,kc->mc", item["response"],
                                 np.asarray(entry.T @ power))
            exitance = np.asarray(item["exit"] @ clusters)
            image[item["pixels"]] += exitance * item["exit_factor"][:, None]
        return image.reshape(height, width, 3)

    def _irradiance(self, points, normals, eta: float, seed: int, rng) -> np.ndarray:
        r"""Estimate :math:`E_t = \int L\,F_t(\eta, \cos\theta)\cos\theta\,d\omega`, (P, 3).

        Next-event estimation of one emitter per point and ray, and the BSSRDF path
        tracer's radiance along each cosine-distributed ray; an emitter a ray hits is
        weighted by the power heuristic against the emitter sampling's density, as the
        tracer weights the emitter its continuation hits.
        """
        mi = mitsuba()
        import drjit as dr
        from mitsuba.python.ad.integrators.common import mis_weight

        count = len(points) * self.rays
        origin = np.repeat(self.frame.point(points), self.rays, axis=0)
        normal = np.repeat(normals, self.rays, axis=0)
        # cosine-distributed directions about each normal
        u1, u2 = rng.random(count), rng.random(count)
        radius, phi = np.sqrt(u1), 2.0 * math.pi * u2
        local = np.stack([radius * np.cos(phi), radius * np.sin(phi),
                          np.sqrt(np.maximum(0.0, 1.0 - u1))], axis=1)
        helper = np.where(np.abs(normal[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
        tangent = np.cross(helper, normal)
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
        bitangent = np.cross(normal, tangent)
        direction = local[:, :1] * tangent + local[:, 1:2] * bitangent + local[:, 2:] * normal
        reach = ORIGIN_OFFSET * 1024.0
        start = origin + reach * normal

        def vector(values):
            return mi.Vector3f(*(mi.Float(np.ascontiguousarray(values[:, k], np.float32))
                                 for k in range(3)))

        scene = self.mitsuba_scene
        integrator = scene.integrator()
        sampler = mi.load_dict({"type": "independent"})
        sampler.seed(seed % 2**32, count)  # Mitsuba seeds are 32-bit
        it = dr.zeros(mi.SurfaceInteraction3f, count)
        it.p = vector(start)
        it.n = vector(normal)
        it.sh_frame = mi.Frame3f(it.n)
        # next-event estimation, every emitter kind
        ds, emitted = scene.sample_emitter_direction(it, sampler.next_2d(), True, True)
        cos_e = dr.dot(ds.d, it.n)
        usable = (ds.pdf != 0.0) & (cos_e > 0.0)
        weight_e = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, cos_e / math.pi))
        nee = dr.select(usable, emitted * weight_e, 0.0)
        # the tracer's radiance along the cosine rays, less the emitter it hits directly,
        # which comes back with its MIS weight
        ray = mi.Ray3f(it.p, vector(direction))
        radiance, _, _, _ = integrator.sample(dr.ADMode.Primal, scene, sampler, ray, None,
                                              None, mi.Bool(True))
        hit = scene.ray_intersect(ray)
        emitter = hit.emitter(scene)
        hit_emission = emitter.eval(hit, hit.is_valid())
        hit_ds = mi.DirectionSample3f(scene, si=hit, ref=it)
        hit_pdf = scene.pdf_emitter_direction(it, hit_ds, hit.is_valid())
        cos_r = mi.Float(np.ascontiguousarray(local[:, 2], np.float32))
        weight_r = mis_weight(cos_r / math.pi, hit_pdf)
        rays = radiance - hit_emission + dr.select(hit.is_valid(), hit_emission * weight_r,
                                                   0.0)
        nee_rgb, ray_rgb = _rgb(nee, count), _rgb(rays, count)
        cos_nee = np.array(cos_e, dtype=np.float64)
        fresnel_nee = fresnel_transmittance(eta, np.clip(cos_nee, 0.0, 1.0))
        fresnel_ray = fresnel_transmittance(eta, local[:, 2])
        per_ray = nee_rgb * (fresnel_nee * np.clip(cos_nee, 0.0, 1.0))[:, None] \
            + ray_rgb * (math.pi * fresnel_ray)[:, None]
        if not np.all(np.isfinite(per_ray)):
            raise InputError("the irradiance estimate of the geometry term is not finite",
                             field="scene", value=self.scene.name)
        return per_ray.reshape(len(points), self.rays, 3).mean(axis=1)
