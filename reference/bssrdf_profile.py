r"""The profile tables of ``bssrdf_path`` on the device: lookups, radius sampling, densities.

:class:`ProfileLookup` holds :class:`~translucent.reference.bssrdf_tables.ProfileTables` as
Dr.Jit arrays (float32) and reads them per lane: the node of a radius in O(1) from its
logarithm (the nodes past the first are geometric), the density :math:`p_c(r)` linear
between nodes, the radius of a uniform number by a binary search in the cumulative and the
closed-form inverse of the segment's quadratic (as
:meth:`~translucent.materials.profiles.sampling.RadialSampler.sample`). The directional
dipole (Frisvad et al. 2014) is evaluated in closed form with each lane's incident
direction (:meth:`ProfileLookup.directional_reflectance`).

Imported once the suite's backend has chosen a variant (it imports Mitsuba at module level).
"""

from __future__ import annotations

import math

from ..backend import mitsuba

mi = mitsuba()

import drjit as dr  # noqa: E402  (after mitsuba(): it points Dr.Jit at a working libLLVM)

from .bssrdf_tables import RULE_CODES, SEGMENT_POINTS  # noqa: E402

__all__ = ["ProfileLookup"]

#: Radii below this (mm) are taken as this where the disk density divides by 2 pi r.
SMALLEST_RADIUS = 1e-30


def _floats(values):
    import numpy as np

    return mi.Float(np.ascontiguousarray(values, dtype=np.float32).ravel())


