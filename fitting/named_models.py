r"""Fit any radial profile of the literature: ``translucent fit --model NAME``.

:class:`NamedProfileModel` is the dipole's parameterisation (``ln sigma_a`` and
``ln sigma_s'`` per channel, eta where unknown, the exposure where unknown; its priors,
starting points and material file) with the forward profile one of
:mod:`translucent.materials.profiles` by name: the better dipole, quantized diffusion,
photon beam diffusion, the Christensen-Burley fits, the photon random walk's table. The
profile is read from its table in reduced units
(:func:`~translucent.materials.profiles.reduced_table.reduced_table`: built once a process,
at the capture's eta, or at :data:`FIT_ETA_POINTS` etas over the prior when eta is fitted):
an emcee chain evaluates it for every walker at every step, which the profile objects
themselves (milliseconds each) could not afford. How closely the table reads each profile
is measured in docs/capture-format.md and held by tests/fitting/test_named_models.py.

Semi-infinite reflection only (the profiles are a half-space's); the material file holds
the coefficients as a ``dipole`` material, with a note naming the profile they belong to.

Examples
--------
>>> sorted(NAMED_MODELS)[:3]
['better_dipole', 'burley_cycles', 'burley_dmfp']
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from .capture import CaptureSpec
from .models import ETA_FIT_RANGE, ReducedTableModel, check_semi_infinite_reflection
from .profile import RadialProfile

__all__ = ["FIT_ETA_POINTS", "NAMED_MODELS", "NamedProfileModel", "named_model_names"]

#: Etas tabulated over :data:`~.models.ETA_FIT_RANGE` when eta is fitted (steps of 0.05).
FIT_ETA_POINTS = 21


def named_model_names() -> tuple[str, ...]:
    """Return the profiles ``fit --model`` takes by name, besides ``dipole`` and ``walk``.

    Every radial profile of :data:`~translucent.materials.profiles.PROFILE_NAMES` but the
    classical dipole (the ``dipole`` model, which also has the slab multipole) and the
    photon random walk's table (the ``walk`` model, with the table's own noise).
    """
    from ..materials.profiles.registry import PROFILES

    return tuple(name for name, entry in PROFILES.items()
                 if not entry.directional and name not in ("dipole", "random_walk"))


NAMED_MODELS = named_model_names()


class NamedProfileModel(ReducedTableModel):
    """A radial profile by name, with the dipole's per-channel coefficients.

    Parameters
    ----------
    profile : RadialProfile
        The capture's measured profile.
    spec : CaptureSpec
    fit_eta : bool, optional
        As :class:`~.models.DipoleModel`.
    name : str
        One of :data:`NAMED_MODELS`.

    Raises
    ------
    InputError
        An unknown name (the valid ones listed), a transmission capture or a slab of finite
        thickness.
    """

    def __init__(self, profile: RadialProfile, spec: CaptureSpec, *,
                 fit_eta: bool | None = None, name: str):
        from ..materials.profiles.reduced_table import reduced_table

        if name not in NAMED_MODELS:
            raise InputError(f"unknown model; valid: dipole, walk, subedit, "
                             f"{', '.join(NAMED_MODELS)}", field="model", value=name)
        check_semi_infinite_reflection(spec, name)
        fitted = spec.eta is None if fit_eta is None else bool(fit_eta)
        etas = (tuple(np.linspace(*ETA_FIT_RANGE, FIT_ETA_POINTS)) if fitted or spec.eta is None
                else (float(spec.eta),))
        self.name = name
        self.table = reduced_table(name, etas)
        super().__init__(profile, spec, fit_eta=fit_eta)
