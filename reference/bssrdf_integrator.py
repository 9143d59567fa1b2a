"""The Dr.Jit code of ``bssrdf_path`` (:mod:`translucent.reference.bssrdf_path` explains it).

Mitsuba's ``dr.syntax`` rewrites these functions and runs them with this module's globals,
so Mitsuba and Dr.Jit are imported at module level; this module is imported only once the
suite's backend has chosen a variant (:func:`translucent.reference.bssrdf_path.register`).
"""

from __future__ import annotations

import math

from ..backend import mitsuba

mi = mitsuba()

import drjit as dr  # noqa: E402  (after mitsuba(): it points Dr.Jit at a working libLLVM)
from mitsuba.python.ad.integrators.common import ADIntegrator, mis_weight  # noqa: E402

from ..errors import InputError  # noqa: E402
from .bssrdf_profile import ProfileLookup  # noqa: E402
from .bssrdf_tables import AXIS_PROBABILITIES, registered_tables  # noqa: E402

__all__ = ["BSSRDFPath", "MAX_PROBE_HITS", "copy_mesh"]

#: Crossings of one probe segment followed at most (a segment through a closed mesh of a
#: few folds crosses it a handful of times; the count only stops a lane that never ends).
MAX_PROBE_HITS = 64

#: The integrator's name in Mitsuba.
INTEGRATOR_NAME = "bssrdf_path"


def copy_mesh(shape, name: str):
    """Return a new Mitsuba mesh with ``shape``'s positions, faces and normals."""
    params = mi.traverse(shape)
    has_normals = shape.has_vertex_normals()
    mesh = mi.Mesh(name, shape.vertex_count(), shape.face_count(),
                   has_vertex_normals=has_normals)
    copied = mi.traverse(mesh)
    copied["vertex_positions"] = mi.Float(params["vertex_positions"])
    copied["faces"] = mi.UInt32(params["faces"])
    if has_normals:
        copied["vertex_normals"] = mi.Float(params["vertex_normals"])
    copied.update()
    return mesh


