r"""The profile tables of ``bssrdf_path``: what each translucent object's BSSRDF reads.

Each translucent object of a scene (a :class:`~translucent.materials.Dipole` material)
gets a radial profile by name (:func:`translucent.materials.profiles.profile`) and, per RGB
channel, the table its probe rays sample radii from: the profile's own sampling table
(:class:`~translucent.materials.profiles.sampling.RadialSampler`), the piecewise-linear
density :math:`p_c(r) = 2\pi r R_c(r)` (mm^-1) on 0 and 4096 geometric nodes spanning
twelve decades about the medium's mean free path. The integrator evaluates the profile
from the same table,

.. math:: R_c(r) = \frac{p_c(r)}{2\pi r}, \qquad
          q_c(r) = \frac{p_c(r)}{2\pi r\,E_c}\ \text{(mm}^{-2}\text{, the disk density)}

with :math:`E_c` the table's energy (its total diffuse reflectance), so sampling and
evaluation agree to round-off and the renderer renders the tabulated profile exactly.
Against the profile's own numpy evaluation the table errs by the interpolation of
:math:`p_c` between nodes a log-step of 0.0068 apart (stated, per profile, in
tests/reference/test_bssrdf_path.py).

The probe ball of channel c has the radius :math:`r_{\max,c}` holding
:data:`PROBE_ENERGY_FRACTION` of its energy; the largest over channels cuts the BSSRDF
(what lies beyond it, at most 1e-4 of any channel's energy, is not rendered).

Tables are plain arrays: they are kept in this process under a content token that the
Mitsuba scene's integrator names (:func:`register_tables`), and written as ``.npz`` beside
an exported scene (:meth:`ProfileTables.save`).
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..materials import Dipole
from ..materials.dipole import dipole_boundary_factor
from ..materials.profiles import (
    HETEROGENEOUS_RULES,
    PROFILE_NAMES,
    RULE_MAX_MEDIA,
    RadialProfile,
    diffuse_entry_transmittance,
    profile,
    require_radial,
)
from ..materials.solid import SolidMedium, quantise_media

__all__ = [
    "AXIS_PROBABILITIES",
    "PROBE_ENERGY_FRACTION",
    "ProfileTables",
    "TranslucentObject",
    "build_tables",
    "exit_normalisation",
    "register_tables",
    "registered_tables",
    "translucent_objects",
]

#: Energy fraction inside a channel's probe ball (pbrt-v4 uses 0.999 of its first
#: wavelength's); beyond the largest ball the BSSRDF is cut.
PROBE_ENERGY_FRACTION = 0.9999

#: Probabilities of the projection axes: the two tangents and the normal at the entry
#: point (pbrt-v4 ``TabulatedBSSRDF::SampleSp``; Cycles ``subsurface_disk``).
AXIS_PROBABILITIES = (0.25, 0.25, 0.5)

#: Arrays of a table file, in order (:meth:`ProfileTables.save`).
ARRAY_FIELDS = ("eta", "exit_normalisation", "radius", "density", "cumulative", "energy",
                "max_radius", "channel_probability", "first_node", "inverse_log_step",
                "directional", "dd_diffusion", "dd_sigma_tr", "dd_extrapolation",
                "dd_boundary", "dd_c_phi", "dd_c_e", "rule", "media_first", "media_count",
                "label_first", "label_lower", "label_extent", "label_shape", "labels",
                "value_at_zero", "sigma_a", "sigma_s_prime", "boundary")

#: The heterogeneous rules' codes in the tables (0: a homogeneous object).
RULE_CODES = {"geometric_mean": 1, "segment_mix": 2, "segment_average": 3}

#: Points along the segment from the entry to the exit point at which ``segment_mix``
#: reads the medium (midpoints of equal parts): each fraction of Eq. 16 within 1/32 of the
#: segment per boundary it crosses.
SEGMENT_POINTS = 32


def exit_normalisation(eta) -> np.ndarray:
    r"""Return :math:`\int_{H^2} F_t(\eta, \cos\theta)\cos\theta\,d\omega = \pi(1 - F_{dr})`.

    The normalisation of the exit term :math:`S_\omega(\omega_o) = F_t(\eta,
    \cos\theta_o) / (\pi (1 - F_{dr}(\eta)))`, whose cosine-weighted integral over the
    outside hemisphere is 1. In pbrt-v4's terms :math:`1 - F_{dr}(\eta) = \eta^2 c` with
    :math:`c = 1 - 2\,\mathrm{FresnelMoment1}(1/\eta)` (``NormalizedFresnelBxDF``).

    Parameters
    ----------
    eta : array_like
        Relative index (inside over outside), >= 1.

    Returns
    -------
    ndarray
        sr; :math:`\pi` at eta = 1.
    """
    return np.pi * diffuse_entry_transmittance(eta)


@dataclass(frozen=True)
class TranslucentObject:
    """One object the BSSRDF renders: its shape in Mitsuba, its medium and its profile.

    Attributes
    ----------
    index : int
        Its position in ``scene.objects``.
    name : str
        The object's name.
    shape_id : str
        The Mitsuba shape's id (the key of the scene dictionary).
    medium : Dipole
        The medium the profile is made from (mm^-1).
    profile : RadialProfile
        The radial profile sampled (the radial average of a directional one).
    directional : DirectionalDipoleProfile or None
        The directional profile evaluated with each incident direction, where it is one.
    """

    index: int
    name: str
    shape_id: str
    medium: Dipole
    profile: object
    directional: object = None
    #: a heterogeneous object's rule (:data:`RULE_CODES`), its media's profiles, the
    #: label of each voxel of its medium (index ``[z, y, x]``) and the box the voxels fill
    #: (rendering-frame units); ``profile`` is then their mean, which the probes sample
    rule: str | None = None
    media: tuple = ()
    labels: np.ndarray | None = None
    bounds: np.ndarray | None = None
    #: the media themselves (Dipoles, one a profile of ``media``)
    media_coefficients: tuple = ()

    def description(self) -> str:
        """Return the profile's name and model, as the image header says it."""
        if self.rule is not None:
            return (f"{len(self.media)} media, each {self.media[0].model or 'profile'}, "
                    f"mixed by {self.rule} ({HETEROGENEOUS_RULES[self.rule]})")
        made = self.directional if self.directional is not None else self.profile
        return getattr(made, "name", type(made).__name__)


