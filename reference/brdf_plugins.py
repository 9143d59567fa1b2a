r"""The analytic BRDFs of Nguyen et al. 2010 as a Mitsuba 3 BSDF plugin, for exact references.

One Python plugin, ``translucent_analytic_brdf``, renders every model of
:mod:`translucent.materials.brdfs`: it evaluates the lobe with the same code as the fast
method (:func:`~translucent.materials.brdfs.lobe_terms` over a Dr.Jit array namespace), so
a difference between the exact reference and the PCA approximation is the approximation's.

==============  ======  ===========  ====================================================
parameter       type    default      meaning
==============  ======  ===========  ====================================================
``model``       string  (required)   ``blinn_phong``, ``ward``, ``ward_duer``,
                                     ``lafortune``, ``cook_torrance``,
                                     ``ashikhmin_shirley`` (or BP, W, WD, La, CT, AS)
``gamma``       float   (required)   editing parameter, in the model's range
``rho_s``       color   1            glossy coefficient k_s (RGB)
``rho_d``       color   0            diffuse albedo k_d (RGB)
``f0``          float   0.04         Schlick F0 of CT and AS
``c_xy``        float   -1           Lafortune C_x = C_y
``c_z``         float   1            Lafortune C_z
``pca_basis``   int     0            K > 0: the edited term is its K-term PCA
                                     reconstruction (the fast method's model), not the
                                     exact one
==============  ======  ===========  ====================================================

With ``pca_basis = K`` the plugin renders the model of the BRDF-editing method exactly
(Nguyen et al. 2010, Eq. 10): the edited term :math:`f_E(\gamma, \delta)` is replaced by
:math:`b_0(\delta) + \sum_{j \le K} c_j(\gamma) b_j(\delta)`
(:class:`~translucent.materials.brdf_pca.PCABasis`, built as the method builds it),
interpolated linearly in :math:`\delta` on the basis's grid, negative lobes included (the
reconstruction is not clamped: that is the model). Sampling stays the exact lobe's, whose
density covers the reconstruction's support (the whole hemisphere for the half-angle
models; Lafortune's lobe cosine > 0, where both are nonzero). Against the exact
reference it is the model error; the method against it, the approximation error.

Sampling is a one-sample mixture of a cosine-weighted diffuse lobe and a glossy lobe
chosen with probability proportional to the mean of ``rho_s`` (``rho_d``):

* BP, AS: half vectors with density :math:`\frac{\gamma+1}{2\pi}\cos^\gamma\theta_h`;
* W, WD, CT: half vectors from Beckmann's distribution with roughness :math:`\gamma`,
  density :math:`\exp(-\tan^2\theta_h/\gamma^2)/(\pi\gamma^2\cos^3\theta_h)`;
* La: a power-cosine lobe :math:`\frac{\gamma+1}{2\pi}\cos^\gamma\alpha` about the
  axis :math:`(C_{xy} v_x, C_{xy} v_y, C_z v_z)/|\cdot|`;

half-vector densities become densities of directions through the reflection Jacobian
:math:`1/(4\,\omega_i\cdot h)`. Samples below the horizon are rejected (weight 0); the
pdf is normalised over the sphere so Mitsuba's chi-square test sees those losses.

The plugin works in the JIT variants (``llvm_ad_rgb``, ``cuda_ad_rgb``); a scalar
variant calls Python once per path vertex and is too slow for renders.
"""

from __future__ import annotations

import functools
import math
import time
from types import SimpleNamespace

from ..backend import mitsuba
from ..materials.brdf_pca import GATHER_TRANSPORTS, LAMBERTIAN_GATHER
from ..materials.brdfs import (
    AnalyticBRDF,
    canonical_model,
    check_gamma,
    lobe_terms,
    pca_variable,
    uses_half_angle,
)
from .mitsuba_scene import (
    GATHER_INTEGRATOR,
    MaterialParts,
    register_integrator_builder,
    register_material_converter,
)

__all__ = ["INTEGRATOR_NAME", "PLUGIN_NAME", "bsdf_dict", "drjit_ops", "gather_integrator",
           "register_plugin", "render_lambertian_gather"]

#: The name the plugin is registered under (``{"type": PLUGIN_NAME, ...}``).
PLUGIN_NAME = "translucent_analytic_brdf"

#: The integrator of :func:`render_lambertian_gather`.
INTEGRATOR_NAME = GATHER_INTEGRATOR