class BSSRDFPath(ADIntegrator):
    """Path tracing with a tabulated BSSRDF on the translucent objects (module docstring)."""

    def __init__(self, props):
        super().__init__(props)
        name = str(props.get("tables", ""))
        try:
            self.tables = registered_tables(name)
        except InputError:  # a file named by an exported scene, beside its XML
            resolver = mi.file_resolver() if hasattr(mi, "file_resolver") \
                else mi.Thread.thread().file_resolver()
            resolved = resolver.resolve(name)
            self.tables = registered_tables(str(resolved))
        self.prepared_for = None

    # ------------------------------------------------------------------ set-up
    def prepare_scene(self, scene):
        """Find the translucent shapes, copy them into the probe scene, upload the tables."""
        if self.prepared_for is scene:
            return
        shapes = {shape.id(): shape for shape in scene.shapes()}
        missing = [key for key in self.tables.shape_ids if key not in shapes]
        if missing:
            raise InputError("the scene has no shape of this id for a translucent object; "
                             f"shapes: {', '.join(sorted(shapes))}", field="tables",
                             value=missing[0])
        self.targets = [mi.ShapePtr(shapes[key]) for key in self.tables.shape_ids]
        probe = {"type": "scene"}
        for k, key in enumerate(self.tables.shape_ids):
            if not isinstance(shapes[key], mi.Mesh):
                raise InputError("bssrdf_path needs a triangle mesh for a translucent object",
                                 field="shape", value=key)
            probe[f"probe_{k}"] = copy_mesh(shapes[key], f"probe_{k}")
        self.probe_scene = mi.load_dict(probe)
        copies = {shape.id(): shape for shape in self.probe_scene.shapes()}
        self.probe_targets = mi.ShapePtr([copies[f"probe_{k}"]
                                          for k in range(self.tables.count)])
        self.lookup = ProfileLookup(self.tables)
        self.eta = mi.Float(self.tables.eta)
        self.exit_norm = mi.Float(self.tables.exit_normalisation)
        self.mm_per_unit = float(self.tables.mm_per_unit)
        self.prepared_for = scene

    def object_index(self, si):
        """Return the translucent object a surface interaction lies on (-1: none)."""
        index = mi.Int32(-1)
        for k, target in enumerate(self.targets):
            index = dr.select(si.shape == target, k, index)
        return index

    # ---------------------------------------------------------- exit sampling
    @dr.syntax
    def probe(self, start, axis, length, target, sampler, active):
        """Every crossing of the segment with the target shape; one chosen uniformly.

        Returns the chosen crossing and the number of crossings (reservoir sampling of
        one among them, pbrt-v4's ``WeightedReservoirSampler`` with unit weights).
        """
        ray = mi.Ray3f(start, axis)
        ray.maxt = length
        hits = mi.UInt32(0)
        chosen = dr.zeros(mi.SurfaceInteraction3f)
        probing = mi.Bool(active)
        steps = mi.UInt32(0)
        while probing:
            hit = self.probe_scene.ray_intersect(ray, mi.RayFlags.All, False, probing)
            probing &= hit.is_valid()
            same = probing & (hit.shape == target)
            hits[same] += 1
            take = same & (sampler.next_1d(same) * mi.Float(hits) < 1.0)
            chosen[take] = hit
            following = hit.spawn_ray(axis)
            following.maxt = length - dr.dot(following.o - start, axis)
            ray[probing] = following
            steps += 1
            probing &= (following.maxt > 0.0) & (steps < MAX_PROBE_HITS)
        return chosen, hits

    def exit_pdf(self, xo, frame, obj, p, n, active):
        r"""Density (mm^-2) of the exit point ``p`` over all axes and channels (one-sample MIS).

        :math:`\sum_a \sum_c P_a P_c\, q_c(r_a)\,|n\cdot a|\,[|p - x_o| \le r_{\max,c}]`:
        the density of probe crossings of strategy (axis, channel) at ``p`` (pbrt-v4
        ``PDF_Sp`` with a channel mixture in place of its hero wavelength).
        """
        d = (p - xo) * self.mm_per_unit
        local = frame.to_local(d)
        normal = frame.to_local(n)
        distance = dr.norm(d)
        projected = (dr.sqrt(dr.square(local.y) + dr.square(local.z)),
                     dr.sqrt(dr.square(local.z) + dr.square(local.x)),
                     dr.sqrt(dr.square(local.x) + dr.square(local.y)))
        cosines = (dr.abs(normal.x), dr.abs(normal.y), dr.abs(normal.z))
        total = mi.Float(0.0)
        for c in range(3):
            row = 3 * obj + c
            chance = dr.gather(mi.Float, self.lookup.channel_probability, row, active)
            reach = dr.gather(mi.Float, self.lookup.max_radius, row, active)
            inside = active & (chance > 0.0) & (distance <= reach)
            for a in range(3):
                disk = self.lookup.disk_pdf(row, projected[a], inside)
                total += dr.select(inside, AXIS_PROBABILITIES[a] * chance * disk * cosines[a],
                                   0.0)
        return total

    def sample_exit(self, sampler, si, obj, active):
        """Sample where light entered, by a probe segment (pbrt-v4 ``SampleSp``).

        Returns the exit interaction, whether one was found, and the weight
        ``crossings / (pdf * pi (1 - F_dr))`` that multiplies ``R * F_t * cos``.
        """
        active = mi.Bool(active)
        lookup = self.lookup
        chance_r = dr.gather(mi.Float, lookup.channel_probability, 3 * obj, active)
        chance_g = dr.gather(mi.Float, lookup.channel_probability, 3 * obj + 1, active)
        u = sampler.next_1d(active)
        channel = dr.select(u < chance_r, 0, dr.select(u < chance_r + chance_g, 1, 2))
        row = 3 * obj + mi.UInt32(channel)
        frame = mi.Frame3f(si.sh_frame.n)
        u = sampler.next_1d(active)
        first, second = AXIS_PROBABILITIES[0], AXIS_PROBABILITIES[0] + AXIS_PROBABILITIES[1]
        axis = dr.select(u < first, frame.s, dr.select(u < second, frame.t, frame.n))
        tangent_1 = dr.select(u < first, frame.t, dr.select(u < second, frame.n, frame.s))
        tangent_2 = dr.select(u < first, frame.n, dr.select(u < second, frame.s, frame.t))
        radius = lookup.sample_radius(row, sampler.next_1d(active), active)
        reach = dr.gather(mi.Float, lookup.max_radius, row, active)
        active &= radius < reach
        phi = 2.0 * math.pi * sampler.next_1d(active)
        half = dr.safe_sqrt(dr.square(reach) - dr.square(radius))
        scale = 1.0 / self.mm_per_unit
        offset = (radius * (dr.cos(phi) * tangent_1 + dr.sin(phi) * tangent_2)
                  - half * axis) * scale
        start = si.p + offset
        target = dr.gather(mi.ShapePtr, self.probe_targets, obj, active)
        chosen, hits = self.probe(start, axis, 2.0 * half * scale, target, sampler, active)
        found = active & (hits > 0)
        pdf = self.exit_pdf(si.p, frame, obj, chosen.p, chosen.n, found)
        found &= pdf > 0.0
        norm = dr.gather(mi.Float, self.exit_norm, obj, found)
        weight = dr.select(found, mi.Float(hits) / (pdf * norm), 0.0)
        return chosen, found, weight

    def profile_value(self, obj, xo, xi, wi, radial, active):
        """:math:`R` between ``xi`` and ``xo`` (mm^-2), light arriving at ``xi`` from ``wi``.

        ``radial``: the radial profile's value there, which the directional dipole replaces
        on its objects.
        """
        value = mi.Spectrum(radial)
        if dr.hint(self.lookup.any_directional, mode="scalar"):
            directional = active & self.lookup.is_directional(obj, active)
            value[directional] = self.lookup.directional_reflectance(
                obj, (xo - xi.p) * self.mm_per_unit, xi.sh_frame.n, wi,
                dr.gather(mi.Float, self.eta, obj, directional), directional)
        return value

    # ------------------------------------------------------------- the path
    @dr.syntax
    def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):
        """Trace one path per lane (Mitsuba's ``ADIntegrator`` interface, primal only)."""
        if mode != dr.ADMode.Primal:
            raise RuntimeError(f"{INTEGRATOR_NAME} renders primal images only")
        self.prepare_scene(scene)
        ctx = mi.BSDFContext()
        ray = mi.Ray3f(ray)
        depth = mi.UInt32(0)
        L = mi.Spectrum(0.0)
        β = mi.Spectrum(1.0)
        η = mi.Float(1.0)
        active = mi.Bool(active)
        prev_si = dr.zeros(mi.SurfaceInteraction3f)
        prev_pdf = mi.Float(1.0)
        prev_delta = mi.Bool(True)

        while active:
            si = scene.ray_intersect(ray, mi.RayFlags.All, False, active)

            # ----------------------------------------------- emitters hit
            ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
            em_pdf = scene.pdf_emitter_direction(prev_si, ds, active & ~prev_delta)
            L += β * mis_weight(prev_pdf, em_pdf) * ds.emitter.eval(si, active)

            active_next = active & (depth + 1 < self.max_depth) & si.is_valid()
            obj_index = self.object_index(si)
            translucent = active_next & (obj_index >= 0)
            opaque = active_next & ~translucent
            obj = mi.UInt32(dr.maximum(obj_index, 0))
            on_translucent = mi.Bool(translucent)

            # ----------------------------------------------- opaque: as Mitsuba's path
            bsdf = si.bsdf(ray)
            active_em = opaque & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
            ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True,
                                                           active_em)
            active_em &= ds.pdf != 0.0
            f_em, pdf_em = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), active_em)
            mis_em = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, pdf_em))
            L[active_em] += β * mis_em * f_em * em_weight
            bs, weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), opaque)
            ray_next = si.spawn_ray(si.to_world(bs.wo))
            next_si = mi.SurfaceInteraction3f(si)
            next_pdf = mi.Float(bs.pdf)
            next_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            η[opaque] *= bs.eta
            weight[on_translucent] = 0.0  # unless reflected or transmitted below

            # ----------------------------------------------- translucent: the BSSRDF
            eta = dr.gather(mi.Float, self.eta, obj, translucent)
            cos_o = mi.Frame3f.cos_theta(si.wi)
            translucent &= (cos_o > 0.0) & (dr.dot(si.n, ray.d) < 0.0)  # seen from outside
            fresnel_o, _, _, _ = mi.fresnel(cos_o, eta)
            reflect = translucent & (sampler.next_1d(translucent) < fresnel_o)
            transmit = translucent & ~reflect
            # specular reflection of the boundary, chosen with probability F_r: weight 1
            mirrored = si.to_world(mi.reflect(si.wi))
            reflect &= dr.dot(mirrored, si.n) > 0.0
            ray_next[reflect] = si.spawn_ray(mirrored)
            weight[reflect] = 1.0
            next_pdf[reflect] = 1.0
            next_delta[reflect] = True
            # transmission, chosen with probability F_t(wo): the exit term's F_t cancels
            xi, found, exit_weight = self.sample_exit(sampler, si, obj, transmit)
            radial = self.lookup.mixed_reflectance(
                obj, si.p, xi.p, dr.norm(si.p - xi.p) * self.mm_per_unit, found)
            # next-event estimation at the exit point (every kind of emitter)
            active_e = mi.Bool(found)
            ds, em_weight = scene.sample_emitter_direction(xi, sampler.next_2d(active_e),
                                                           True, active_e)
            cos_e = dr.dot(ds.d, xi.sh_frame.n)
            active_e &= (ds.pdf != 0.0) & (cos_e > 0.0) & (dr.dot(ds.d, xi.n) > 0.0)
            fresnel_e, _, _, _ = mi.fresnel(cos_e, eta)
            value = self.profile_value(obj, si.p, xi, ds.d, radial, active_e) \
                * ((1.0 - fresnel_e) * cos_e * exit_weight)
            mis_e = dr.select(ds.delta, 1.0, mis_weight(ds.pdf, cos_e / math.pi))
            L[active_e] += β * mis_e * value * em_weight
            # the path goes on from the exit point, cosine-distributed
            wi_local = mi.warp.square_to_cosine_hemisphere(sampler.next_2d(found))
            wi = xi.sh_frame.to_world(wi_local)
            leaves = found & (dr.dot(wi, xi.n) > 0.0) & (wi_local.z > 0.0)
            fresnel_i, _, _, _ = mi.fresnel(wi_local.z, eta)
            weight[transmit] = dr.select(
                leaves, self.profile_value(obj, si.p, xi, wi, radial, leaves)
                * ((1.0 - fresnel_i) * math.pi * exit_weight), 0.0)
            ray_next[leaves] = xi.spawn_ray(wi)
            next_si[transmit] = xi
            next_pdf[transmit] = wi_local.z / math.pi
            next_delta[transmit] = False

            # ----------------------------------------------- on to the next vertex
            β[active_next] *= weight
            β[~active_next] = 0.0
            prev_si = next_si
            prev_pdf = next_pdf
            prev_delta = next_delta
            ray = ray_next
            β_max = dr.max(β)
            active_next &= β_max != 0.0
            rr_prob = dr.minimum(β_max * dr.square(η), 0.95)
            rr_active = depth >= self.rr_depth
            β[rr_active] *= dr.rcp(rr_prob)
            active_next &= ~rr_active | (sampler.next_1d() < rr_prob)
            depth[si.is_valid()] += 1
            active = active_next

        return L, mi.Bool(True), [], L

    def to_string(self):
        """Describe the integrator as Mitsuba prints it."""
        return (f"BSSRDFPath[max_depth = {self.max_depth}, rr_depth = {self.rr_depth}, "
                f"objects = {list(self.tables.shape_ids)}]")