def translucent_objects(scene, profile_name: str, shape_ids, channel: int | None = None,
                        rule: str | None = None) -> list[TranslucentObject]:
    """Return the objects of ``scene`` that ``bssrdf_path`` renders with ``profile_name``.

    Parameters
    ----------
    scene : Scene
    profile_name : str
        One of :data:`~translucent.materials.profiles.PROFILE_NAMES`.
    shape_ids : sequence of str
        The Mitsuba shape id of each object of the scene, in order.
    channel : {0, 1, 2}, optional
        Give every channel this channel's coefficients (a monochrome render).
    rule : str, optional
        How a heterogeneous object's media are mixed (a key of
        :data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`): its solid medium is
        reduced, voxel by voxel, to at most
        :data:`~translucent.materials.profiles.RULE_MAX_MEDIA` media, as the method that
        follows the rule reduces it, and each medium gets ``profile_name``.
        A uniform solid medium is its one Dipole.

    Raises
    ------
    InputError
        An unknown profile (the valid ones listed), a profile that is neither radial nor
        the directional dipole, a translucent object whose mesh is not closed (probe rays
        count its crossings), what the profile refuses of the medium, a heterogeneous
        medium without a rule or with a directional profile; each naming the scene file,
        the field and the value.
    """
    from .manifold_nee import boundary_edge_count

    if profile_name not in PROFILE_NAMES:
        raise InputError(f"unknown profile; valid: {', '.join(PROFILE_NAMES)}",
                         file=scene.source, field="profile", value=profile_name)
    if rule is not None and rule not in HETEROGENEOUS_RULES:
        raise InputError(f"unknown heterogeneous rule; valid: {', '.join(HETEROGENEOUS_RULES)}",
                         file=scene.source, field="rule", value=rule)
    found = []
    for index, obj in enumerate(scene.objects):
        medium = obj.material
        solid = None
        if isinstance(medium, SolidMedium):
            if medium.is_uniform:
                medium = medium.dipole()
            else:
                solid = medium
        elif not isinstance(medium, Dipole):
            continue
        field = f"objects[{index}]"
        open_edges = boundary_edge_count(obj.mesh.vertices, obj.mesh.faces)
        if open_edges:
            raise InputError(
                f"bssrdf_path finds exit points by probe rays that count the crossings of "
                f"a closed surface; this mesh has {open_edges} open or inconsistently "
                f"oriented edges", file=scene.source, field=f"{field}.mesh", value=obj.name)
        if solid is not None:
            found.append(_heterogeneous_object(scene, index, obj, str(shape_ids[index]),
                                               solid, profile_name, channel, rule))
            continue
        medium = _one_channel(medium, channel)
        made = _made(scene, field, obj.name, profile_name, medium)
        directional = None
        if getattr(made, "directional", False):
            if getattr(made, "model", "") != "directional_dipole":
                require_radial(made, field=f"{field}.material (profile {profile_name})")
            directional, made = made, made.radial_average()
        found.append(TranslucentObject(index, obj.name, str(shape_ids[index]), medium, made,
                                       directional))
    return found


