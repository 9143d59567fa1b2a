r"""Path tracing with a BSSRDF made of a radial profile: the exact image of a profile.

``bssrdf_path`` renders every translucent object of a scene (a
:class:`~translucent.materials.Dipole` material) as a surface whose subsurface transport is
a profile chosen by name (:func:`translucent.materials.profiles.profile`), and everything
else as Mitsuba's ``path`` does (opaque BSDFs, emitters, camera). Against a volumetric
reference it measures the profile's error (the model), against a fast method the method's
own (the approximation): the profile rendered exactly in the whole scene.

**The BSSRDF.** A profile :math:`R_c(r)` (mm^-2, per RGB channel) is the exitance at
distance r from where unit power entered (each profile module states it so). Light
arriving at :math:`x_i` from :math:`\omega_i` enters with the Fresnel transmittance
:math:`F_t = 1 - F_r` of the smooth boundary of relative index :math:`\eta`; the exitance
at :math:`x_o` leaves distributed as :math:`F_t(\eta, \cos\theta_o)\cos\theta_o`:

.. math::
    S(x_i, \omega_i; x_o, \omega_o) = F_t(\eta, \cos\theta_i)\; R(\lVert x_o - x_i\rVert)\;
    S_\omega(\omega_o), \qquad
    S_\omega(\omega_o) = \frac{F_t(\eta, \cos\theta_o)}{\pi\,(1 - F_{dr}(\eta))}

so that :math:`\int S_\omega \cos\theta_o\,d\omega_o = 1`: the exitance the profile gives
leaves the surface whole. This is the form of pbrt-v4's separable BSSRDF (``TabulatedBSSRDF``
with ``NormalizedFresnelBxDF``) with its normalisation stated over the outside hemisphere:
:math:`1 - F_{dr}(\eta) = \eta^2 c`, :math:`c = 1 - 2\,\mathrm{FresnelMoment1}(1/\eta)`.
pbrt-v4's ``Sw`` is :math:`F_t / (c\pi)`, scaled by :math:`\eta^2` in radiance transport,
and the transmission into the surface before it by :math:`1/\eta^2`: its product is
:math:`F_t R F_t / (c\pi)`, :math:`\eta^2` times this one (its exit term integrates to
:math:`\eta^2`). Jensen et al. 2001 write :math:`S_d = F_t R_d F_t / \pi`, which loses
:math:`F_{dr}` of the exitance a second time.
The directional dipole (Frisvad et al. 2014) is the one profile that depends on
:math:`\omega_i`; it is evaluated with each sample's own incident direction in the tangent
frame of :math:`x_i` (:meth:`~.bssrdf_profile.ProfileLookup.directional_reflectance`), and
its radial average at normal incidence is what the probe rays sample.

**The estimator** (pbrt-v4 ``VolPathIntegrator``'s BSSRDF branch; Cycles
``subsurface_disk``). Where a path meets a translucent object at :math:`x_o`, the smooth
boundary reflects with probability :math:`F_r(\eta, \cos\theta_o)` (weight 1), or light
has come out of the object (probability :math:`F_t`, which cancels :math:`S_\omega`'s
numerator). Then a projection axis (the two tangents and the normal at :math:`x_o`, with
probabilities 1/4, 1/4, 1/2) and a channel (1/3 each) are drawn, a radius from that
channel's inverse CDF of :math:`2\pi r R_c(r)` and an angle uniformly; the probe segment
through that disk point, along the axis, inside the channel's ball of radius
:math:`r_{\max,c}`, is intersected with the object again and again (Mitsuba has no "all
hits" query) and one of its k crossings chosen uniformly. With :math:`q_c` the disk
density (mm^-2), the crossing :math:`x_i` has the one-sample MIS density

.. math::
    \hat p(x_i) = \sum_{a}\sum_{c} P_a P_c\, q_c(r_a(x_i))\,|n_i\cdot a|\,
    [\lVert x_i - x_o\rVert \le r_{\max,c}]

(:math:`r_a` the distance from :math:`x_o` projected along axis a) and the estimate is
weighted by :math:`k / \hat p` (pbrt-v4 ``PDF_Sp`` times the reservoir's ``1/k``; the sum of
the crossings' contributions over each axis is unbiased, so the balance heuristic over
axes and channels is too). At :math:`x_i` next-event estimation samples any emitter (point,
spot, directional, area, environment: a delta light needs no manifold search, the
boundary is inside the BSSRDF) with
:math:`f = F_t(\eta,\cos\theta_i) R\,\cos\theta_i / (\pi(1 - F_{dr}))`, combined by the power
heuristic with the cosine-distributed continuation that carries the path on for
inter-reflection; Russian roulette as Mitsuba's ``path`` and ``volpath``.

**Heterogeneous objects.** A solid medium (:class:`~translucent.materials.solid.SolidMedium`)
has no one profile; with a rule (``PROFILE+RULE``, a key of
:data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`) it is reduced to the media a
method derives from it (:data:`~translucent.materials.profiles.RULE_MAX_MEDIA`), each gets the named
profile, and :math:`R` between two points is the rule's mix of them: the geometric mean of
the media's profiles at the two points (``geometric_mean``, splatting's Eq. 8 of Chen et al.
2012) or Eq. 16 of Sheng et al. 2014 over the media along the straight segment
(``segment_mix``, radiosity's). The probes sample the media's mean profile, whose support
holds every rule's. So each method's rule is rendered exactly, and a method's error on a
solid medium splits into its rule's and its own.

**What it does not do.** Light is not transmitted through a translucent object (its
transport is the profile's, of a half-space); the profile is cut beyond the largest probe
ball (:data:`~.bssrdf_tables.PROBE_ENERGY_FRACTION`); interior media other than a
:class:`~translucent.materials.Dipole` or a solid medium with a rule are refused.

References
----------
M. Pharr, W. Jakob, G. Humphreys: Physically Based Rendering, 4th ed., Sect. 11.4 and 14.3
(pbrt-v4 ``src/pbrt/bssrdf.h``, ``src/pbrt/cpu/integrators.cpp``).
A. King, C. Kulla, A. Conty, M. Fajardo: BSSRDF importance sampling. SIGGRAPH 2013 Talks
(the three projection axes; Blender Cycles ``kernel/integrator/subsurface_disk.h``).
H. W. Jensen, S. Marschner, M. Levoy, P. Hanrahan: A practical model for subsurface light
transport. SIGGRAPH 2001.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from ..backend import mitsuba
from ..errors import InputError
from ..materials import Dipole
from ..materials.profiles import HETEROGENEOUS_RULES
from ..materials.solid import SolidMedium
from .bssrdf_tables import (
    ProfileTables,
    TranslucentObject,
    build_tables,
    register_tables,
    translucent_objects,
)
from .model_keys import model_rule, without_rule

__all__ = ["INTEGRATOR_NAME", "BSSRDFConversion", "register", "bssrdf_conversion"]

#: The integrator's name in Mitsuba and on the command line.
INTEGRATOR_NAME = "bssrdf_path"


def register() -> None:
    """Register ``bssrdf_path`` with Mitsuba for the active variant (idempotent).

    Raises
    ------
    InputError
        Under a scalar variant (the integrator is vectorised: llvm_ad_rgb or cuda_ad_rgb).
    """
    mi = mitsuba()
    if not mi.variant().startswith(("llvm_", "cuda_")):
        raise InputError(f"{INTEGRATOR_NAME} needs a JIT variant (llvm_ad_rgb or "
                         "cuda_ad_rgb); set TRANSLUCENT_VARIANT", field="variant",
                         value=mi.variant())
    from .bssrdf_integrator import BSSRDFPath

    mi.register_integrator(INTEGRATOR_NAME, lambda props: BSSRDFPath(props))


@dataclass
class BSSRDFConversion:
    """What :func:`~translucent.reference.convert_scene` needs to render with a profile.

    Parameters
    ----------
    scene : Scene
    profile : str
        The profile's name.
    channel : {0, 1, 2}, optional
        A monochrome render of this channel's coefficients.
    """

    scene: object
    profile: str
    channel: int | None = None
    #: how a heterogeneous object's media are mixed (HETEROGENEOUS_RULES); None: refused
    rule: str | None = None
    objects: list[TranslucentObject] = field(default_factory=list)
    tables: ProfileTables | None = None

    def surface_parts(self, index: int, obj, parts):
        """Return the Mitsuba parts of object ``index``: a translucent one's boundary alone.

        The smooth ``dielectric`` boundary (its reflection is rendered as Mitsuba's, what
        it transmits is the profile's) without an interior medium.

        Raises
        ------
        InputError
            An interior medium that is not a Dipole's (a heterogeneous medium has no
            radial profile).
        """
        if isinstance(obj.material, Dipole) or (
                isinstance(obj.material, SolidMedium) and
                (self.rule is not None or obj.material.is_uniform)):
            boundary = {"type": "dielectric", "int_ior": obj.material.eta, "ext_ior": 1.0}
            return dataclasses.replace(parts, bsdf=boundary, interior=None,
                                       blocks_delta_lights=False, max_albedo=0.0,
                                       chromatic=False, description="",
                                       prefers_per_channel=False)
        if parts.interior is not None:
            hint = (f" (a heterogeneous medium: add the rule that mixes its media, "
                    f"'{self.profile}+RULE', RULE one of {', '.join(HETEROGENEOUS_RULES)})"
                    if isinstance(obj.material, SolidMedium) else "")
            raise InputError(f"{INTEGRATOR_NAME} renders homogeneous media (Dipole "
                             "materials) by their radial profile; this medium is "
                             f"{type(obj.material).__name__}, which has none{hint}",
                             file=self.scene.source, field=f"objects[{index}].material",
                             value=obj.name)
        return parts

    def integrator_properties(self, shape_ids) -> dict:
        """Make the tables for the objects with Mitsuba ids ``shape_ids``; the integrator's props.

        Raises
        ------
        InputError
            What :func:`~.bssrdf_tables.translucent_objects` refuses, or a scene with no
            translucent object at all.
        """
        self.objects = translucent_objects(self.scene, self.profile, shape_ids, self.channel,
                                           self.rule)
        if not self.objects:
            raise InputError(f"{INTEGRATOR_NAME} renders translucent objects by a profile; "
                             "this scene has none (no Dipole material)", file=self.scene.source,
                             field="integrator", value=INTEGRATOR_NAME)
        self.tables = build_tables(self.objects, self.scene.mm_per_unit)
        register()
        return {"tables": register_tables(self.tables)}

    def description(self) -> dict:
        """Return what the image header says of the profile: its name and each object's."""
        return {"name": self.profile if self.rule is None else f"{self.profile}+{self.rule}",
                "objects": {obj.name: obj.description() for obj in self.objects},
                "bssrdf": "F_t(eta, cos theta_i) R(r) F_t(eta, cos theta_o) / "
                          "(pi (1 - F_dr(eta)))"}


