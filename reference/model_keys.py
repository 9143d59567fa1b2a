"""The keys of model references: a profile, the object's geometry, a heterogeneous rule.

A model reference (the BSSRDF path tracer's exact render of a method's model) is named by
``PROFILE[+geometry|+walk][+RULE]``: the radial profile
(:data:`~translucent.materials.profiles.PROFILE_NAMES`), ``+geometry`` where the model adds
diffusion's correction for the object's own shape and ``+walk`` where it adds the photon
random walks' (:data:`GEOMETRY_SUFFIXES`, :mod:`translucent.reference.geometry_term`), and
``+RULE`` where a heterogeneous object's media are mixed by a rule
(:data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`).
"""

from __future__ import annotations

from ..materials.profiles import HETEROGENEOUS_RULES

__all__ = ["GEOMETRY_SUFFIX", "GEOMETRY_SUFFIXES", "WALK_SUFFIX", "model_key", "model_rule",
           "parse_model_key", "without_rule"]

#: The suffix of a model that adds diffusion's correction for the object's geometry
#: (``dipole+geometry``, :mod:`translucent.scenes.object_diffusion`).
GEOMETRY_SUFFIX = "+geometry"
#: The suffix of a model that adds the photon random walks' correction (``dipole+walk``,
#: :mod:`translucent.scenes.object_walk`).
WALK_SUFFIX = "+walk"
#: Each geometry model (a value of the methods' knob ``geometry``) and its suffix.
GEOMETRY_SUFFIXES = {"diffusion": GEOMETRY_SUFFIX, "walk": WALK_SUFFIX}


def model_key(profile: str, geometry: bool | str | None, rule: str | None = None) -> str:
    """Return the model reference's key of ``profile``, with the geometry or without.

    ``geometry``: the geometry model (a key of :data:`GEOMETRY_SUFFIXES`; True is
    ``"diffusion"``), or None / False for the half-space profile alone.

    ``rule``: how a heterogeneous object's media are mixed (a key of
    :data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`), added as ``+rule``.

    Examples
    --------
    >>> model_key("dipole", True)
    'dipole+geometry'
    >>> parse_model_key(model_key("better_dipole", False))
    ('better_dipole', None)
    >>> model_key("dipole", False, "segment_mix")
    'dipole+segment_mix'
    >>> model_key("dipole", "walk")
    'dipole+walk'
    """
    if geometry is True:
        geometry = "diffusion"
    suffix = GEOMETRY_SUFFIXES[geometry] if geometry else ""
    return profile + suffix + (f"+{rule}" if rule else "")


def model_rule(key: str) -> str | None:
    """Return the heterogeneous rule a model key names (None: none).

    Examples
    --------
    >>> model_rule("dipole+geometric_mean"), model_rule("dipole+geometry")
    ('geometric_mean', None)
    """
    for rule in HETEROGENEOUS_RULES:
        if key.endswith(f"+{rule}"):
            return rule
    return None


def parse_model_key(key: str) -> tuple[str, str | None]:
    """Return ``(profile, geometry)`` of a model reference's key (:func:`model_key`).

    ``geometry`` is the geometry model (a key of :data:`GEOMETRY_SUFFIXES`), or None. A
    heterogeneous rule (:func:`model_rule`) is left out of ``profile``.

    Examples
    --------
    >>> parse_model_key("dipole+walk"), parse_model_key("dipole")
    (('dipole', 'walk'), ('dipole', None))
    """
    key = without_rule(key)
    for model, suffix in GEOMETRY_SUFFIXES.items():
        if key.endswith(suffix):
            return key[:-len(suffix)], model
    return key, None


def without_rule(key: str) -> str:
    """Return ``key`` less its heterogeneous rule (:func:`model_rule`), if it names one.

    Examples
    --------
    >>> without_rule("dipole+segment_mix"), without_rule("dipole")
    ('dipole', 'dipole')
    """
    rule = model_rule(key)
    return key if rule is None else key[:-len(rule) - 1]