def _one_channel(medium: Dipole, channel: int | None) -> Dipole:
    """Return ``medium`` with every channel given ``channel``'s coefficients (None: as is)."""
    if channel is None:
        return medium
    return dataclasses.replace(medium, sigma_a=np.full(3, medium.sigma_a[channel]),
                               sigma_s_prime=np.full(3, medium.sigma_s_prime[channel]))


def _made(scene, field: str, name: str, profile_name: str, medium: Dipole):
    """Return ``profile(profile_name, medium)``, its refusal naming the scene's object."""
    try:
        return profile(profile_name, medium)
    except InputError as error:
        raise InputError(f"profile {profile_name!r} refuses this medium: {error.reason}",
                         file=scene.source, field=f"{field}.material", value=name) from None


def _heterogeneous_object(scene, index: int, obj, shape_id: str, solid: SolidMedium,
                          profile_name: str, channel: int | None,
                          rule: str | None) -> TranslucentObject:
    """Return the :class:`TranslucentObject` of a solid medium mixed by ``rule``."""
    field = f"objects[{index}]"
    if rule is None:
        raise InputError(f"a heterogeneous medium has no one radial profile: render it with "
                         f"a rule that mixes its media (profile '{profile_name}+RULE', RULE "
                         f"one of {', '.join(HETEROGENEOUS_RULES)})", file=scene.source,
                         field=f"{field}.material", value=obj.name)
    if rule == "segment_average" and profile_name != "dipole":
        raise InputError("segment_average evaluates the classical dipole of the averaged "
                         "medium: use profile 'dipole'", file=scene.source, field="profile",
                         value=profile_name)
    quantised = quantise_media(solid, solid.voxel_centres(), max_media=RULE_MAX_MEDIA[rule])
    coefficients = tuple(_one_channel(medium, channel) for medium in quantised.media)
    media = tuple(_made(scene, field, obj.name, profile_name, medium)
                  for medium in coefficients)
    if any(getattr(made, "directional", False) for made in media):
        raise InputError(f"profile {profile_name!r} depends on the incident direction; a "
                         "heterogeneous rule mixes radial profiles", file=scene.source,
                         field="profile", value=profile_name)
    mean = MeanProfile(media)
    return TranslucentObject(index, obj.name, shape_id, _one_channel(quantised.media[0],
                                                                    channel), mean,
                             rule=rule, media=media,
                             labels=quantised.labels.reshape(solid.shape),
                             bounds=np.asarray(solid.bounds, dtype=np.float64),
                             media_coefficients=coefficients)


class MeanProfile(RadialProfile):
    """The mean of a heterogeneous object's media's profiles: what its probes sample.

    Every medium's profile is positive wherever the mean is, so exit points drawn from
    it reach every pair a rule gives light to.
    """

    def __init__(self, media):
        self.media = tuple(media)
        self.name = f"mean of {len(self.media)} media"

    def reflection(self, r) -> np.ndarray:
        """Return the media's mean profile at ``r`` (mm), mm^-2."""
        return np.mean([medium.reflection(r) for medium in self.media], axis=0)

    def length_scale(self) -> np.ndarray:
        """Return the geometric mean of the media's length scales, mm (tables span 12 decades)."""
        return np.exp(np.mean([np.log(medium.length_scale()) for medium in self.media],
                              axis=0))


