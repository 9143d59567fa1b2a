"""The Dr.Jit code of ``volpath_mnee`` (:mod:`translucent.reference.manifold_nee` explains it).

Mitsuba's ``dr.syntax`` rewrites these functions and runs them with this module's globals,
so Mitsuba and Dr.Jit are imported at module level; this module is imported only once the
suite's backend has chosen a variant (:func:`translucent.reference.manifold_nee.register`).
"""

from __future__ import annotations

from ..backend import mitsuba

mi = mitsuba()

import drjit as dr  # noqa: E402  (after mitsuba(): it points Dr.Jit at a working libLLVM)
from mitsuba.python.ad.integrators.common import ADIntegrator, mis_weight  # noqa: E402

from .manifold_settings import (  # noqa: E402
    COUNTERS,
    DIFFERENCE_STEP,
    INTEGRATOR_NAME,
    MAX_ITERATIONS,
    MAX_TRIALS,
    MIN_STEP,
    POSITION_PRECISION,
    ROULETTE_TRANSMITTANCE,
    SAME_POINT,
    SEEDED_FRACTION,
    TOLERANCE,
)

__all__ = ["ManifoldVolpath"]

def index_spectrum(spec, idx):
    m = spec[0]
    m[idx == 1] = spec[1]
    m[idx == 2] = spec[2]
    return m

def tangent_frame(si):
    """Orthonormal basis (s, t) of the triangle's plane and the normal derivatives in it."""
    ng = si.n
    s = dr.normalize(si.dp_du - ng * dr.dot(ng, si.dp_du))
    s = dr.select(dr.all(dr.isfinite(s)), s, mi.coordinate_system(ng)[0])
    t = dr.cross(ng, s)
    # (a, b) in (s, t) -> (du, dv): invert [[s.dp_du, s.dp_dv], [t.dp_du, t.dp_dv]]
    m00, m01 = dr.dot(s, si.dp_du), dr.dot(s, si.dp_dv)
    m10, m11 = dr.dot(t, si.dp_du), dr.dot(t, si.dp_dv)
    det = m00 * m11 - m01 * m10
    usable = dr.abs(det) > 1e-12
    inv = dr.select(usable, dr.rcp(det), 0.0)
    dn_ds = (si.dn_du * m11 - si.dn_dv * m10) * inv
    dn_dt = (si.dn_dv * m00 - si.dn_du * m01) * inv
    return s, t, dn_ds, dn_dt

def refract_in(d, n, eta):
    """Direction of ``d`` (travelling towards a surface of outward normal ``n``) inside."""
    cos_i = -dr.dot(d, n)
    r = dr.rcp(eta)
    sin2_t = r * r * (1.0 - cos_i * cos_i)
    cos_t = dr.safe_sqrt(1.0 - sin2_t)
    return r * d + (r * cos_i - cos_t) * n

def skipped_length(ray, si):
    r"""Length along ``ray`` (just spawned at ``si``) that ``spawn_ray``'s offset skipped.

    The offset moves the origin :math:`\epsilon (1 + \max_k |p_k|)` along the normal, so the
    ray starts that over :math:`|\cos|` past the crossing: a path entering a medium would
    skip a shell of it (docs/references.md). 0 at grazing angles, where it is unbounded.
    """
    cosine = dr.abs(dr.dot(ray.d, si.n))
    return dr.select(cosine > 1e-4, dr.norm(ray.o - si.p) / cosine, 0.0)