@functools.lru_cache(maxsize=None)
def drjit_ops():
    """Return the Dr.Jit array namespace for :func:`~translucent.materials.brdfs.lobe_terms`."""
    import drjit as dr

    return SimpleNamespace(sqrt=dr.sqrt, exp=dr.exp, maximum=dr.maximum, minimum=dr.minimum,
                           select=dr.select, power=dr.power, abs=dr.abs)


def _rgb(props, key, default) -> list[float]:
    if key not in props:
        return [float(default)] * 3
    value = props[key]
    if isinstance(value, (int, float)):
        return [float(value)] * 3
    return [float(value[i]) for i in range(3)]


def _plugin_class(mi):
    import drjit as dr

    flags = mi.BSDFFlags
    diffuse_flags = flags.DiffuseReflection | flags.FrontSide
    glossy_flags = flags.GlossyReflection | flags.FrontSide
    ops = drjit_ops()

    class AnalyticBRDFPlugin(mi.BSDF):
        """Mitsuba BSDF of an :class:`~translucent.materials.brdfs.AnalyticBRDF`."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.model = canonical_model(props["model"])
            self.gamma = check_gamma(self.model, props["gamma"])
            rho_s, rho_d = _rgb(props, "rho_s", 1.0), _rgb(props, "rho_d", 0.0)
            self.rho_s, self.rho_d = mi.Color3f(*rho_s), mi.Color3f(*rho_d)
            self.f0 = float(props["f0"]) if "f0" in props else 0.04
            c_xy = float(props["c_xy"]) if "c_xy" in props else -1.0
            c_z = float(props["c_z"]) if "c_z" in props else 1.0
            self.lafortune_c = (c_xy, c_z)
            self.pca_basis = int(props["pca_basis"]) if "pca_basis" in props else 0
            if self.pca_basis > 0:
                from ..materials.brdf_pca import build_pca_basis

                basis = build_pca_basis(self.model, self.pca_basis)
                self.pca_table = mi.Float(basis.reconstruct(self.gamma).astype("float32"))
                self.pca_start = float(basis.delta[0])
                self.pca_step = float(basis.delta[1] - basis.delta[0])
                self.pca_size = len(basis.delta)
            weight_s, weight_d = sum(rho_s) / 3.0, sum(rho_d) / 3.0
            total = weight_s + weight_d
            self.glossy_probability = 0.5 if total <= 0 else weight_s / total
            self.m_components = [diffuse_flags, glossy_flags]
            self.m_flags = diffuse_flags | glossy_flags

        # -- the BRDF itself ---------------------------------------------------------
        def _lobe(self, cos_l, cos_v, l_dot_v):
            """Return the fixed and edited terms (the edited one from the PCA table if K > 0)."""
            fixed, edited = lobe_terms(self.model, self.gamma, cos_l, cos_v, l_dot_v, ops,
                                       f0=self.f0, lafortune_c=self.lafortune_c)
            if self.pca_basis == 0:
                return fixed, edited
            variable = pca_variable(self.model, cos_l, cos_v, l_dot_v, ops,
                                    lafortune_c=self.lafortune_c)
            if uses_half_angle(self.model):
                delta = dr.acos(dr.clip(variable, 0.0, 1.0))
            else:
                delta = variable
            position = dr.clip((delta - self.pca_start) / self.pca_step, 0.0,
                               self.pca_size - 1.0)
            index = dr.minimum(mi.UInt32(position), self.pca_size - 2)
            fraction = position - mi.Float(index)
            table = (dr.gather(mi.Float, self.pca_table, index) * (1.0 - fraction)
                     + dr.gather(mi.Float, self.pca_table, index + 1) * fraction)
            inside = (cos_l > 0) & (cos_v > 0)
            if not uses_half_angle(self.model):  # zero where every gamma's lobe is zero
                inside &= delta > 0
            return fixed, dr.select(inside, table, 0.0)

        def _value(self, wi, wo):
            cos_v = mi.Frame3f.cos_theta(wi)
            cos_l = mi.Frame3f.cos_theta(wo)
            fixed, edited = self._lobe(cos_l, cos_v, dr.dot(wi, wo))
            above = (cos_l > 0) & (cos_v > 0)
            diffuse = dr.select(above, self.rho_d * dr.inv_pi, 0.0)
            return (diffuse + self.rho_s * (fixed * edited)) * dr.maximum(cos_l, 0.0)

        # -- glossy lobe densities and samples ------------------------------------------
        def _half_vector_pdf(self, cos_h):
            cos_h = dr.maximum(cos_h, 0.0)
            if self.model in ("ward", "ward_duer", "cook_torrance"):
                gamma2 = self.gamma * self.gamma
                cos2 = dr.maximum(cos_h * cos_h, 1e-12)
                tan2 = dr.maximum(1.0 - cos2, 0.0) / cos2
                return dr.select(cos_h > 0,
                                 dr.exp(-tan2 / gamma2) / (math.pi * gamma2 * cos2 * cos_h), 0.0)
            return (self.gamma + 1.0) / (2.0 * math.pi) * dr.power(cos_h, self.gamma)

        def _lafortune_axis(self, wi):
            c_xy, c_z = self.lafortune_c
            return dr.normalize(mi.Vector3f(c_xy * wi.x, c_xy * wi.y, c_z * wi.z))

        def _glossy_pdf(self, wi, wo):
            if self.model == "lafortune":
                cos_a = dr.maximum(dr.dot(self._lafortune_axis(wi), wo), 0.0)
                return (self.gamma + 1.0) / (2.0 * math.pi) * dr.power(cos_a, self.gamma)
            h = dr.normalize(wi + wo)
            wi_dot_h = dr.dot(wi, h)
            pdf = self._half_vector_pdf(mi.Frame3f.cos_theta(h)) / (4.0 * dr.maximum(wi_dot_h,
                                                                                    1e-12))
            return dr.select(wi_dot_h > 0, pdf, 0.0)

        def _sample_glossy(self, wi, sample2):
            phi = 2.0 * math.pi * sample2.y
            if self.model in ("ward", "ward_duer", "cook_torrance"):
                tan2 = -(self.gamma * self.gamma) * dr.log(dr.maximum(1.0 - sample2.x, 1e-30))
                cos_t = dr.rsqrt(1.0 + tan2)
            else:
                cos_t = dr.power(sample2.x, 1.0 / (self.gamma + 1.0))
            sin_t = dr.safe_sqrt(1.0 - cos_t * cos_t)
            local = mi.Vector3f(sin_t * dr.cos(phi), sin_t * dr.sin(phi), cos_t)
            if self.model == "lafortune":
                return mi.Frame3f(self._lafortune_axis(wi)).to_world(local)
            return 2.0 * dr.dot(wi, local) * local - wi  # mirror wi about the half vector

        def _mixture(self, ctx):
            has_diffuse = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0)
            has_glossy = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
            if has_diffuse and has_glossy:
                return self.glossy_probability
            return 1.0 if has_glossy else (0.0 if has_diffuse else None)

        def _pdf(self, ctx, wi, wo):
            p_glossy = self._mixture(ctx)
            if p_glossy is None:
                return dr.zeros(mi.Float, dr.width(wo))
            pdf = (1.0 - p_glossy) * mi.warp.square_to_cosine_hemisphere_pdf(wo)
            if p_glossy > 0:
                pdf += p_glossy * self._glossy_pdf(wi, wo)
            valid = (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
            return dr.select(valid, pdf, 0.0)

        def _masked_value(self, ctx, wi, wo):
            if self._mixture(ctx) is None:
                return mi.Color3f(0.0)
            has_diffuse = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0)
            has_glossy = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 1)
            if has_diffuse and has_glossy:
                return self._value(wi, wo)
            cos_l = dr.maximum(mi.Frame3f.cos_theta(wo), 0.0)
            if has_diffuse:
                above = (mi.Frame3f.cos_theta(wi) > 0) & (cos_l > 0)
                return dr.select(above, self.rho_d * dr.inv_pi * cos_l, 0.0)
            fixed, edited = self._lobe(mi.Frame3f.cos_theta(wo), mi.Frame3f.cos_theta(wi),
                                       dr.dot(wi, wo))
            return self.rho_s * (fixed * edited) * cos_l

        # -- the mi.BSDF interface -------------------------------------------------
        def sample(self, ctx, si, sample1, sample2, active=True):
            wi = si.wi
            p_glossy = self._mixture(ctx)
            bs = dr.zeros(mi.BSDFSample3f)
            if p_glossy is None:
                return bs, mi.Color3f(0.0)
            pick_glossy = sample1 < p_glossy
            wo_diffuse = mi.warp.square_to_cosine_hemisphere(sample2)
            wo_glossy = self._sample_glossy(wi, sample2) if p_glossy > 0 else wo_diffuse
            wo = dr.select(pick_glossy, wo_glossy, wo_diffuse)
            bs.wo = wo
            bs.pdf = self._pdf(ctx, wi, wo)
            bs.eta = 1.0
            bs.sampled_type = dr.select(pick_glossy, mi.UInt32(+flags.GlossyReflection),
                                        mi.UInt32(+flags.DiffuseReflection))
            bs.sampled_component = dr.select(pick_glossy, mi.UInt32(1), mi.UInt32(0))
            value = self._masked_value(ctx, wi, wo)
            valid = (active & (mi.Frame3f.cos_theta(wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
                     & (bs.pdf > 0))
            bs.pdf = dr.select(valid, bs.pdf, 0.0)
            weight = dr.select(valid, value / dr.maximum(bs.pdf, 1e-30), 0.0)
            return bs, weight

        def eval(self, ctx, si, wo, active=True):
            return dr.select(active, self._masked_value(ctx, si.wi, wo), 0.0)

        def pdf(self, ctx, si, wo, active=True):
            return dr.select(active, self._pdf(ctx, si.wi, wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

        def traverse(self, callback):
            callback.put("rho_s", self.rho_s, mi.ParamFlags.NonDifferentiable)
            callback.put("rho_d", self.rho_d, mi.ParamFlags.NonDifferentiable)

        def parameters_changed(self, keys):
            pass

        def to_string(self):
            return (f"AnalyticBRDFPlugin[model={self.model}, gamma={self.gamma}, "
                    f"rho_s={self.rho_s}, rho_d={self.rho_d}, f0={self.f0}, "
                    f"lafortune_c={self.lafortune_c}, pca_basis={self.pca_basis}]")

    return AnalyticBRDFPlugin


@functools.lru_cache(maxsize=None)
def _register(kind: str, variant: str):
    """Register the BSDF (``kind="bsdf"``) or the integrator once per variant."""
    mi = mitsuba()
    if kind == "bsdf":
        plugin_class = _plugin_class(mi)
        mi.register_bsdf(PLUGIN_NAME, lambda props: plugin_class(props))
    else:
        plugin_class = _integrator_class(mi)
        mi.register_integrator(INTEGRATOR_NAME, lambda props: plugin_class(props))
    return plugin_class


def register_plugin():
    """Register ``translucent_analytic_brdf`` with Mitsuba (once per variant); return its class."""
    return _register("bsdf", mitsuba().variant())


def gather_integrator(transport: str, bounces: int) -> dict:
    """Return the Mitsuba integrator entry of a gather transport (registering the integrator).

    Parameters
    ----------
    transport : str
        A key of :data:`~translucent.materials.brdf_pca.GATHER_TRANSPORTS`: how many
        surfaces from the eye reflect the direct light by their whole BRDF.
    bounces : int
        n of Eq. 17 (>= 0): paths have ``bounces + 2`` surface vertices at most.
    """
    _register("integrator", mitsuba().variant())
    return {"type": INTEGRATOR_NAME, "max_depth": int(bounces) + 2,
            "brdf_light_vertices": GATHER_TRANSPORTS[transport]}


def bsdf_dict(material: AnalyticBRDF, pca_basis: int = 0) -> dict:
    """Return the Mitsuba ``load_dict`` entry of ``material`` (registering the plugin).

    Parameters
    ----------
    material : AnalyticBRDF

    Returns
    -------
    dict
        ``{"type": PLUGIN_NAME, "model": ..., "gamma": ..., "rho_s": ..., ...}``.
    """
    mi = mitsuba()
    register_plugin()
    return {"type": PLUGIN_NAME, "model": material.model, "gamma": float(material.gamma),
            "rho_s": mi.ScalarColor3f(*material.rho_s.tolist()),
            "rho_d": mi.ScalarColor3f(*material.rho_d.tolist()), "f0": float(material.f0),
            "c_xy": float(material.lafortune_c[0]), "c_z": float(material.lafortune_c[1]),
            "pca_basis": int(pca_basis)}


def _convert_analytic_brdf(material: AnalyticBRDF, context) -> MaterialParts:
    # two-sided like the Lambertian conversion: open meshes (floors) reflect on both sides,
    # as the fast method's view samples (normals turned towards the eye) assume
    return MaterialParts({"type": "twosided", "bsdf": bsdf_dict(material,
                                                                 context.brdf_basis)})


register_material_converter(AnalyticBRDF, _convert_analytic_brdf)
register_integrator_builder(GATHER_INTEGRATOR, gather_integrator)


# ---------------------------------------------------------------------------------------
# the light transport the PCA method converges to


def _integrator_class(mi):
    import drjit as dr

    class LambertianGatherIntegrator(mi.SamplingIntegrator):
        """Paths whose first surface reflects with its full BSDF and later ones diffusely.

        At the first surface seen from the eye the whole BSDF (glossy and diffuse) is
        evaluated and sampled; every later surface reflects with its diffuse component
        only, and paths have at most ``max_depth`` surface vertices. Light is gathered by
        emitter sampling only, which is unbiased for every light type. This is the
        transport of Nguyen et al. 2010 (Sect. 5.2: Lambertian gather samples and
        Lambertian bounces among them) without its discretisation. With
        ``brdf_light_vertices`` 2, the second surface (a gather sample) reflects the light
        it receives directly by its whole BSDF too (the method's ``gather_reflection``
        "brdf").
        """

        def __init__(self, props):
            mi.SamplingIntegrator.__init__(self, props)
            self.max_depth = int(props["max_depth"]) if "max_depth" in props else 4
            self.brdf_light_vertices = (int(props["brdf_light_vertices"])
                                        if "brdf_light_vertices" in props else 1)

        def sample(self, scene, sampler, ray, medium=None, active=True):
            result = mi.Color3f(0.0)
            throughput = mi.Color3f(1.0)
            alive = mi.Bool(active)
            ray = mi.Ray3f(ray)
            for depth in range(self.max_depth):
                si = scene.ray_intersect(ray, alive)
                alive &= si.is_valid()
                if depth == 0:
                    result += dr.select(alive, si.emitter(scene).eval(si, alive), 0.0)
                bsdf = si.bsdf(ray)
                emitted, emitter_weight = scene.sample_emitter_direction(
                    si, sampler.next_2d(alive), True, alive)
                wo = si.to_local(emitted.d)
                value = bsdf.eval(self._context(depth, self.brdf_light_vertices), si, wo, alive)
                context = self._context(depth, 1)
                result += dr.select(alive & (emitted.pdf > 0), throughput * value
                                    * emitter_weight, 0.0)
                sample, weight = bsdf.sample(context, si, sampler.next_1d(alive),
                                             sampler.next_2d(alive), alive)
                throughput *= weight
                alive &= dr.any(throughput != 0.0)
                ray = si.spawn_ray(si.to_world(sample.wo))
            return result, mi.Bool(True), []

        @staticmethod
        def _context(depth: int, whole_brdf_vertices: int):
            context = mi.BSDFContext()
            if depth >= whole_brdf_vertices:
                context.type_mask = +mi.BSDFFlags.DiffuseReflection
            return context

        def aov_names(self):
            return []

        def to_string(self):
            return (f"LambertianGatherIntegrator[max_depth={self.max_depth}, "
                    f"brdf_light_vertices={self.brdf_light_vertices}]")

    return LambertianGatherIntegrator


def render_lambertian_gather(scene, *, bounces: int = 2, spp: int = 64, passes: int = 4,
                             seed: int = 0):
    """Path-trace the transport the PCA method approximates (its converged limit).

    The first surface seen from the eye reflects with its exact BRDF; the next ``bounces
    + 1`` surfaces reflect with their diffuse term only (Nguyen et al. 2010, Sect. 5.2:
    gather samples and the gather matrix :math:`M_s` are Lambertian). With infinitely many
    gather samples, basis functions and wavelet coefficients the fast method renders
    this image; against the exact reference it shows the cost of the Lambertian
    assumption (glossy-to-glossy and caustic paths are missing).

    Parameters
    ----------
    scene : Scene
    bounces : int
        n of Eq. 17 (>= 0).
    spp, passes : int
        Samples per pixel per pass and independent passes (>= 2 for a variance).
    seed : int

    Returns
    -------
    Image
        Mean radiance and the variance of the mean (across passes).
    """
    import numpy as np

    from ..errors import check_count
    from ..image import Image
    from .mitsuba_scene import to_mitsuba_dict

    for name, value, low in (("bounces", bounces, 0), ("spp", spp, 1), ("passes", passes, 1),
                             ("seed", seed, 0)):
        check_count(value, name, low)
    mi = mitsuba()
    register_plugin()
    started = time.perf_counter()
    description = to_mitsuba_dict(scene, spp=spp)
    description["integrator"] = gather_integrator(LAMBERTIAN_GATHER, bounces)
    loaded = mi.load_dict(description)
    images = np.stack([np.array(mi.render(loaded, spp=spp, seed=seed * passes + k))
                       .astype(np.float64)[..., :3] for k in range(passes)])
    variance = images.var(axis=0, ddof=1) / passes if passes > 1 else None
    return Image(images.mean(axis=0), variance, metadata={
        "producer": "reference_lambertian_gather", "scene": scene.name, "spp": spp,
        "passes": passes, "seed": seed, "bounces": int(bounces),
        "seconds": time.perf_counter() - started})