class ProfileLookup:
    """The tables as Dr.Jit arrays; row ``3 o + c`` is object o's channel c.

    Parameters
    ----------
    tables : ProfileTables
    """

    def __init__(self, tables):
        self.nodes = int(tables.nodes)
        self.radius = _floats(tables.radius)
        self.density = _floats(tables.density)
        self.cumulative = _floats(tables.cumulative)
        self.energy = _floats(tables.energy)
        self.max_radius = _floats(tables.max_radius)
        self.channel_probability = _floats(tables.channel_probability)
        self.first_node = _floats(tables.first_node)
        self.inverse_log_step = _floats(tables.inverse_log_step)
        self.cut_radius = _floats(tables.max_radius.reshape(-1, 3).max(axis=1))
        self.any_directional = bool((tables.directional > 0).any())
        self.directional = _floats(tables.directional)
        self.dd_diffusion = _floats(tables.dd_diffusion)
        self.dd_sigma_tr = _floats(tables.dd_sigma_tr)
        self.dd_extrapolation = _floats(tables.dd_extrapolation)
        self.dd_boundary = _floats(tables.dd_boundary)
        self.dd_c_phi = _floats(tables.dd_c_phi)
        self.dd_c_e = _floats(tables.dd_c_e)
        # heterogeneous objects: the rule, the media's entries, the voxels' labels
        rules = tables.rule.astype(int)
        self.any_geometric_mean = bool((rules == RULE_CODES["geometric_mean"]).any())
        self.any_segment_mix = bool((rules == RULE_CODES["segment_mix"]).any())
        self.any_segment_average = bool((rules == RULE_CODES["segment_average"]).any())
        along = (rules == RULE_CODES["segment_mix"]) | (rules == RULE_CODES["segment_average"])
        self.most_media = int(tables.media_count[along].max(initial=0))
        self.sigma_a = _floats(tables.sigma_a)
        self.sigma_s_prime = _floats(tables.sigma_s_prime)
        self.boundary = _floats(tables.boundary)
        self.rule = mi.UInt32(rules.astype("uint32"))
        self.media_first = mi.UInt32(tables.media_first.astype("uint32"))
        self.media_count = mi.UInt32(tables.media_count.astype("uint32"))
        self.label_first = mi.UInt32(tables.label_first.astype("uint32"))
        self.label_lower = _floats(tables.label_lower)
        self.label_extent = _floats(tables.label_extent)
        self.label_shape = mi.UInt32(tables.label_shape.astype("uint32"))
        self.labels = mi.UInt32(tables.labels.astype("uint32"))
        self.value_at_zero = _floats(tables.value_at_zero)

    # ------------------------------------------------------------ one row
    def segment(self, row, r, active):
        """Return the node index k and the nodes r_k, r_{k+1} around ``r`` (mm) of ``row``."""
        last = self.nodes - 2
        base = row * self.nodes
        first = dr.gather(mi.Float, self.first_node, row, active)
        position = dr.log(dr.maximum(r, SMALLEST_RADIUS) / first) \
            * dr.gather(mi.Float, self.inverse_log_step, row, active)
        k = dr.select(r < first, 0, mi.Int32(dr.floor(position)) + 1)
        k = dr.clip(k, 0, last)
        left = dr.gather(mi.Float, self.radius, base + mi.UInt32(k), active)
        right = dr.gather(mi.Float, self.radius, base + mi.UInt32(k) + 1, active)
        # the float32 logarithm may land one node off at a node: step back or on once
        down = (r < left) & (k > 0)
        up = (r >= right) & (k < last)
        k = k - dr.select(down, 1, 0) + dr.select(up, 1, 0)
        moved = active & (down | up)
        left[moved] = dr.gather(mi.Float, self.radius, base + mi.UInt32(k), moved)
        right[moved] = dr.gather(mi.Float, self.radius, base + mi.UInt32(k) + 1, moved)
        return mi.UInt32(k), left, right

    def density_at(self, row, r, active):
        r"""Return :math:`p_c(r)` (mm^-1) of ``row`` at ``r`` (mm); 0 beyond the last node."""
        k, left, right = self.segment(row, r, active)
        index = row * self.nodes + k
        t = dr.clip((r - left) / (right - left), 0.0, 1.0)
        low = dr.gather(mi.Float, self.density, index, active)
        high = dr.gather(mi.Float, self.density, index + 1, active)
        inside = active & (r >= 0.0) & (r <= right)
        return dr.select(inside, dr.fma(t, high - low, low), 0.0)

    def disk_pdf(self, row, r, active):
        r"""Return :math:`q_c(r) = p_c(r) / (2\pi r E_c)` (mm^-2), the disk density."""
        energy = dr.gather(mi.Float, self.energy, row, active)
        value = self.density_at(row, r, active) \
            / (2.0 * math.pi * dr.maximum(r, SMALLEST_RADIUS) * energy)
        return dr.select(active & (energy > 0.0), value, 0.0)

    def sample_radius(self, row, u, active):
        """Return a radius (mm) of density :math:`p_c / E_c` from the uniform number ``u``."""
        base = row * self.nodes
        target = u * dr.gather(mi.Float, self.energy, row, active)

        def below(i):
            return dr.gather(mi.Float, self.cumulative, base + i, active) <= target

        k = dr.binary_search(0, self.nodes - 1, below)
        k = mi.UInt32(dr.clip(mi.Int32(k) - 1, 0, self.nodes - 2))
        index = base + k
        left = dr.gather(mi.Float, self.radius, index, active)
        width = dr.gather(mi.Float, self.radius, index + 1, active) - left
        low = dr.gather(mi.Float, self.density, index, active)
        high = dr.gather(mi.Float, self.density, index + 1, active)
        remaining = dr.maximum(target - dr.gather(mi.Float, self.cumulative, index, active),
                               0.0)
        # width (low t + (high - low) t^2 / 2) = remaining, solved without cancellation
        quadratic = 0.5 * width * (high - low)
        linear = width * low
        root = dr.safe_sqrt(dr.square(linear) + 4.0 * quadratic * remaining)
        denominator = linear + root
        t = dr.select(denominator > 0.0, 2.0 * remaining / denominator, 0.0)
        return left + dr.clip(t, 0.0, 1.0) * width

    # ------------------------------------------------------------ the profile
    def reflectance(self, obj, r, active):
        r"""Return :math:`R_c(r) = p_c(r) / (2\pi r)` per channel (mm^-2); 0 past every ball."""
        cut = dr.gather(mi.Float, self.cut_radius, obj, active)
        active = active & (r <= cut)
        scale = 1.0 / (2.0 * math.pi * dr.maximum(r, SMALLEST_RADIUS))
        values = [self.density_at(3 * obj + c, r, active) * scale for c in range(3)]
        return dr.select(active, mi.Spectrum(*values), 0.0)

    # ------------------------------------------------------- heterogeneous objects
    def label_at(self, obj, p, active):
        """Return the medium label of the voxel holding ``p`` (rendering-frame units).

        Clamped into the box, as :meth:`~translucent.materials.solid.SolidMedium.voxel_index`.
        """
        index = []
        for axis, coordinate in enumerate((p.x, p.y, p.z)):
            lower = dr.gather(mi.Float, self.label_lower, 3 * obj + axis, active)
            extent = dr.gather(mi.Float, self.label_extent, 3 * obj + axis, active)
            size = dr.gather(mi.UInt32, self.label_shape, 3 * obj + axis, active)
            cell = mi.Int32(dr.floor((coordinate - lower) / extent * mi.Float(size)))
            index.append(mi.UInt32(dr.clip(cell, 0, mi.Int32(size) - 1)))
        nx = dr.gather(mi.UInt32, self.label_shape, 3 * obj, active)
        ny = dr.gather(mi.UInt32, self.label_shape, 3 * obj + 1, active)
        flat = (index[2] * ny + index[1]) * nx + index[0]
        first = dr.gather(mi.UInt32, self.label_first, obj, active)
        return dr.gather(mi.UInt32, self.labels, first + flat, active)

    def mixed_reflectance(self, obj, xo, xi, r, active):
        r"""Return the BSSRDF's :math:`R` between ``xi`` and ``xo`` (mm^-2) by the object's rule.

        A homogeneous object reads its own profile (:meth:`reflectance`). ``geometric_mean``
        (Chen et al. 2012, Eq. 8): :math:`\sqrt{P_{l(x_i)}(r) P_{l(x_o)}(r)}` with
        :math:`l` the label of the voxel at each point. ``segment_mix`` (Sheng et al. 2014,
        Eq. 16, as :func:`~translucent.materials.profiles.mixed_profile`): the fractions
        :math:`f_m` of :data:`~.bssrdf_tables.SEGMENT_POINTS` midpoints of the straight
        segment in each medium, then :math:`(\sum_m S_m(0) f_m)\prod_m S_m(f_m r)/S_m(0)`.
        ``segment_average`` (:func:`~translucent.materials.profiles.segment_average_profile`):
        the dipole, in closed form, of the coefficients averaged with the same fractions.
        """
        rule = dr.gather(mi.UInt32, self.rule, obj, active)
        value = self.reflectance(obj, r, active & (rule == 0))
        if self.any_geometric_mean:
            mean = active & (rule == RULE_CODES["geometric_mean"])
            first = dr.gather(mi.UInt32, self.media_first, obj, mean)
            at_entry = self.reflectance(first + self.label_at(obj, xi, mean), r, mean)
            at_exit = self.reflectance(first + self.label_at(obj, xo, mean), r, mean)
            value[mean] = dr.sqrt(at_entry * at_exit)
        if self.any_segment_mix or self.any_segment_average:
            mix = active & (rule == RULE_CODES["segment_mix"])
            average = active & (rule == RULE_CODES["segment_average"])
            along = mix | average
            first = dr.gather(mi.UInt32, self.media_first, obj, along)
            count = dr.gather(mi.UInt32, self.media_count, obj, along)
            labels = [self.label_at(obj, xi + (xo - xi) * ((k + 0.5) / SEGMENT_POINTS), along)
                      for k in range(SEGMENT_POINTS)]
            zero_mix, ratio = mi.Spectrum(0.0), mi.Spectrum(1.0)
            mean_a, mean_s = mi.Spectrum(0.0), mi.Spectrum(0.0)
            for m in range(self.most_media):
                hits = mi.Float(0.0)
                for label in labels:
                    hits += dr.select(label == m, 1.0, 0.0)
                fraction = hits / SEGMENT_POINTS
                crossed = along & (mi.UInt32(m) < count) & (hits > 0.0)
                entry = first + m
                if self.any_segment_mix:
                    mixed = crossed & mix
                    zero = self._rgb(self.value_at_zero, entry, mixed)
                    zero_mix += dr.select(mixed, zero * fraction, 0.0)
                    partial = self.reflectance(entry, fraction * r, mixed)
                    ratio *= dr.select(mixed, partial / zero, 1.0)
                if self.any_segment_average:
                    averaged = crossed & average
                    mean_a += dr.select(averaged, self._rgb(self.sigma_a, entry, averaged)
                                        * fraction, 0.0)
                    mean_s += dr.select(averaged, self._rgb(self.sigma_s_prime, entry,
                                                            averaged) * fraction, 0.0)
            if self.any_segment_mix:
                value[mix] = zero_mix * ratio
            if self.any_segment_average:
                cut = dr.gather(mi.Float, self.cut_radius, obj, average)
                boundary = dr.gather(mi.Float, self.boundary, obj, average)
                value[average] = dr.select(r <= cut, _dipole(mean_a, mean_s, boundary, r),
                                           0.0)
        return value

    @staticmethod
    def _rgb(array, entry, active):
        """Return the three channels of ``entry`` in a per-entry RGB array."""
        return mi.Spectrum(*[dr.gather(mi.Float, array, 3 * entry + c, active)
                             for c in range(3)])

    def is_directional(self, obj, active):
        """Whether object ``obj`` evaluates the directional dipole."""
        return dr.gather(mi.Float, self.directional, obj, active) > 0.0

    def directional_reflectance(self, obj, d, normal, wi, eta, active):
        r"""Return the directional dipole's :math:`R` (mm^-2) for light arriving from ``wi``.

        Frisvad, Hachisuka and Kjeldsen 2014, Sect. 4-5, as
        :meth:`~translucent.materials.profiles.DirectionalDipoleProfile.evaluate` on a
        plane: ``d`` is the displacement from the entry point to the exit point (mm),
        ``normal`` the normal at the entry point, ``wi`` the direction towards the light.
        The incident angle is each lane's own; :math:`x\cdot\omega_{12}` is the 3D
        displacement's, the squared distance its full length's.
        """
        cos_i = dr.clip(dr.dot(wi, normal), 0.0, 1.0)
        tangential = wi - normal * cos_i
        sin_t = dr.norm(tangential) / eta
        mu0 = dr.safe_sqrt(1.0 - dr.square(sin_t))
        along = dr.normalize(-tangential)
        along = dr.select(dr.all(dr.isfinite(along)), along, 0.0)
        x_dot_w = dr.dot(d, along) * sin_t
        r2 = dr.squared_norm(d)
        boundary = dr.gather(mi.Float, self.dd_boundary, obj, active)
        c_phi = dr.gather(mi.Float, self.dd_c_phi, obj, active)
        c_e = dr.gather(mi.Float, self.dd_c_e, obj, active)
        values = []
        for c in range(3):
            row = 3 * obj + c
            diffusion = dr.gather(mi.Float, self.dd_diffusion, row, active)
            sigma_tr = dr.gather(mi.Float, self.dd_sigma_tr, row, active)
            extrapolation = dr.gather(mi.Float, self.dd_extrapolation, row, active)
            cos_beta = -dr.safe_sqrt((r2 - dr.square(x_dot_w))
                                     / (r2 + dr.square(extrapolation)))
            d_r = dr.safe_sqrt(r2 + diffusion * mu0 * (diffusion * mu0
                                                       - 2.0 * extrapolation * cos_beta))
            real = _source_term(x_dot_w, -mu0, 0.0, d_r, diffusion, sigma_tr, c_phi, c_e)
            height = 2.0 * boundary * extrapolation
            d_v = dr.sqrt(r2 + dr.square(height))
            image = _source_term(x_dot_w - height * mu0, mu0, -height, d_v, diffusion,
                                 sigma_tr, c_phi, c_e)
            value = dr.maximum(real - image, 0.0) / (4.0 * math.pi)
            present = active & (diffusion > 0.0)
            values.append(dr.select(present & dr.isfinite(value), value, 0.0))
        return mi.Spectrum(*values)