class ManifoldVolpath(ADIntegrator):
    """``volpath`` with manifold next-event estimation (module docstring)."""

    def __init__(self, props):
        super().__init__(props)
        self.counters = [0] * len(COUNTERS)
        self.prepared_for = None
        # specular manifold sampling of the refraction points the straight start misses
        self.seeded_solutions = bool(props.get("seeded_solutions", False))

    # ------------------------------------------------------------------ set-up
    def prepare_scene(self, scene):
        """Find the lights a medium vertex connects to and the scene's media, once."""
        if self.prepared_for is scene:
            return
        connectable = []
        for emitter in scene.emitters():
            flags = emitter.flags()
            if (mi.has_flag(flags, mi.EmitterFlags.DeltaPosition)
                    or mi.has_flag(flags, mi.EmitterFlags.DeltaDirection)
                    or mi.has_flag(flags, mi.EmitterFlags.Surface)):
                connectable.append(emitter)
        self.connectable = mi.EmitterPtr(connectable) if connectable else None
        self.n_connectable = len(connectable)
        self.handle_null_scattering = any(
            medium is not None and not medium.is_homogeneous()
            for shape in scene.shapes()
            for medium in (shape.interior_medium(), shape.exterior_medium()))
        extent = scene.bbox().extents()
        self.scene_size = float(max(extent[0], extent[1], extent[2]))
        self.prepared_for = scene

    def reset_counts(self):
        """Start the counts (:data:`COUNTERS`) again from zero."""
        self.counters = [0] * len(COUNTERS)

    # ------------------------------------------------------------- transmittance
    @dr.syntax
    def transmittance(self, scene, sampler, origin, target, directional, medium,
                      channel, active):
        """Return the transmittance from ``origin`` to ``target``.

        ``origin`` is an Interaction3f, ``target`` a point or, when ``directional``, a
        direction: ratio tracking through media, null surfaces passed, any other surface
        blocks (as ``volpath``'s shadow rays).
        """
        active = mi.Bool(active)
        ray = origin.spawn_ray(dr.select(directional, target,
                                         dr.normalize(target - origin.p)))
        max_dist = dr.select(directional, dr.inf,
                             dr.norm(target - origin.p) * (1.0 - mi.math.ShadowEpsilon))
        total = mi.Float(0.0)
        tr = mi.Spectrum(1.0)
        # most shadow rays from inside a dielectric end on it: settle those with one ray
        ray.maxt = max_dist
        first = scene.ray_intersect(ray, mi.RayFlags.Minimal, False, active)
        blocked = active & first.is_valid() & ~mi.has_flag(first.bsdf().flags(),
                                                             mi.BSDFFlags.Null)
        tr[blocked] = 0.0
        active &= ~blocked
        medium = dr.select(active, medium, dr.zeros(mi.MediumPtr))
        si = dr.zeros(mi.SurfaceInteraction3f)
        needs_intersection = mi.Bool(True)
        lead = mi.Float(0.0)  # as in sample(): the shell spawn_ray's offset skipped
        while active:
            remaining = max_dist - total
            ray.maxt = remaining
            active &= remaining > 0.0
            needs_intersection &= active
            si[needs_intersection] = scene.ray_intersect(ray, needs_intersection)
            # a medium entered at a crossing starts there: measure from it
            shifted = needs_intersection & (medium != None)  # noqa: E711
            si.t[shifted] = si.t + lead
            ray.o[shifted] = ray.o - lead * ray.d
            lead[needs_intersection] = 0.0
            needs_intersection &= False
            in_medium = active & (medium != None)  # noqa: E711
            on_surface = active & ~in_medium
            mei = medium.sample_interaction(ray, sampler.next_1d(in_medium), channel,
                                            in_medium)
            mei.t[in_medium & (si.t < mei.t)] = dr.inf
            factor = mi.Spectrum(1.0)
            homogeneous = in_medium & medium.is_homogeneous()
            mei.t[homogeneous] = dr.minimum(remaining, si.t)
            factor[homogeneous] = medium.transmittance_eval_pdf(mei, si, homogeneous)[0]
            mei.t[homogeneous] = dr.inf
            escaped = in_medium & ~mei.is_valid()
            in_medium &= mei.is_valid()
            ray.o[in_medium] = mei.p
            si.t[in_medium] = si.t - mei.t
            factor[in_medium] *= mei.sigma_n / mei.combined_extinction
            on_surface |= escaped
            on_surface &= si.is_valid() & ~in_medium
            bsdf = si.bsdf(ray)
            factor[on_surface] *= bsdf.eval_null_transmission(si, on_surface)
            tr *= factor
            ray[on_surface] = si.spawn_ray(mi.Vector3f(ray.d))
            lead[on_surface] = skipped_length(ray, si)
            needs_intersection |= on_surface
            active &= (in_medium | on_surface) & dr.any(tr != 0.0)
            total[active] += dr.select(in_medium, mei.t, si.t)
            crossing = on_surface & si.is_medium_transition()
            medium[crossing] = si.target_medium(ray.d)
        return tr

    # -------------------------------------------------------------- the solve
    def constraint(self, to_v, to_light, n, s, t, directional, eta):
        """Return the Snell mismatch :math:`C` in the basis (s, t).

        ``to_v`` and ``to_light`` run from the boundary point to the vertex and to the
        light (the light's direction when ``directional``); ``n`` is the normal there.
        Differences, not positions: a vertex near the boundary keeps its precision.
        """
        wi = dr.normalize(to_v)
        wo = dr.normalize(to_light)
        w = wo + eta * wi
        tangential = w - n * dr.dot(n, w)
        return mi.Vector2f(dr.dot(tangential, s), dr.dot(tangential, t))

    def constraint_at(self, si, frame, v, light, directional, eta):
        """Return :math:`C` at the surface point ``si``."""
        to_light = dr.select(directional, light, light - si.p)
        return self.constraint(v - si.p, to_light, si.sh_frame.n, frame[0], frame[1],
                               directional, eta)

    def local_constraint(self, si, frame, a, b, to_v, to_light, directional, eta):
        """Return :math:`C` at tangent offset (a, b) of the first-order model about ``si``."""
        s, t, dn_ds, dn_dt = frame
        offset = a * s + b * t
        n = dr.normalize(si.sh_frame.n + a * dn_ds + b * dn_dt)
        moved_light = dr.select(directional, to_light, to_light - offset)
        return self.constraint(to_v - offset, moved_light, n, s, t, directional, eta)

    def tolerance(self, si, v):
        """Return :data:`TOLERANCE` plus what float32 positions allow at ``si``."""
        return TOLERANCE + POSITION_PRECISION * (1.0 + dr.max(dr.abs(si.p))) \
            / dr.maximum(dr.norm(v - si.p), 1e-30)

    @dr.syntax
    def solve(self, scene, v, si, light, directional, eta, active):
        """Newton's method on the boundary from ``si`` (module docstring).

        Returns the surface interaction reached and whether :math:`|C|` fell below
        :data:`TOLERANCE` there (plus what float32 positions allow: a vertex close to the
        boundary knows its direction to it only to :data:`POSITION_PRECISION` times the
        coordinates' size over the distance).
        """
        active = mi.Bool(active)
        si = mi.SurfaceInteraction3f(si)
        error = dr.norm(self.constraint_at(si, tangent_frame(si), v, light, directional,
                                           eta))
        converged = active & (error < self.tolerance(si, v))
        active &= ~converged
        beta = mi.Float(1.0)
        iteration = mi.UInt32(0)
        while active:
            frame = tangent_frame(si)
            to_v = v - si.p
            to_light = dr.select(directional, light, light - si.p)
            # the step of the differences follows the shorter lever: the vertex's distance
            h = DIFFERENCE_STEP * dr.minimum(dr.norm(to_v), dr.norm(to_light))
            ca = (self.local_constraint(si, frame, h, 0.0, to_v, to_light, directional, eta)
                  - self.local_constraint(si, frame, -h, 0.0, to_v, to_light, directional,
                                          eta)) / (2.0 * h)
            cb = (self.local_constraint(si, frame, 0.0, h, to_v, to_light, directional, eta)
                  - self.local_constraint(si, frame, 0.0, -h, to_v, to_light, directional,
                                          eta)) / (2.0 * h)
            c = self.constraint(to_v, to_light, si.sh_frame.n, frame[0], frame[1],
                                directional, eta)
            det = ca.x * cb.y - cb.x * ca.y
            step_a = -(cb.y * c.x - cb.x * c.y) / det
            step_b = -(ca.x * c.y - ca.y * c.x) / det
            step = beta * (step_a * frame[0] + step_b * frame[1])
            ray = mi.Ray3f(v, dr.normalize(step - to_v))
            candidate = scene.ray_intersect(ray, mi.RayFlags.All | mi.RayFlags.dNSdUV,
                                            False, active)
            leaves = (candidate.is_valid() & (dr.dot(ray.d, candidate.n) > 0.0)
                      & dr.all(dr.isfinite(step)))
            candidate_error = dr.norm(self.constraint_at(candidate, tangent_frame(candidate),
                                                         v, light, directional, eta))
            better = active & leaves & (candidate_error < error)
            si[better] = candidate
            error[better] = candidate_error
            beta = dr.select(better, dr.minimum(1.0, 2.0 * beta), 0.5 * beta)
            converged |= better & (error < self.tolerance(si, v))
            iteration += 1
            active &= ~converged & (iteration < MAX_ITERATIONS) & (beta >= MIN_STEP)
        return si, converged

    def geometry(self, si, v, light, directional, eta):
        r"""Return :math:`|d\omega_\ell| / |dA_\perp(v)|` (or the cross-section ratio) at ``si``."""
        frame = tangent_frame(si)
        s_axis, t_axis, dn_ds, dn_dt = frame
        distance = dr.norm(v - si.p)
        h = DIFFERENCE_STEP * (distance + self.scene_size)
        to_surface = si.p - light

        def beam(a, b):
            offset = a * s_axis + b * t_axis
            n = dr.normalize(si.sh_frame.n + a * dn_ds + b * dn_dt)
            d = dr.select(directional, -light, dr.normalize(to_surface + offset))
            return offset + distance * refract_in(d, n, eta), d

        xa1, da1 = beam(h, 0.0)
        xa0, da0 = beam(-h, 0.0)
        xb1, db1 = beam(0.0, h)
        xb0, db0 = beam(0.0, -h)
        axis = dr.normalize(v - si.p)
        area_at_v = dr.abs(dr.dot(dr.cross(xa1 - xa0, xb1 - xb0), axis))
        d0 = dr.select(directional, -light, dr.normalize(to_surface))
        solid_angle = dr.abs(dr.dot(dr.cross(da1 - da0, db1 - db0), d0))
        cross_section = dr.abs(dr.dot(si.n, d0)) * (4.0 * h * h)
        light_measure = dr.select(directional, cross_section, solid_angle)
        return dr.select(area_at_v > 0.0, light_measure / area_at_v, 0.0)

    def boundary_eta(self, si, active):
        """Relative index inside a smooth dielectric at ``si``, 0 where it is none."""
        bsdf = si.bsdf()
        ctx = mi.BSDFContext()
        probe = mi.SurfaceInteraction3f(si)
        probe.wi = mi.Vector3f(0.0, 0.0, -1.0)  # from inside, along the normal: no TIR
        bs, _ = bsdf.sample(ctx, probe, mi.Float(0.9999), mi.Point2f(0.5), active)
        dielectric = (active & mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaTransmission)
                      & ~mi.has_flag(bsdf.flags(), mi.BSDFFlags.Null) & (bs.pdf > 0))
        return dr.select(dielectric, dr.rcp(bs.eta), 0.0)

    def refracts(self, si, v, light, directional):
        """Whether the converged point ``si`` joins ``v`` and the light by a refraction."""
        wo = dr.select(directional, light, dr.normalize(light - si.p))
        wi = dr.normalize(v - si.p)
        normal = si.sh_frame.n
        return (dr.dot(wo, normal) > 0.0) & (dr.dot(wi, normal) < 0.0) \
            & (dr.dot(wo, si.n) > 0.0) & (dr.dot(wi, si.n) < 0.0)

    def same_point(self, v, a, b):
        """Whether two solves from ``v`` ended at the same boundary point (:data:`SAME_POINT`)."""
        return dr.norm(a - b) < SAME_POINT * (dr.norm(v - a) + self.scene_size)

    @dr.syntax
    def through(self, scene, sampler, mei, medium, channel, phase, phase_ctx, emitter, si,
                light, directional, area, ps, sample, eta, active):
        r"""Return ``phase * E_perp`` at ``mei`` from the light through refraction point ``si``."""
        result = mi.Spectrum(0.0)
        wo = dr.select(directional, light, dr.normalize(light - si.p))
        cos_o = dr.dot(wo, si.sh_frame.n)
        fresnel, _, _, _ = mi.fresnel(cos_o, eta)
        g = self.geometry(si, mei.p, light, directional, eta)
        # intensity towards y: delta lights from their own sampling at y
        it_y = dr.zeros(mi.Interaction3f)
        it_y.p = si.p + si.n * (mi.math.RayEpsilon * (1.0 + dr.max(dr.abs(si.p))))
        it_y.time = mei.time
        ds_y, weight_y = emitter.sample_direction(it_y, sample, active & ~area)
        intensity = dr.select(directional, weight_y, weight_y * dr.square(ds_y.dist))
        # area lights: radiance at the sampled point times its cosine over the area pdf
        si_l = mi.SurfaceInteraction3f(ps, dr.zeros(mi.Color0f))
        to_y = dr.normalize(si.p - ps.p)
        si_l.wi = si_l.to_local(to_y)
        radiance = emitter.eval(si_l, active & area)
        cos_l = dr.maximum(dr.dot(ps.n, to_y), 0.0)
        intensity[area] = radiance * cos_l * dr.select(ps.pdf > 0, dr.rcp(ps.pdf), 0.0)
        # the segment v -> y is clear by construction (y is the first hit from v): closed
        # form in a homogeneous medium, ratio tracking in others
        homogeneous = medium.is_homogeneous()
        inside = dr.exp(-mei.sigma_t * dr.norm(si.p - mei.p))
        tracked = active & ~homogeneous
        inside[tracked] = self.transmittance(scene, sampler, mi.Interaction3f(mei), si.p,
                                             mi.Bool(False), medium, channel, tracked)
        # outside: one shadow ray; the tracking loop only where it meets something
        outer_medium = si.target_medium(wo)
        shadow = mi.Ray3f(it_y.p, wo, dr.select(directional, dr.inf, dr.norm(light - it_y.p)
                                                * (1.0 - mi.math.ShadowEpsilon)))
        clear = ~scene.ray_test(shadow, active) & (outer_medium == None)  # noqa: E711
        outside = mi.Spectrum(1.0)
        tracked = active & ~clear
        outside[tracked] = self.transmittance(scene, sampler, mi.Interaction3f(it_y), light,
                                              directional, outer_medium, channel, tracked)
        value, _ = phase.eval_pdf(phase_ctx, mei, dr.normalize(si.p - mei.p), active)
        result[active] = value * intensity * (1.0 - fresnel) * g * inside * outside
        return result

    def exit_point(self, scene, v, d, active):
        """Return the first surface hit from ``v`` along ``d`` and whether the ray leaves there.

        The start of a solve: the straight line to the light, or a random seed direction.
        """
        start = scene.ray_intersect(mi.Ray3f(v, d), mi.RayFlags.All | mi.RayFlags.dNSdUV,
                                    False, active)
        return start, active & start.is_valid() & (dr.dot(d, start.n) > 0.0)

    def seed(self, scene, sampler, v, eta, active):
        """Return the boundary point hit from ``v`` along a uniform random direction (same eta)."""
        d = mi.warp.square_to_uniform_sphere(sampler.next_2d(active))
        start, usable = self.exit_point(scene, v, d, active)
        usable &= dr.abs(self.boundary_eta(start, usable) - eta) < 1e-6 * eta
        return start, usable

    @dr.syntax
    def other_solution(self, scene, sampler, v, known, known_valid, light, directional, eta,
                       active):
        r"""Specular manifold sampling of the refraction points the straight start misses.

        A solve from a random seed (:meth:`seed`, a uniform direction from ``v``) reaches
        refraction point :math:`y` with probability :math:`p(y)` (its basin's solid angle
        over :math:`4\pi`); weighting by :math:`1/p(y)`, and by zero where :math:`y` is the
        point ``known`` the straight start found, gives the sum over every other point
        (Zeltner, Georgiev and Jakob 2020, Eq. 10). :math:`1/p(y)` is estimated without
        bias by the number of further seeds until one reaches :math:`y` again (their
        Sect. 4.3), at most :data:`MAX_TRIALS`.

        Returns the point, whether one was found, the weight (the count of trials) and
        whether that count was cut.
        """
        active = mi.Bool(active)
        start, usable = self.seed(scene, sampler, v, eta, active)
        si, converged = self.solve(scene, v, start, light, directional, eta, usable)
        found = usable & converged & self.refracts(si, v, light, directional)
        found &= ~(known_valid & self.same_point(v, si.p, known.p))
        trials = mi.UInt32(0)
        matched = mi.Bool(False)
        searching = mi.Bool(found)
        while searching:
            trials += 1
            again, usable = self.seed(scene, sampler, v, eta, searching)
            reached, hit = self.solve(scene, v, again, light, directional, eta, usable)
            matched |= usable & hit & self.same_point(v, reached.p, si.p)
            searching &= ~matched & (trials < MAX_TRIALS)
        capped = found & ~matched
        return si, found, mi.Float(trials), capped

    @dr.syntax
    def connect(self, scene, sampler, mei, medium, channel, phase, phase_ctx, active):
        r"""Make the manifold next-event estimate at the medium vertices ``mei``.

        Returns ``phase * E_perp`` (times the emitter-selection weight) and the counts of
        what happened (:data:`COUNTERS`).
        """
        active = mi.Bool(active)
        choices = self.n_connectable
        index = dr.minimum(mi.UInt32(sampler.next_1d(active) * choices), choices - 1)
        emitter = dr.gather(mi.EmitterPtr, self.connectable, index, active)
        flags = emitter.flags()
        directional = mi.has_flag(flags, mi.EmitterFlags.DeltaDirection)
        area = mi.has_flag(flags, mi.EmitterFlags.Surface)
        sample = sampler.next_2d(active)
        it = mi.Interaction3f(mei)
        ds, _ = emitter.sample_direction(it, sample, active & ~area)
        ps, _ = emitter.sample_position(mei.time, sample, active & area)
        light = dr.select(directional, ds.d, dr.select(area, ps.p, ds.p))
        toward = dr.select(directional, light, dr.normalize(light - mei.p))
        first, active = self.exit_point(scene, mei.p, toward, active)
        # Russian roulette on the straight segment's transmittance (its clearest channel):
        # deep vertices, whose light is all but extinguished, rarely pay for a solve
        clearest = dr.exp(-dr.min(mei.sigma_t) * first.t)
        keep = dr.minimum(1.0, clearest / ROULETTE_TRANSMITTANCE)
        active &= sampler.next_1d(active) < keep
        eta = self.boundary_eta(first, active)
        active &= eta > 0.0
        attempted = mi.Bool(active)
        si, converged = self.solve(scene, mei.p, first, light, directional, eta, active)
        not_converged = active & ~converged
        valid = active & converged & self.refracts(si, mei.p, light, directional)
        not_refraction = active & converged & ~valid
        result = self.through(scene, sampler, mei, medium, channel, phase, phase_ctx,
                              emitter, si, light, directional, area, ps, sample, eta, valid)
        seeded = mi.Bool(False)
        capped = mi.Bool(False)
        if dr.hint(self.seeded_solutions, mode="scalar"):
            # area lights keep the partition with unidirectional hits (``covered``); a
            # fraction of the connections search, weighted by its inverse (unbiased)
            searches = attempted & ~area & (sampler.next_1d(attempted) < SEEDED_FRACTION)
            other, seeded, trials, capped = self.other_solution(
                scene, sampler, mei.p, si, valid, light, directional, eta, searches)
            found = self.through(scene, sampler, mei, medium, channel, phase, phase_ctx,
                                 emitter, other, light, directional, area, ps, sample, eta,
                                 seeded)
            result += (trials / SEEDED_FRACTION) * found
        # only where a connection was made: elsewhere keep may be 0
        result = dr.select(attempted, result * (choices / keep), 0.0)
        tally = (attempted, valid, not_converged, not_refraction, seeded, capped)
        return result, tally

    def covered(self, scene, v, y, light, active):
        """Whether the solver, from the straight line ``v``-``light``, reaches ``y``."""
        first, active = self.exit_point(scene, v, dr.normalize(light - v), active)
        eta = self.boundary_eta(first, active)
        active &= eta > 0.0
        si, converged = self.solve(scene, v, first, light, mi.Bool(False), eta, active)
        return active & converged & self.same_point(v, y, si.p)

    # ------------------------------------------------------------- the path
    @dr.syntax
    def sample(self, mode, scene, sampler, ray, δL, state_in, active, **kwargs):
        """Trace one path per lane (Mitsuba's ``ADIntegrator`` interface, primal only)."""
        if mode != dr.ADMode.Primal:
            raise RuntimeError(f"{INTEGRATOR_NAME} renders primal images only")
        self.prepare_scene(scene)
        ray = mi.Ray3f(ray)
        depth = mi.UInt32(0)
        L = mi.Spectrum(0.0)
        throughput = mi.Spectrum(1.0)
        eta_path = mi.Float(1.0)
        active = mi.Bool(active)
        si = dr.zeros(mi.SurfaceInteraction3f)
        needs_intersection = mi.Bool(True)
        last_scatter_event = dr.zeros(mi.Interaction3f)
        last_scatter_direction_pdf = mi.Float(1.0)
        medium = dr.zeros(mi.MediumPtr)
        valid_ray = mi.Bool(False)
        specular_chain = mi.Bool(True)
        # since the last medium vertex: how many delta surface events, and the last one
        after_medium = mi.Bool(False)
        delta_events = mi.UInt32(0)
        refraction_point = mi.Point3f(0.0)
        n_channels = dr.size_v(mi.Spectrum)
        channel = mi.UInt32(dr.minimum(n_channels * sampler.next_1d(active),
                                       n_channels - 1))
        # per path, summed after the loop (one variable each: loop state is found by name)
        n_connections, n_solved = mi.UInt32(0), mi.UInt32(0)
        n_not_converged, n_not_refraction, n_kept = mi.UInt32(0), mi.UInt32(0), mi.UInt32(0)
        n_seeded, n_capped = mi.UInt32(0), mi.UInt32(0)
        medium_vertex = mi.Point3f(0.0)
        # what spawn_ray's offset skipped of the medium this ray enters (skipped_length)
        lead = mi.Float(0.0)

        while active:
            active &= dr.any(throughput != 0.0)
            # Russian roulette exactly as volpath: keep with min(max(T) eta^2, 0.95)
            q = dr.minimum(dr.max(throughput) * dr.square(eta_path), 0.95)
            perform_rr = depth > self.rr_depth
            active &= (sampler.next_1d(active) < q) | ~perform_rr
            throughput[perform_rr] = throughput * dr.rcp(q)

            active_medium = active & (medium != None)  # noqa: E711
            active_surface = active & ~active_medium

            # ----------------------------------------------- medium sampling
            u = sampler.next_1d(active_medium)
            # the medium starts at the crossing, not at the offset origin: sample it from
            # there, intersect from the offset origin (the crossing would find its own
            # surface), and measure the hit from the crossing
            lead[~active_medium] = 0.0
            offset_origin = mi.Point3f(ray.o)
            ray.o[active_medium] = offset_origin - lead * ray.d
            crossing = mi.Point3f(ray.o)
            mei = medium.sample_interaction(ray, u, channel, active_medium)
            ray.maxt[active_medium & medium.is_homogeneous() & mei.is_valid()] = mei.t
            # a vertex inside the skipped shell lies before the offset origin: no surface
            # between (the crossing's own surface is behind it)
            in_shell = active_medium & (ray.maxt <= lead)
            intersect = needs_intersection & active_medium & ~in_shell
            ray.o[intersect] = offset_origin
            ray.maxt[intersect] = ray.maxt - lead
            si[intersect] = scene.ray_intersect(ray, intersect)
            si.t[intersect] = si.t + lead
            si.t[needs_intersection & in_shell] = dr.inf
            ray.o[active_medium] = crossing
            ray.maxt[intersect] = ray.maxt + lead
            lead[active_medium] = 0.0
            needs_intersection &= ~active_medium
            mei.t[active_medium & (si.t < mei.t)] = dr.inf
            tr, free_flight_pdf = medium.transmittance_eval_pdf(mei, si, active_medium)
            tr_pdf = index_spectrum(free_flight_pdf, channel)
            weight = mi.Spectrum(1.0)
            weight[active_medium] *= dr.select(tr_pdf > 0.0, tr / tr_pdf, 0.0)
            escaped_medium = active_medium & ~mei.is_valid()
            active_medium &= mei.is_valid()
            if dr.hint(self.handle_null_scattering, mode="scalar"):
                scatter_prob = dr.mean(mei.sigma_t / mei.combined_extinction)
                act_null = (sampler.next_1d(active_medium) >= scatter_prob) & active_medium
                act_medium_scatter = ~act_null & active_medium
                weight[act_null] *= mei.sigma_n / (1.0 - scatter_prob)
            else:
                scatter_prob = mi.Float(1.0)
                act_null = mi.Bool(False)
                act_medium_scatter = mi.Bool(active_medium)
            depth[act_medium_scatter] += 1
            last_scatter_event[act_medium_scatter] = mei
            active &= depth < self.max_depth
            act_medium_scatter &= active
            ray.o[act_null] = mei.p
            si.t[act_null] = si.t - mei.t
            weight[act_medium_scatter] *= mei.sigma_s / scatter_prob
            throughput *= weight

            phase_ctx = mi.PhaseFunctionContext(sampler)
            phase = mei.medium.phase_function()
            phase[~act_medium_scatter] = dr.zeros(mi.PhaseFunctionPtr)

            # ----------------------------------------------- surfaces, emitter hits
            active_surface |= escaped_medium
            intersect = active_surface & needs_intersection
            si[intersect] = scene.ray_intersect(ray, intersect)
            ray_from_camera = active_surface & (depth == 0)
            count_direct = ray_from_camera | specular_chain
            emitter = si.emitter(scene)
            active_e = active_surface & (emitter != None)  # noqa: E711
            # one refraction after a medium vertex into an area light: the manifold
            # connection counted it unless its solver would have missed this path
            once_refracted = active_e & after_medium & (delta_events == 1) \
                & mi.has_flag(emitter.flags(), mi.EmitterFlags.Surface)
            skip = mi.Bool(False)
            if dr.hint(self.connectable is not None, mode="scalar"):
                skip = once_refracted & self.covered(scene, medium_vertex,
                                                     refraction_point, si.p,
                                                     once_refracted)
            n_kept += dr.select(once_refracted & ~skip, 1, 0)
            active_e &= ~skip
            ds = mi.DirectionSample3f(scene, si, last_scatter_event)
            emitter_pdf = scene.pdf_emitter_direction(last_scatter_event, ds, active_e)
            emitted = emitter.eval(si, active_e)
            contrib = dr.select(count_direct, throughput * emitted,
                                throughput * mis_weight(last_scatter_direction_pdf,
                                                        emitter_pdf) * emitted)
            L[active_e] += contrib

            active_surface &= si.is_valid()
            ctx = mi.BSDFContext()
            bsdf = si.bsdf(ray)

            # ----------------------------------------------- next-event estimation
            active_e_surface = active_surface & mi.has_flag(bsdf.flags(),
                                                            mi.BSDFFlags.Smooth) \
                & (depth + 1 < self.max_depth)
            sample_emitters = mei.medium.use_emitter_sampling()
            specular_chain &= ~act_medium_scatter
            specular_chain |= act_medium_scatter & ~sample_emitters
            active_e_medium = act_medium_scatter & sample_emitters
            active_nee = active_e_surface | active_e_medium
            reference = dr.zeros(mi.Interaction3f)
            reference[active_e_medium] = mei
            reference[active_e_surface] = si
            ds, emitter_val = scene.sample_emitter_direction(reference,
                                                             sampler.next_2d(active_nee),
                                                             False, active_nee)
            active_nee &= ds.pdf != 0.0
            nee_medium = dr.select(active_nee, medium, dr.zeros(mi.MediumPtr))
            nee_medium[active_e_surface & si.is_medium_transition()] = \
                si.target_medium(ds.d)
            shadow = self.transmittance(scene, sampler, reference, ds.p, mi.Bool(False),
                                        nee_medium, channel, active_nee)
            emitted = emitter_val * shadow
            bsdf_val, bsdf_pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds.d), active_e_surface)
            phase_val, phase_pdf = phase.eval_pdf(phase_ctx, mei, ds.d, active_e_medium)
            nee_weight = dr.select(active_e_surface, bsdf_val, phase_val)
            nee_pdf = dr.select(ds.delta, 0.0,
                                dr.select(active_e_surface, bsdf_pdf, phase_pdf))
            L[active_nee] += throughput * nee_weight * mis_weight(ds.pdf, nee_pdf) * emitted

            if dr.hint(self.connectable is not None, mode="scalar"):
                # manifold next-event estimation through the boundary
                radiance, events = self.connect(scene, sampler, mei, medium, channel, phase,
                                                phase_ctx, active_e_medium)
                n_connections += dr.select(events[0], 1, 0)
                n_solved += dr.select(events[1], 1, 0)
                n_not_converged += dr.select(events[2], 1, 0)
                n_not_refraction += dr.select(events[3], 1, 0)
                n_seeded += dr.select(events[4], 1, 0)
                n_capped += dr.select(events[5], 1, 0)
                L[active_e_medium] += throughput * radiance
            after_medium |= act_medium_scatter
            medium_vertex[act_medium_scatter] = mei.p
            delta_events[act_medium_scatter] = 0

            # ----------------------------------------------- phase sampling
            valid_ray |= act_medium_scatter
            wo, phase_weight, phase_pdf = phase.sample(phase_ctx, mei,
                                                       sampler.next_1d(act_medium_scatter),
                                                       sampler.next_2d(act_medium_scatter),
                                                       act_medium_scatter)
            act_medium_scatter &= phase_pdf > 0.0
            throughput[act_medium_scatter] *= phase_weight
            ray[act_medium_scatter] = mei.spawn_ray(wo)
            lead[act_medium_scatter] = 0.0
            needs_intersection |= act_medium_scatter
            last_scatter_direction_pdf[act_medium_scatter] = phase_pdf

            # ----------------------------------------------- BSDF sampling
            bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(active_surface),
                                          sampler.next_2d(active_surface), active_surface)
            active_surface &= bs.pdf > 0
            throughput[active_surface] *= bsdf_weight
            eta_path[active_surface] *= bs.eta
            ray[active_surface] = si.spawn_ray(si.to_world(bs.wo))
            lead[active_surface] = skipped_length(ray, si)
            needs_intersection |= active_surface
            non_null_bsdf = active_surface & ~mi.has_flag(bs.sampled_type,
                                                          mi.BSDFFlags.Null)
            depth[non_null_bsdf] += 1
            last_scatter_event[non_null_bsdf] = si
            last_scatter_direction_pdf[non_null_bsdf] = bs.pdf
            delta = non_null_bsdf & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
            refraction_point[delta & (delta_events == 0)] = si.p
            delta_events[delta] += 1
            after_medium &= ~(non_null_bsdf & ~delta)
            valid_ray |= non_null_bsdf
            specular_chain |= delta
            specular_chain &= ~(active_surface & mi.has_flag(bs.sampled_type,
                                                             mi.BSDFFlags.Smooth))
            has_medium_trans = active_surface & si.is_medium_transition()
            medium[has_medium_trans] = si.target_medium(ray.d)
            active &= active_surface | active_medium

        tally = (n_connections, n_solved, n_not_converged, n_not_refraction, n_kept,
                 n_seeded, n_capped)
        for k, count in enumerate(tally):
            self.counters[k] += int(dr.sum(count, mode="evaluated")[0])
        return L, valid_ray, [], L

    def to_string(self):
        """Describe the integrator as Mitsuba prints it."""
        return (f"ManifoldVolpath[max_depth = {self.max_depth}, rr_depth = {self.rr_depth}, "
                f"seeded_solutions = {self.seeded_solutions}]")
