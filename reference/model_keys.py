"""The keys of model references: a profile, the object's geometry, a heterogeneous rule.

A model reference (the BSSRDF path tracer's exact render of a method's model) is named by
``PROFILE[+geometry][+RULE]``: the radial profile
(:data:`~translucent.materials.profiles.PROFILE_NAMES`), ``+geometry`` where the model adds
the object's own shape
(:mod:`translucent.reference.geometry_term`), and ``+RULE`` where a heterogeneous object's
media are mixed by a rule (:data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`).
"""

from __future__ import annotations

from ..materials.profiles import HETEROGENEOUS_RULES

__all__ = ["GEOMETRY_SUFFIX", "model_key", "model_rule", "parse_model_key", "without_rule"]

#: The suffix of a model that includes the object's geometry (``dipole+geometry``).
GEOMETRY_SUFFIX = "+geometry"


def model_key(profile: str, geometry: bool, rule: str | None = None) -> str:
    """Return the model reference's key of ``profile``, with the geometry or without.

    ``rule``: how a heterogeneous object's media are mixed (a key of
    :data:`~translucent.materials.profiles.HETEROGENEOUS_RULES`), added as ``+rule``.

    Examples
    --------
    >>> model_key("dipole", True)
    'dipole+geometry'
    >>> parse_model_key(model_key("better_dipole", False))
    ('better_dipole', False)
    >>> model_key("dipole", False, "segment_mix")
    'dipole+segment_mix'
    """
    return profile + (GEOMETRY_SUFFIX if geometry else "") + (f"+{rule}" if rule else "")


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


def parse_model_key(key: str) -> tuple[str, bool]:
    """Return ``(profile, geometry)`` of a model reference's key (:func:`model_key`).

    A heterogeneous rule (:func:`model_rule`) is left out of ``profile``.
    """
    key = without_rule(key)
    if key.endswith(GEOMETRY_SUFFIX):
        return key[:-len(GEOMETRY_SUFFIX)], True
    return key, False


def without_rule(key: str) -> str:
    """Return ``key`` less its heterogeneous rule (:func:`model_rule`), if it names one.

    Examples
    --------
    >>> without_rule("dipole+segment_mix"), without_rule("dipole")
    ('dipole', 'dipole')
    """
    rule = model_rule(key)
    return key if rule is None else key[:-len(rule) - 1]