def bssrdf_conversion(scene, integrator: str | None, profile: str | None,
                      channel: int | None = None) -> BSSRDFConversion | None:
    """Return the conversion helper when ``integrator`` is ``bssrdf_path``, else None.

    Raises
    ------
    InputError
        ``bssrdf_path`` without a profile or with an unknown one (the valid ones listed),
        or a profile with another integrator. ``profile`` may end in ``+RULE``, the rule
        that mixes a heterogeneous object's media
        (:data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`).
    """
    from ..materials.profiles import PROFILE_NAMES

    rule = None if profile is None else model_rule(profile)
    if rule is not None:
        profile = without_rule(profile)
    if integrator != INTEGRATOR_NAME:
        if profile is not None:
            raise InputError(f"a profile goes with integrator {INTEGRATOR_NAME} (the "
                             f"volumetric integrators render the medium itself)",
                             file=scene.source, field="profile", value=profile)
        return None
    if profile is None or profile not in PROFILE_NAMES:
        what = f"{INTEGRATOR_NAME} needs a profile" if profile is None else "unknown profile"
        raise InputError(f"{what}; valid: {', '.join(PROFILE_NAMES)}",
                         file=scene.source, field="profile", value=profile)
    return BSSRDFConversion(scene, profile, channel, rule)