def _dipole(sigma_a, sigma_s_prime, boundary, r):
    r"""Return the classical dipole :math:`R_d(r)` (mm^-2) of per-lane coefficients.

    As :func:`~translucent.materials.dipole_reflectance_profile`, with ``boundary`` its A.
    """
    sigma_t = sigma_a + sigma_s_prime
    albedo = sigma_s_prime / dr.maximum(sigma_t, 1e-30)
    sigma_tr = dr.sqrt(3.0 * sigma_a * sigma_t)
    z_r = 1.0 / dr.maximum(sigma_t, 1e-30)
    total = mi.Spectrum(0.0)
    for z in (z_r, z_r * (1.0 + 4.0 * boundary / 3.0)):
        d = dr.sqrt(dr.square(r) + dr.square(z))
        total += z * (sigma_tr + 1.0 / d) * dr.exp(-sigma_tr * d) / dr.square(d)
    value = albedo / (4.0 * math.pi) * total
    return dr.select(dr.isfinite(value) & (sigma_t > 0.0), value, 0.0)


def _source_term(x_dot_w, w_dot_n, x_dot_n, d, diffusion, sigma_tr, c_phi, c_e):
    """Frisvad et al.'s S'_d (without 1/(4 pi)), as the numpy ``_source_term``."""
    sd = sigma_tr * d
    one = 1.0 + sd
    d2 = dr.square(d)
    return dr.exp(-sd) / (d2 * d) * (
        c_phi * (d2 / diffusion + 3.0 * one * x_dot_w)
        - c_e * (3.0 * diffusion * one * w_dot_n
                 - (one + 3.0 * diffusion * (3.0 * one + dr.square(sd)) / d2 * x_dot_w)
                 * x_dot_n))
