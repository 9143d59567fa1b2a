r"""Profiles found by name: :func:`profile` over the mapping :data:`PROFILES`.

Each entry names a model, says in one line what it is, and makes it from a medium (a
:class:`~translucent.materials.homogeneous.Dipole` or a measured medium's name, Jensen et
al. 2001). Every profile a name gives is a
:class:`~translucent.materials.profiles.base.RadialProfile`, except the directional
dipole, which depends on the incident direction; ``radial=True`` asks for its azimuthal
average instead. An unknown name is an :class:`~translucent.errors.InputError` listing the
valid ones; ``translucent profiles`` prints the mapping.

Examples
--------
>>> import translucent
>>> marble = translucent.profile("better_dipole", "Marble")
>>> [round(float(v), 4) for v in marble.total()]
[0.8345, 0.7943, 0.7543]
>>> translucent.profile("burley_dmfp", "Marble").radius_containing(0.99).shape
(3,)
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any

from ...errors import InputError
from ..catalogue import measured_medium
from ..homogeneous import Dipole
from .better_dipole import BetterDipoleProfile
from .burley import BurleyProfile
from .classical_dipole import DipoleProfile
from .directional_dipole import DirectionalDipoleProfile
from .photon_beam_diffusion import PhotonBeamDiffusionProfile
from .quantized_diffusion import QuantizedDiffusionProfile
from .random_walk import RandomWalkProfile

__all__ = ["PROFILES", "PROFILE_NAMES", "ProfileEntry", "profile", "profile_descriptions"]


@dataclass(frozen=True)
class ProfileEntry:
    """A registered profile: how to make it from a medium and what it is, in one line."""

    make: Any
    description: str
    directional: bool = False


def _dipole(medium, entry_fresnel: bool = False):
    # per unit power entering, as every other profile here (the dipole's own default for
    # radiosity multiplies by the diffuse entry transmittance)
    return DipoleProfile(medium, entry_fresnel=entry_fresnel)


def _burley(fit):
    def make(medium, surface_albedo=None):
        return BurleyProfile(medium, fit, surface_albedo=surface_albedo)
    return make


#: name -> entry, in the order ``translucent profiles`` lists them.
PROFILES: dict[str, ProfileEntry] = {
    "dipole": ProfileEntry(_dipole, "classical dipole (Jensen et al. 2001)"),
    "better_dipole": ProfileEntry(
        BetterDipoleProfile, "better dipole: Grosjean's D, exact boundary (d'Eon 2012)"),
    "quantized_diffusion": ProfileEntry(
        QuantizedDiffusionProfile,
        "quantized diffusion: the beam's time-resolved diffusion as Gaussians "
        "(d'Eon and Irving 2011)"),
    "photon_beam_diffusion": ProfileEntry(
        PhotonBeamDiffusionProfile,
        "photon beam diffusion, multiple + single scattering (Habel et al. 2013), "
        "pbrt-v4's table"),
    "burley_searchlight": ProfileEntry(
        _burley("searchlight"),
        "Christensen-Burley normalized diffusion, searchlight fit on the mean free path "
        "(2015, Eq. 5)"),
    "burley_transmission": ProfileEntry(
        _burley("transmission"),
        "Christensen-Burley normalized diffusion, diffuse surface transmission fit on the "
        "mean free path (2015, Eq. 6)"),
    "burley_dmfp": ProfileEntry(
        _burley("dmfp"),
        "Christensen-Burley normalized diffusion, searchlight fit on the diffuse mean free "
        "path (2015, Eq. 8)"),
    "burley_cycles": ProfileEntry(
        _burley("cycles"),
        "Christensen-Burley as Blender Cycles evaluates it: d = radius / (4 pi), cut at 16 d"),
    "directional_dipole": ProfileEntry(
        DirectionalDipoleProfile,
        "directional dipole: depends on the incident direction (Frisvad, Hachisuka, "
        "Kjeldsen 2014)", directional=True),
    "random_walk": ProfileEntry(
        RandomWalkProfile,
        "the photon random walk's own profile, tabulated (transport, exact boundary)"),
}

#: The names :func:`profile` takes.
PROFILE_NAMES: tuple[str, ...] = tuple(PROFILES)


def profile_descriptions() -> dict[str, str]:
    """Return name -> one-line description, in :data:`PROFILE_NAMES` order."""
    return {name: entry.description for name, entry in PROFILES.items()}


def _medium(medium) -> Dipole:
    if isinstance(medium, Dipole):
        return medium
    if isinstance(medium, str):
        return measured_medium(medium)
    raise InputError("must be a Dipole (sigma_a, sigma_s', eta, g) or a measured medium's "
                     "name", field="medium", value=type(medium).__name__)


def profile(name: str, medium, *, radial: bool = False, **options):
    """Make the profile ``name`` of ``medium``.

    Parameters
    ----------
    name : str
        One of :data:`PROFILE_NAMES`.
    medium : Dipole or str
        The medium (RGB coefficients in mm^-1), or a measured medium's name ("Marble").
    radial : bool
        For a directional profile, return its radial average (a
        :class:`~translucent.materials.profiles.base.RadialProfile`); radial profiles are
        returned as they are.
    **options
        Passed to the profile: ``incident_angle`` (radians) for the directional dipole,
        ``surface_albedo`` for the Burley variants, ``entry_fresnel`` for the dipole.

    Returns
    -------
    RadialProfile or DirectionalDipoleProfile

    Raises
    ------
    InputError
        An unknown name (the message lists the valid ones), a medium that is not one, an
        option the profile does not take, or what the profile itself refuses.
    """
    entry = PROFILES.get(name) if isinstance(name, str) else None
    if entry is None:
        raise InputError(f"unknown profile; valid: {', '.join(PROFILE_NAMES)}",
                         field="profile", value=name)
    medium = _medium(medium)
    try:
        inspect.signature(entry.make).bind(medium, **options)
    except TypeError as error:
        raise InputError(f"profile {name!r} does not take these options ({error})",
                         field="options", value=sorted(options)) from None
    made = entry.make(medium, **options)
    if radial and entry.directional:
        return made.radial_average()
    return made