@dataclass(frozen=True, eq=False)
class ProfileTables:
    r"""The arrays the integrator reads, for ``n`` objects (row ``3 o + c``: object o, channel c).

    Attributes
    ----------
    shape_ids : tuple of str
        Mitsuba shape id of each object.
    mm_per_unit : float
        mm per scene unit (distances are converted once, at lookup).
    eta : ndarray (n,)
        Relative index of each object's boundary.
    exit_normalisation : ndarray (n,)
        :func:`exit_normalisation` of eta, sr.
    radius, density, cumulative : ndarray (3n, K)
        Nodes (mm), :math:`p_c` at the nodes (mm^-1) and its cumulative integral.
    energy : ndarray (3n,)
        :math:`E_c` (dimensionless).
    max_radius : ndarray (3n,)
        Probe-ball radius :math:`r_{\max,c}`, mm.
    channel_probability : ndarray (3n,)
        Probability of sampling with channel c (1/3 each; 0 for a channel without energy).
    first_node, inverse_log_step : ndarray (3n,)
        The first geometric node (mm) and 1 / its log-ratio: node of a radius in O(1).
    directional : ndarray (n,)
        1 where the directional dipole is evaluated with each incident direction.
    dd_diffusion, dd_sigma_tr, dd_extrapolation : ndarray (3n,)
        Its D (mm), sigma_tr (mm^-1) and d_e (mm) per row.
    dd_boundary, dd_c_phi, dd_c_e : ndarray (n,)
        Its A, C_phi and C_E.
    rule : ndarray (n,)
        :data:`RULE_CODES` of a heterogeneous object, 0 for a homogeneous one.
    media_first, media_count : ndarray (n,)
        A heterogeneous object's media: entries ``media_first ..`` (rows ``3 e + c``).
    label_first : ndarray (n,)
        Where its voxels' labels start in ``labels``.
    label_lower, label_extent, label_shape : ndarray (3n,)
        Its voxel box (rendering-frame units: corner and size) and voxels along x, y, z.
    labels : ndarray
        Every heterogeneous object's voxel labels, ``[z, y, x]`` flattened, in turn.
    value_at_zero : ndarray (3 entries,)
        Each entry's profile at r = 0, mm^-2 (Eq. 16's :math:`S_m(0)`; may be Inf for
        profiles no ``segment_mix`` object uses).
    sigma_a, sigma_s_prime : ndarray (3 entries,)
        Each entry's medium, mm^-1 (``segment_average`` averages its media's).
    boundary : ndarray (n,)
        The dipole's internal-reflection factor A of each object's eta.

    The rows past ``3n`` (the entries past the objects) are the heterogeneous objects'
    media, which their rules evaluate.
    """

    shape_ids: tuple
    mm_per_unit: float
    eta: np.ndarray
    exit_normalisation: np.ndarray
    radius: np.ndarray
    density: np.ndarray
    cumulative: np.ndarray
    energy: np.ndarray
    max_radius: np.ndarray
    channel_probability: np.ndarray
    first_node: np.ndarray
    inverse_log_step: np.ndarray
    directional: np.ndarray
    dd_diffusion: np.ndarray
    dd_sigma_tr: np.ndarray
    dd_extrapolation: np.ndarray
    dd_boundary: np.ndarray
    dd_c_phi: np.ndarray
    dd_c_e: np.ndarray
    rule: np.ndarray
    media_first: np.ndarray
    media_count: np.ndarray
    label_first: np.ndarray
    label_lower: np.ndarray
    label_extent: np.ndarray
    label_shape: np.ndarray
    labels: np.ndarray
    value_at_zero: np.ndarray
    sigma_a: np.ndarray
    sigma_s_prime: np.ndarray
    boundary: np.ndarray

    @property
    def count(self) -> int:
        """Number of objects."""
        return len(self.shape_ids)

    @property
    def nodes(self) -> int:
        """Nodes per row, K."""
        return self.radius.shape[1]

    def token(self) -> str:
        """Return a content hash of the tables (what the integrator's ``tables`` names)."""
        digest = hashlib.sha256(repr((self.shape_ids, self.mm_per_unit)).encode())
        for name in ARRAY_FIELDS:
            digest.update(np.ascontiguousarray(getattr(self, name), np.float64).tobytes())
        return "bssrdf-" + digest.hexdigest()[:24]

    def save(self, path) -> Path:
        """Write the tables as ``.npz`` (read back by :meth:`load`)."""
        path = Path(path)
        with open(path, "wb") as handle:
            np.savez_compressed(handle, shape_ids=np.array(self.shape_ids),
                                mm_per_unit=np.float64(self.mm_per_unit),
                                **{name: getattr(self, name) for name in ARRAY_FIELDS})
        return path

    @classmethod
    def load(cls, path) -> ProfileTables:
        """Read tables written by :meth:`save`.

        Raises
        ------
        InputError
            A file that is missing, unreadable or lacks an array (named).
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: np.asarray(data[name], dtype=np.float64)
                          for name in ARRAY_FIELDS}
                shape_ids = tuple(str(s) for s in data["shape_ids"])
                mm_per_unit = float(data["mm_per_unit"])
        except (OSError, ValueError, KeyError) as error:
            raise InputError(f"not a bssrdf_path table file ({error})", file=path,
                             field="tables", value=str(path)) from None
        return cls(shape_ids, mm_per_unit, **arrays)

    def reflectance(self, obj: int, r) -> np.ndarray:
        r"""Return the tabulated :math:`R_c(r)` of object ``obj`` (numpy), ``r.shape + (3,)``.

        What the integrator evaluates (mm^-2 at ``r`` mm), cut at the largest probe ball.
        """
        r = np.asarray(r, dtype=np.float64)
        out = np.zeros(r.shape + (3,))
        cut = self.max_radius[3 * obj:3 * obj + 3].max()
        for c in range(3):
            row = 3 * obj + c
            density = np.interp(r, self.radius[row], self.density[row], right=0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                out[..., c] = np.where((r > 0) & (r <= cut), density / (2 * np.pi * r), 0.0)
        return out


def _row_arrays(sampler, fraction: float):
    """Per channel: nodes, density, cumulative, energy, probe radius of a RadialSampler."""
    radius = np.asarray(sampler.radius, dtype=np.float64)
    density = np.asarray(sampler.density, dtype=np.float64)
    cumulative = np.asarray(sampler.cumulative, dtype=np.float64)
    energy = np.asarray(sampler.energy, dtype=np.float64)
    max_radius = np.array([float(sampler.quantile(fraction)[c]) for c in range(3)])
    return radius, density, cumulative, energy, max_radius


def build_tables(objects: list[TranslucentObject], mm_per_unit: float) -> ProfileTables:
    """Gather the tables of ``objects`` (:func:`translucent_objects`) into one set.

    Entries ``0 .. n-1`` are the objects (what their probes sample); a heterogeneous
    object's media follow as further entries, which only its rule evaluates.

    Raises
    ------
    InputError
        A profile that reflects nothing in every channel (nothing could be sampled), or a
        ``segment_mix`` medium whose profile is not finite and positive at r = 0 (Eq. 16
        divides by it).
    """
    rows = {name: [] for name in ("radius", "density", "cumulative", "energy", "max_radius",
                                  "channel_probability", "first_node", "inverse_log_step",
                                  "dd_diffusion", "dd_sigma_tr", "dd_extrapolation",
                                  "value_at_zero", "sigma_a", "sigma_s_prime")}
    per_object = {name: [] for name in ("eta", "directional", "dd_boundary", "dd_c_phi",
                                        "dd_c_e", "rule", "media_first", "media_count",
                                        "label_first", "label_lower", "label_extent",
                                        "label_shape", "boundary")}
    labels = []

    def add_entry(made, obj, dd=None, reach=None, medium=None):
        radius, density, cumulative, energy, max_radius = _row_arrays(
            made.sampler, PROBE_ENERGY_FRACTION)
        present = energy > 0
        if not present.any():
            raise InputError("the profile reflects nothing in any channel: nothing leaves "
                             "the object", field=f"objects[{obj.index}].material",
                             value=obj.name)
        if reach is not None:
            max_radius = np.maximum(max_radius, reach)
        rows["radius"].append(radius)
        rows["density"].append(density)
        rows["cumulative"].append(cumulative)
        rows["energy"].append(energy)
        rows["max_radius"].append(np.where(present, max_radius, 0.0))
        rows["channel_probability"].append(present / present.sum())
        first = radius[:, 1]
        last = radius[:, -1]
        steps = np.log(last / first) / (radius.shape[1] - 2)
        rows["first_node"].append(first)
        rows["inverse_log_step"].append(1.0 / steps)
        with np.errstate(all="ignore"):
            rows["value_at_zero"].append(np.asarray(made.reflection(np.zeros(1)),
                                                    dtype=np.float64).reshape(3))
        for name in ("dd_diffusion", "dd_sigma_tr", "dd_extrapolation"):
            rows[name].append(np.zeros(3) if dd is None else getattr(dd, name[3:]))
        medium = obj.medium if medium is None else medium
        rows["sigma_a"].append(np.asarray(medium.sigma_a, dtype=np.float64))
        rows["sigma_s_prime"].append(np.asarray(medium.sigma_s_prime, dtype=np.float64))
        return max_radius

    media_entries = []  # (object, its media, reach), as their entries follow the objects
    for obj in objects:
        reach = None
        if obj.rule is not None:
            # the object's probe balls, and its media's cut, hold every medium's reach
            reach = np.max([_row_arrays(made.sampler, PROBE_ENERGY_FRACTION)[4]
                            for made in obj.media], axis=0)
        add_entry(obj.profile, obj, obj.directional, reach)
        dd = obj.directional
        per_object["eta"].append(obj.medium.eta)
        per_object["boundary"].append(float(dipole_boundary_factor(obj.medium.eta)))
        per_object["directional"].append(0.0 if dd is None else 1.0)
        for name in ("boundary", "c_phi", "c_e"):
            per_object["dd_" + name].append(0.0 if dd is None else getattr(dd, name))
        per_object["rule"].append(0.0 if obj.rule is None else RULE_CODES[obj.rule])
        first_medium = len(objects) + sum(len(media) for _, media, _ in media_entries)
        per_object["media_first"].append(first_medium if obj.rule is not None else 0)
        per_object["media_count"].append(len(obj.media))
        per_object["label_first"].append(sum(len(chunk) for chunk in labels))
        if obj.rule is None:
            per_object["label_lower"].append(np.zeros(3))
            per_object["label_extent"].append(np.ones(3))
            per_object["label_shape"].append(np.ones(3))
        else:
            per_object["label_lower"].append(obj.bounds[0])
            per_object["label_extent"].append(obj.bounds[1] - obj.bounds[0])
            per_object["label_shape"].append(np.array(obj.labels.shape[::-1], np.float64))
            labels.append(np.asarray(obj.labels, dtype=np.float64).ravel())
            media_entries.append((obj, obj.media, reach))
    for obj, media, reach in media_entries:
        for made, medium in zip(media, obj.media_coefficients, strict=True):
            add_entry(made, obj, reach=reach, medium=medium)
        if obj.rule == "segment_mix":
            zero = np.array(rows["value_at_zero"][-len(media):])
            if not (np.all(np.isfinite(zero)) and np.all(zero > 0)):
                raise InputError("segment_mix (Eq. 16) divides by each medium's profile at "
                                 f"r = 0, which is {zero.min()} here: use a profile finite "
                                 "there (the dipole)", field=f"objects[{obj.index}].material",
                                 value=obj.name)
    stacked = {name: (np.concatenate(values, axis=0) if values else np.zeros((0,)))
               for name, values in rows.items()}
    eta = np.asarray(per_object.pop("eta"), dtype=np.float64)
    return ProfileTables(
        shape_ids=tuple(obj.shape_id for obj in objects), mm_per_unit=float(mm_per_unit),
        eta=eta, exit_normalisation=exit_normalisation(eta), **stacked,
        labels=np.concatenate(labels) if labels else np.zeros(1),
        **{name: np.asarray(values, dtype=np.float64).ravel()
           for name, values in per_object.items()})


#: Tables of the scenes converted in this process, by token.
_REGISTERED: dict[str, ProfileTables] = {}


def register_tables(tables: ProfileTables) -> str:
    """Keep ``tables`` in this process and return the token the integrator names them by."""
    token = tables.token()
    _REGISTERED[token] = tables
    return token


def registered_tables(token: str) -> ProfileTables:
    """Return the tables registered under ``token``, or read them from a file of that name.

    Raises
    ------
    InputError
        Neither registered here nor a table file.
    """
    tables = _REGISTERED.get(token)
    if tables is not None:
        return tables
    if Path(token).is_file():
        return ProfileTables.load(token)
    raise InputError("bssrdf_path's profile tables are neither converted in this process "
                     "nor a table file; convert the scene with translucent (or export it)",
                     field="tables", value=token)
