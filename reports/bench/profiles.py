r"""Radial profiles against the photon random walk: every registered profile, two sets of media.

``translucent bench profiles`` measures each radial profile of
:data:`~translucent.materials.profiles.PROFILE_NAMES` (the directional dipole by its radial
average at normal incidence) against the photon random walk of
:mod:`translucent.fitting.random_walk` (transport, checked against MCML), on

* a grid in optical units (:math:`\sigma_t = 1` mm^-1, so lengths are mean free paths):
  single-scattering albedos :math:`\alpha = \sigma_s/\sigma_t` (``--albedos``) x relative
  indices (``--etas``) x Henyey-Greenstein asymmetries (``--gs``); the walk scatters with
  :math:`\sigma_s = \alpha`, :math:`\sigma_a = 1 - \alpha` and the phase function of g,
  the profiles take the reduced coefficients :math:`\sigma'_s = (1 - g)\sigma_s` (the
  similarity relation), as every profile of the registry does;
* the 12 measured media of Jensen et al. 2001 (``--media``), each RGB channel a row.

Both sides are per unit power *entering* the medium: the walk starts each photon inside,
below the entry point, with unit weight at normal incidence (no entry Fresnel term), and
every registered profile is made per unit power entering (the dipole with
``entry_fresnel=False``). Exits are binned into rings about the entry point, geometric in
the reduced radius :math:`\sigma'_t r` (:data:`RINGS_PER_DECADE`), and compared ring by
ring with the profile's energy in the same ring (:func:`ring_energy`). Per row and profile:

* ``total``: the relative error of the total diffuse reflectance (profile's ``total()``
  against all the walk's exits);
* ``l1``: the energy-weighted relative L1 error, :math:`\sum_k |E^p_k - E^{MC}_k| /
  \sum_k E^{MC}_k` over the rings inside the radius holding 99 % of the walk's energy
  (:math:`E_k` the energy of ring k);
* ``near``: the same over the rings inside one reduced mean free path :math:`1/\sigma'_t`
  of the entry point;
* ``tail``: the same over the rings between the radii holding 90 % and 99 %.

Each walk row has its own noise, from independent batches (:data:`BATCHES`): for the total
its standard error (the weight lost at the kill radius added in quadrature), for an L1
measure the L1 that an exact profile would get from the walk's noise alone,
:math:`\sqrt{2/\pi}\sum_k \sigma_k / \sum_k E^{MC}_k`. An error at most
:data:`WITHIN_NOISE` times its noise is "within noise": the walk does not resolve it.

The Burley comparison (:func:`burley_comparison`) repeats the set-up of Christensen and
Burley 2015 for their searchlight fit: eta = 1, g = 0, mean free path 1, the surface
albedo A the walk's own total, averaged over :data:`BURLEY_ALBEDOS`; the memo reports an
average relative error of :data:`BURLEY_PUBLISHED`.

The walks are cached (``Cache("bench_profiles")``, keyed by the content hash of the walk's
settings): a second run reads them. The bench also times each profile's ``reflection`` on
:data:`TIMING_RADII` radii x 3 channels (target :data:`EVALUATION_TARGET_SECONDS`) and its
construction (the build of any table), beside ``np.exp`` over as many numbers in the same
run. It writes JSON, a Markdown table and one PNG per plotted medium into ``--out``.

References
----------
P. H. Christensen, B. Burley: Approximate reflectance profiles for efficient subsurface
scattering. Pixar Technical Memo 15-04, 2015.
H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan: A practical model for subsurface
light transport. SIGGRAPH 2001 (Table 1: the measured media).
L. Wang, S. L. Jacques, L. Zheng: MCML. Computer Methods and Programs in Biomedicine 47,
1995.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...atomic import atomic_write_text, check_output_folder
from ...errors import InputError, check_count
from ...materials import Dipole, measured_medium, measured_medium_names
from ...materials.profiles import PROFILE_NAMES, profile
from . import steps_bar, write_figures
from ._profiles_output import markdown, plot_medium

__all__ = [
    "BATCHES", "BURLEY_ALBEDOS", "BURLEY_PUBLISHED", "Case", "DEFAULT_ALBEDOS", "DEFAULT_ETAS",
    "DEFAULT_GS", "DEFAULT_PHOTONS", "METRICS", "Settings", "burley_comparison",
    "check_settings", "command_line", "grid_cases", "markdown", "measure_row", "media_cases",
    "profiles_table", "ring_energy", "time_profiles", "walk_rings",
]

#: Single-scattering albedos of the grid: the Burley set, with 0.95 and 0.999 added.
DEFAULT_ALBEDOS = (0.01, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 0.99, 0.999)
DEFAULT_ETAS = (1.0, 1.3, 1.5)
DEFAULT_GS = (0.0, 0.8)
#: Photons per walk row (one channel each): the high-albedo rows reach a relative standard
#: error of their total near 1e-3, and the grid with the 12 media and the Burley set stays
#: within 20 minutes of wall clock on two shared cores (docs/profiles.md).
DEFAULT_PHOTONS = 100_000
#: ``--quick``: a tiny table for tests (two albedos, one boundary, one medium).
QUICK = {"albedos": (0.5, 0.99), "etas": (1.0,), "gs": (0.0,), "media": ("Ketchup",),
         "photons": 4000, "burley_albedos": (0.5, 0.99), "burley_photons": 4000}
#: Independent batches of each walk (its standard errors); 16 batches estimate a standard
#: error to about 18 %.
BATCHES = 16
#: Seeds of the walks come from the hash of their settings (reproducible, distinct).
SEED_DIGITS = 12
#: A walk of more photons runs in independent chunks of this many (each holds an exit
#: buffer of about 50 bytes x 12 exits a photon) and pools them.
CHUNK_PHOTONS = 200_000

#: Ring edges in reduced radius sigma_t' r: 0, then 10^(k / RINGS_PER_DECADE) from
#: INNER_RADIUS on (decades are edges, so one mean free path is one).
RINGS_PER_DECADE = 16
INNER_RADIUS = 1e-2
#: The last ring reaches OUTER_DIFFUSION_LENGTHS diffusion lengths 1/sigma_tr (at least
#: MIN_OUTER, at most MAX_OUTER reduced radii; a non-absorbing medium takes MAX_OUTER). The
#: walk's kill radius lies 20 mean free paths beyond: Spectralon (no absorption, 99 % of
#: its energy inside about 170 mean free paths) then loses 0.6 % of the entering power
#: there, which its noise counts; a kill radius twice as far costs twice the walk time.
OUTER_DIFFUSION_LENGTHS = 10.0
MIN_OUTER = 30.0
MAX_OUTER = 500.0
#: Gauss-Legendre nodes per ring for the profile's energy in the ring (rings span a factor
#: 1.155 in radius; the first, from 0, holds r R(r), finite for the 1/r of single
#: scattering).
RING_NODES = 8

#: The energy fractions that bound the L1 measures.
FRACTION = 0.99
TAIL_FROM = 0.90
#: An error at most this many times its noise is "within noise" (two standard errors for
#: the total; twice the L1 of an exact profile for the L1 measures).
WITHIN_NOISE = 2.0
#: The error measures, in table order.
METRICS = ("total", "l1", "near", "tail")

#: The Burley comparison: albedos over (0, 1) and the figure of Christensen and Burley 2015
#: for their searchlight fit against Monte Carlo (average relative error, as a fraction).
BURLEY_ALBEDOS = (0.01, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.99)
BURLEY_PUBLISHED = 0.053
#: Photons per albedo of the Burley comparison: its L1 an exact fit would get from the
#: walk's noise alone is then about 0.6 % (measured), well below the fit's error.
BURLEY_PHOTONS = 2_000_000
#: A difference from the published figure above this (fraction) is explained in the docs.
BURLEY_EXPLAIN = 0.015

#: Plotted media (those of them in the run; else the run's first medium).
PLOT_MEDIA = ("Marble", "Skin1", "Ketchup", "Wholemilk")
#: Means within this relative distance of the smallest tie for "best".
TIE = 1e-9
#: The walk's own table is the reference's table: "best model" leaves it out.
TRANSPORT_TABLE = "random_walk"

#: Timing: radii per evaluation, repeats (best of), the medium, its radii's range (mm).
TIMING_RADII = 1_000_000
TIMING_REPEATS = 7
TIMING_MEDIUM = "Skin1"
TIMING_RANGE_MM = 20.0
#: Target for one evaluation of TIMING_RADII radii x 3 channels (issue 36), seconds.
EVALUATION_TARGET_SECONDS = 0.050

JSON_NAME = "profiles.json"
MARKDOWN_NAME = "profiles.md"
#: Bumped when the JSON layout changes; WALK_FORMAT when the cached walk rows change.
FORMAT = 1
WALK_FORMAT = 1


# ---------------------------------------------------------------------- settings and cases


@dataclass(frozen=True)
class Settings:
    """What a run measures (checked by :func:`check_settings`)."""

    albedos: tuple = DEFAULT_ALBEDOS
    etas: tuple = DEFAULT_ETAS
    gs: tuple = DEFAULT_GS
    media: tuple = tuple(measured_medium_names())
    photons: int = DEFAULT_PHOTONS
    burley_albedos: tuple = BURLEY_ALBEDOS
    burley_photons: int = BURLEY_PHOTONS
    timing_radii: int = TIMING_RADII
    timing_repeats: int = TIMING_REPEATS


def _numbers(values, field: str, low: float, high: float, what: str,
             low_open: bool = False) -> tuple:
    """Return ``values`` (a comma-separated string or a sequence) as floats in range."""
    parts = ([p.strip() for p in values.split(",") if p.strip()] if isinstance(values, str)
             else list(values))
    try:
        numbers = tuple(float(p) for p in parts)
    except (TypeError, ValueError):
        raise InputError(f"must be comma-separated numbers ({what})", field=field,
                         value=values) from None
    for number in numbers:
        below = number <= low if low_open else number < low
        if not math.isfinite(number) or below or number > high:
            raise InputError(f"must lie in {'(' if low_open else '['}{low:g}, {high:g}] "
                             f"({what})", field=field, value=number)
    if not numbers:
        raise InputError(f"needs at least one value ({what})", field=field, value=values)
    return tuple(dict.fromkeys(numbers))


def check_settings(*, albedos=DEFAULT_ALBEDOS, etas=DEFAULT_ETAS, gs=DEFAULT_GS,
                   media=None, photons=DEFAULT_PHOTONS, burley_albedos=BURLEY_ALBEDOS,
                   burley_photons=BURLEY_PHOTONS, timing_radii=TIMING_RADII,
                   timing_repeats=TIMING_REPEATS) -> Settings:
    """Return checked :class:`Settings`; :class:`InputError` naming the option otherwise.

    Parameters
    ----------
    albedos : str or sequence of float
        Single-scattering albedos in (0, 1].
    etas : str or sequence of float
        Relative indices in [1, 2] (the span of the walk table the random-walk and Burley
        profiles read).
    gs : str or sequence of float
        Henyey-Greenstein asymmetries in [-0.95, 0.95].
    media : str or sequence of str, optional
        Measured media (default all 12); ``"none"`` or an empty string: none.
    photons : int
        Photons per walk row, at least 10 per batch.
    burley_albedos : sequence of float
        Albedos in (0, 1) of the Burley comparison.
    burley_photons : int
        Photons per albedo of the Burley comparison, at least 10 per batch.
    timing_radii, timing_repeats : int
        Radii per timed evaluation and repeats (best of).
    """
    albedos = _numbers(albedos, "--albedos", 0.0, 1.0, "single-scattering albedos",
                       low_open=True)
    etas = _numbers(etas, "--etas", 1.0, 2.0, "relative indices; the walk table spans 1-2")
    gs = _numbers(gs, "--gs", -0.95, 0.95, "Henyey-Greenstein g")
    if media is None:
        media = tuple(measured_medium_names())
    elif isinstance(media, str):
        media = () if media.strip().lower() in ("", "none") else tuple(
            p.strip() for p in media.split(",") if p.strip())
    known = {name.lower(): name for name in measured_medium_names()}
    for name in media:
        if str(name).lower() not in known:
            raise InputError(f"unknown measured medium; valid: {', '.join(known.values())}",
                             field="--media", value=name)
    media = tuple(dict.fromkeys(known[str(name).lower()] for name in media))
    photons = check_count(photons, "--photons", 10 * BATCHES,
                          why=f" (10 per batch, {BATCHES} batches)")
    burley_albedos = _numbers(burley_albedos, "burley_albedos", 0.0, 1.0,
                              "single-scattering albedos", low_open=True)
    burley_photons = check_count(burley_photons, "--burley-photons", 10 * BATCHES,
                                 why=f" (10 per batch, {BATCHES} batches)")
    return Settings(albedos, etas, gs, media, photons, burley_albedos, burley_photons,
                    check_count(timing_radii, "timing_radii", 1000),
                    check_count(timing_repeats, "timing_repeats", 1))


@dataclass(frozen=True)
class Case:
    """One walk row: a medium's channel (coefficients in mm^-1).

    ``medium`` is what the profiles are made from (RGB), ``channel`` the one compared.
    """

    kind: str
    label: str
    medium: Dipole
    channel: int
    albedo: float | None = None

    @property
    def sigma_a(self) -> float:
        """Absorption coefficient of the channel, mm^-1."""
        return float(self.medium.sigma_a[self.channel])

    @property
    def sigma_s_prime(self) -> float:
        """Reduced scattering coefficient of the channel, mm^-1."""
        return float(self.medium.sigma_s_prime[self.channel])

    @property
    def sigma_t_prime(self) -> float:
        """Reduced extinction sigma_a + sigma_s', mm^-1."""
        return self.sigma_a + self.sigma_s_prime

    def walk_settings(self, photons: int) -> dict:
        """Return what determines the walk (the cache key hashes it)."""
        medium = self.medium
        return {"sigma_a": self.sigma_a, "sigma_s_prime": self.sigma_s_prime,
                "eta": float(medium.eta), "g": float(medium.g), "photons": int(photons),
                "batches": BATCHES, "edges": reduced_edges(self).tolist(),
                "format": WALK_FORMAT}


def grid_cases(albedos, etas, gs) -> list[Case]:
    r"""Return the grid's cases in optical units: :math:`\sigma_t = 1` mm^-1, one channel."""
    cases = []
    for g in gs:
        for eta in etas:
            for albedo in albedos:
                medium = Dipole(sigma_a=[1.0 - albedo] * 3,
                                sigma_s_prime=[albedo * (1.0 - g)] * 3, eta=eta, g=g,
                                name=f"albedo {albedo:g}")
                cases.append(Case("grid", f"a={albedo:g} eta={eta:g} g={g:g}", medium, 0,
                                  float(albedo)))
    return cases


def media_cases(media) -> list[Case]:
    """Return one case per RGB channel of each measured medium (its own eta, g = 0)."""
    return [Case("medium", f"{name} {'RGB'[c]}", measured_medium(name), c)
            for name in media for c in range(3)]


# ---------------------------------------------------------------------- the walk


def reduced_edges(case: Case) -> np.ndarray:
    """Return the ring edges in reduced radius sigma_t' r for ``case`` (see the constants)."""
    albedo = case.sigma_s_prime / case.sigma_t_prime
    sigma_tr = math.sqrt(3.0 * max(1.0 - albedo, 0.0))
    outer = MAX_OUTER if sigma_tr == 0 else OUTER_DIFFUSION_LENGTHS / sigma_tr
    outer = min(MAX_OUTER, max(MIN_OUTER, outer))
    first = round(RINGS_PER_DECADE * math.log10(INNER_RADIUS))
    last = math.ceil(RINGS_PER_DECADE * math.log10(outer))
    powers = np.arange(first, last + 1) / RINGS_PER_DECADE
    return np.concatenate([[0.0], 10.0 ** powers])


def _walk(case: Case, settings: dict) -> dict:
    """Walk ``case`` in chunks of at most :data:`CHUNK_PHOTONS` and pool them."""
    from ...cache import content_hash
    from ...fitting.random_walk import photon_random_walk

    medium = Dipole(sigma_a=[case.sigma_a] * 3, sigma_s_prime=[case.sigma_s_prime] * 3,
                    eta=case.medium.eta, g=case.medium.g)
    edges = np.asarray(settings["edges"]) / case.sigma_t_prime
    seed = int(content_hash(settings)[:SEED_DIGITS], 16)
    photons = settings["photons"]
    sizes = [CHUNK_PHOTONS] * (photons // CHUNK_PHOTONS) + (
        [photons % CHUNK_PHOTONS] if photons % CHUNK_PHOTONS else [])
    if len(sizes) > 1 and sizes[-1] < 10 * BATCHES:  # a last chunk too small to batch
        sizes[-2] += sizes.pop()
    tallies = [photon_random_walk(medium, photons=size, radial_edges_mm=edges,
                                  batches=BATCHES, seed=seed + index, channels=(0,))
               for index, size in enumerate(sizes)]
    share = np.asarray(sizes, dtype=np.float64) / photons  # independent chunks, pooled

    def pooled(name):
        return sum(w * getattr(t, name)[..., 0] for w, t in zip(share, tallies, strict=True))

    def pooled_se(name):
        return np.sqrt(sum((w * getattr(t, name)[..., 0]) ** 2
                           for w, t in zip(share, tallies, strict=True)))

    return {"edges_mm": edges, "reflectance": pooled("reflectance"),
            "reflectance_se": pooled_se("reflectance_se"),
            "total": float(pooled("total_reflectance")),
            "total_se": float(pooled_se("total_reflectance_se")),
            "lost": float(pooled("lost")), "seconds": float(sum(t.seconds for t in tallies)),
            "photons": int(photons), "seed": seed}


def walk_rings(case: Case, photons: int) -> tuple[dict, bool]:
    """Return the walk's rings for ``case`` and whether they came from the cache.

    Parameters
    ----------
    case : Case
    photons : int
        Photons of the walk (one channel).

    Returns
    -------
    (dict, bool)
        ``edges_mm`` (ring edges, mm), ``reflectance`` and ``reflectance_se`` (mean
        exitance over each ring and its standard error, mm^-2 per entering photon),
        ``total``, ``total_se``, ``lost`` (fractions of the entering power), ``seconds``,
        ``photons``, ``seed``; and True where the cache held it.
    """
    from ...cache import Cache, content_hash

    settings = case.walk_settings(photons)
    key = content_hash({"bench": "profiles", "walk": settings})
    value, made = Cache("bench_profiles").load_or_make(
        key, lambda: _walk(case, settings), what=f"the walk of {case.label}",
        valid=lambda value: isinstance(value, dict) and "reflectance_se" in value)
    return value, not made


# ---------------------------------------------------------------------- the comparison


def ring_energy(made, edges, channel: int) -> np.ndarray:
    r"""Return a profile's energy in each ring, :math:`2\pi\int R(r)\,r\,dr` (per unit power).

    Parameters
    ----------
    made : RadialProfile
    edges : ndarray, shape (K + 1,)
        Ring edges, mm, increasing from 0.
    channel : int

    Returns
    -------
    ndarray, shape (K,)
        Dimensionless; Gauss-Legendre with :data:`RING_NODES` nodes per ring.
    """
    nodes, weights = np.polynomial.legendre.leggauss(RING_NODES)
    inner, outer = edges[:-1, None], edges[1:, None]
    half = 0.5 * (outer - inner)
    r = inner + half * (nodes + 1.0)
    values = made.reflection(r)[..., channel]
    return 2.0 * np.pi * np.sum(values * r * weights * half, axis=1)


def _regions(mc: dict, mean_free_path: float) -> dict:
    """Return the rings of each L1 measure and the radii holding 90 % and 99 %."""
    edges = mc["edges_mm"]
    energy = mc["reflectance"] * np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    cumulative = np.cumsum(energy) / mc["total"] if mc["total"] > 0 else np.ones_like(energy)
    k99 = min(int(np.searchsorted(cumulative, FRACTION)), energy.size - 1)
    k90 = min(int(np.searchsorted(cumulative, TAIL_FROM)), k99)
    index = np.arange(energy.size)
    near = index[(edges[1:] <= mean_free_path * (1 + 1e-9)) & (index <= k99)]
    tail = index[k90 + 1:k99 + 1] if k99 > k90 else index[k90:k99 + 1]
    return {"l1": index[:k99 + 1], "near": near, "tail": tail, "energy": energy,
            "radius_90": float(np.interp(TAIL_FROM, cumulative, edges[1:])),
            "radius_99": float(np.interp(FRACTION, cumulative, edges[1:])),
            "resolved": bool(cumulative[-1] >= FRACTION)}


def _mc_noise(mc: dict, regions: dict) -> dict:
    """Return the walk's own noise in each error measure (see the module docstring)."""
    edges = mc["edges_mm"]
    spread = mc["reflectance_se"] * np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    noise = {"total": math.hypot(mc["total_se"], mc["lost"]) / mc["total"]
             if mc["total"] > 0 else math.nan}
    for metric in METRICS[1:]:
        rings = regions[metric]
        held = regions["energy"][rings].sum()
        noise[metric] = (math.sqrt(2.0 / math.pi) * spread[rings].sum() / held
                         if rings.size and held > 0 else math.nan)
    return noise


def _errors(energy, total, mc: dict, regions: dict) -> dict:
    errors = {"total": (total - mc["total"]) / mc["total"] if mc["total"] > 0 else math.nan}
    for metric in METRICS[1:]:
        rings = regions[metric]
        held = regions["energy"][rings].sum()
        errors[metric] = (float(np.abs(energy[rings] - regions["energy"][rings]).sum() / held)
                          if rings.size and held > 0 else math.nan)
    return errors


def _profiles_of(medium: Dipole) -> dict:
    """Return name -> radial profile of ``medium``, or the reason it was refused."""
    made = {}
    for name in PROFILE_NAMES:
        try:
            made[name] = profile(name, medium, radial=True)
        except InputError as error:
            made[name] = str(error)
    return made


def measure_row(case: Case, mc: dict, made: dict, cached: bool = False) -> dict:
    """Return one row: the walk's figures and noise, each profile's errors against them.

    Parameters
    ----------
    case : Case
    mc : dict
        :func:`walk_rings`' rings.
    made : dict
        Profile name -> RadialProfile of ``case.medium`` (or the reason it was refused).
    cached : bool
        Whether the walk came from the cache.

    Returns
    -------
    dict
        ``case``, ``kind``, coefficients (mm^-1), ``mean_free_path`` (1/sigma_t', mm),
        ``mc`` (total, its standard error, lost weight, radii holding 90 % and 99 % (mm),
        ``noise`` per measure, seconds, photons, cached) and ``profiles`` (per name:
        ``status``, ``reason``, ``total``, ``errors`` and ``within_noise`` per measure).
    """
    mean_free_path = 1.0 / case.sigma_t_prime
    regions = _regions(mc, mean_free_path)
    noise = _mc_noise(mc, regions)
    results = {}
    for name, candidate in made.items():
        if isinstance(candidate, str):
            results[name] = {"status": "refused", "reason": candidate}
            continue
        energy = ring_energy(candidate, mc["edges_mm"], case.channel)
        total = float(candidate.total()[case.channel])
        errors = _errors(energy, total, mc, regions)
        results[name] = {"status": "ok", "reason": "", "total": total, "errors": errors,
                         "within_noise": {m: bool(abs(errors[m]) <= WITHIN_NOISE * noise[m])
                                          for m in METRICS}}
    medium = case.medium
    return {"case": case.label, "kind": case.kind, "albedo": case.albedo,
            "medium": medium.name, "channel": "RGB"[case.channel], "eta": float(medium.eta),
            "g": float(medium.g), "sigma_a": case.sigma_a,
            "sigma_s_prime": case.sigma_s_prime, "mean_free_path": mean_free_path,
            "mc": {"total": mc["total"], "total_se": mc["total_se"], "lost": mc["lost"],
                   "radius_90": regions["radius_90"], "radius_99": regions["radius_99"],
                   "rings_hold_99": regions["resolved"], "noise": noise,
                   "seconds": mc["seconds"], "photons": mc["photons"], "cached": cached},
            "profiles": results}


# ---------------------------------------------------------------------- Burley 2015


def burley_comparison(albedos=BURLEY_ALBEDOS, photons: int = BURLEY_PHOTONS, *,
                      progress: bool = False) -> dict:
    r"""Return the searchlight fit against the walk as Christensen and Burley 2015 set it up.

    eta = 1, g = 0, mean free path 1 (optical units), the surface albedo A the walk's own
    total reflectance (their fit scales a profile of the Monte Carlo's total); each albedo
    walked with ``photons`` (cached, shared with a grid row of the same settings).

    Parameters
    ----------
    albedos : sequence of float
        Single-scattering albedos in (0, 1); default :data:`BURLEY_ALBEDOS`.
    photons : int
        Photons per albedo.
    progress : bool
        Show a progress bar over the albedos.

    Returns
    -------
    dict
        ``published`` (:data:`BURLEY_PUBLISHED`), ``measured`` (the mean over albedos of
        the energy-weighted relative L1 inside the 99 % radius), ``pointwise`` (the mean
        over albedos and rings inside it of :math:`|E^{fit}_k / E^{MC}_k - 1|`, rings
        equally spaced in ln r), ``noise`` (the mean L1 an exact profile would get),
        ``albedos``, ``photons``, ``walks_cached``, ``per_albedo``.
    """
    per_albedo, cached_walks = [], 0
    bar = steps_bar("Burley's set-up", len(albedos), unit="walk", enabled=progress)
    try:
        for case in grid_cases(albedos, (1.0,), (0.0,)):
            bar.set_postfix_str(case.label)
            mc, cached = walk_rings(case, photons)
            cached_walks += cached
            fit = profile("burley_searchlight", case.medium, surface_albedo=mc["total"])
            regions = _regions(mc, 1.0 / case.sigma_t_prime)
            energy = ring_energy(fit, mc["edges_mm"], case.channel)
            rings = regions["l1"]
            walked = regions["energy"][rings]
            lit = walked > 0
            per_albedo.append({
                "albedo": case.albedo, "A": mc["total"], "A_se": mc["total_se"],
                "l1": _errors(energy, mc["total"], mc, regions)["l1"],
                "pointwise": float(np.mean(np.abs(energy[rings][lit] / walked[lit] - 1.0))),
                "noise": _mc_noise(mc, regions)["l1"], "radius_99": regions["radius_99"]})
            bar.update()
    finally:
        bar.close()

    def mean(key):
        return float(np.mean([e[key] for e in per_albedo])) if per_albedo else math.nan

    return {"published": BURLEY_PUBLISHED, "measured": mean("l1"),
            "pointwise": mean("pointwise"), "noise": mean("noise"),
            "albedos": [float(a) for a in albedos], "photons": int(photons),
            "walks_cached": int(cached_walks), "per_albedo": per_albedo,
            "explain_above": BURLEY_EXPLAIN,
            "set_up": "searchlight (pencil beam at normal incidence), eta = 1, g = 0, "
                      "sigma_t = 1 mm^-1, A = the walk's total reflectance"}


# ---------------------------------------------------------------------- summary


def _regions_of(rows, gs) -> dict:
    """Return region label -> rows: grid rows by albedo band and g, then the media."""
    bands = (("albedo < 0.5", 0.0, 0.5), ("0.5 <= albedo < 0.95", 0.5, 0.95),
             ("albedo >= 0.95", 0.95, 2.0))
    found = {}
    for g in gs:
        for label, low, high in bands:
            chosen = [row for row in rows if row["kind"] == "grid" and row["g"] == g
                      and low <= row["albedo"] < high]
            if chosen:
                found[f"g = {g:g}, {label}"] = chosen
    media = [row for row in rows if row["kind"] == "medium"]
    if media:
        found["measured media"] = media
    return found


def _tied(ranked) -> list[str]:
    """Return the names that share the smallest value of ``ranked`` ((value, name), sorted).

    Profiles that share a total (the Burley variants and the walk's table all take A from
    the walk table) tie; the tie is reported, not broken by the alphabet.
    """
    if not ranked:
        return []
    first = ranked[0][0]
    return [n for v, n in ranked if v <= first * (1.0 + TIE) + 1e-300]


def summarise(rows, gs) -> dict:
    """Return per region: each profile's mean |error| per measure, and the best profiles.

    Returns
    -------
    dict
        region -> ``rows`` (count), ``profiles`` (name -> measure -> mean |error|, over
        the rows where it was made; ``refused`` rows counted), ``best`` and
        ``best_model`` (measure -> the names that share the smallest mean, a tie listed
        whole; the latter leaves out the walk's own table).
    """
    summary = {}
    for region, chosen in _regions_of(rows, gs).items():
        means = {}
        for name in PROFILE_NAMES:
            made = [row["profiles"][name] for row in chosen
                    if row["profiles"][name]["status"] == "ok"]
            means[name] = {m: float(np.nanmean([abs(e["errors"][m]) for e in made]))
                           if made else math.nan for m in METRICS}
            means[name]["refused"] = len(chosen) - len(made)
        best, best_model = {}, {}
        for m in METRICS:
            ranked = sorted((v[m], n) for n, v in means.items()
                            if math.isfinite(v[m]) and v["refused"] == 0)
            best[m] = _tied(ranked)
            best_model[m] = _tied([(v, n) for v, n in ranked if n != TRANSPORT_TABLE])
        summary[region] = {"rows": len(chosen), "profiles": means, "best": best,
                           "best_model": best_model}
    return summary


# ---------------------------------------------------------------------- timing


def _best_of(function, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        began = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - began)
    return best


def time_profiles(radii: int = TIMING_RADII, repeats: int = TIMING_REPEATS) -> dict:
    """Time each profile's ``reflection`` and construction, beside ``np.exp``.

    The radii are uniform over [0, :data:`TIMING_RANGE_MM`) mm; the medium is
    :data:`TIMING_MEDIUM`. The baseline is ``np.exp`` over ``3 * radii`` float64, timed
    before and after the profiles (the faster kept); each figure is the best of
    ``repeats``. Construction is timed cold: pbrt's table cache is emptied first.

    Returns
    -------
    dict
        ``radii``, ``repeats``, ``medium``, ``baseline_seconds``, ``target_seconds``
        (:data:`EVALUATION_TARGET_SECONDS` scaled to ``radii``),
        ``walk_table_read_seconds`` (reading the shipped walk table, kept for the process)
        and ``profiles`` (name -> ``evaluate_seconds``, ``evaluate_ratio``,
        ``build_seconds``, ``build_ratio``, ``table`` (whether it builds one),
        ``meets_target``).
    """
    from ...materials.profiles.photon_beam_diffusion import beam_diffusion_table
    from ...materials.profiles.random_walk import TABLE_PATH

    r = np.random.default_rng(1).uniform(0.0, TIMING_RANGE_MM, int(radii))
    numbers = -np.repeat(r[None, :], 3, axis=0)
    baseline = _best_of(lambda: np.exp(numbers), repeats)

    def read_table():
        with np.load(TABLE_PATH) as data:
            return [data[key] for key in data.files]

    table_read = _best_of(read_table, 1)
    medium = measured_medium(TIMING_MEDIUM)
    target = EVALUATION_TARGET_SECONDS * int(radii) / TIMING_RADII  # fewer radii, less time
    timed = {}
    for name in PROFILE_NAMES:
        beam_diffusion_table.cache_clear()
        began = time.perf_counter()
        made = profile(name, medium, radial=True)
        build = time.perf_counter() - began
        made.reflection(r[:1000])
        seconds = _best_of(lambda made=made: made.reflection(r), repeats)
        timed[name] = {"evaluate_seconds": seconds, "build_seconds": build,
                       "table": hasattr(made, "lookup") or hasattr(made, "table"),
                       "meets_target": seconds <= target}
    baseline = min(baseline, _best_of(lambda: np.exp(numbers), repeats))
    for entry in timed.values():
        entry["evaluate_ratio"] = entry["evaluate_seconds"] / baseline
        entry["build_ratio"] = entry["build_seconds"] / baseline
    return {"radii": int(radii), "channels": 3, "repeats": int(repeats),
            "medium": TIMING_MEDIUM, "baseline": f"np.exp over {3 * int(radii)} float64",
            "baseline_seconds": baseline, "target_seconds": target,
            "walk_table_read_seconds": table_read, "profiles": timed}


# ---------------------------------------------------------------------- the table


NORMALISATION = (
    "Normalisation: per unit power entering the medium on both sides. The walk starts each "
    "photon inside, at normal incidence, with unit weight (no entry Fresnel term) and "
    "scores exits through the exact Fresnel boundary; every profile is made per unit power "
    "entering (the dipole without its entry transmittance). The walk scatters with sigma_s "
    "and the Henyey-Greenstein phase function of g; the profiles take sigma_s' = (1 - g) "
    "sigma_s (the similarity relation). The directional dipole is its radial average at "
    "normal incidence.")
NOISE_RULE = (
    f"Noise: each walk row's noise comes from {BATCHES} independent batches; for the total "
    "it is the relative standard error (the weight lost at the kill radius added in "
    "quadrature), for an L1 measure the L1 an exact profile would get from the walk's noise "
    f"alone. An error at most {WITHIN_NOISE:g} times its noise is within noise (marked *): "
    "the walk does not resolve it. Near: rings inside one reduced mean free path "
    "1/sigma_t'; tail: rings between the radii holding 90 % and 99 % of the walk's energy.")


def _measure_all(cases, settings: Settings, progress: bool):
    """Walk (or read) every case and measure its row; return rows and (case, rings, made)."""
    rows, kept, made_for = [], [], {}
    bar = steps_bar("profiles against the walk", len(cases), unit="walk", enabled=progress)
    try:
        for case in cases:
            bar.set_postfix_str(case.label)
            mc, cached = walk_rings(case, settings.photons)
            key = case.medium.name if case.kind == "medium" else case.label
            if key not in made_for:
                made_for = {key: _profiles_of(case.medium)}  # one medium at a time
            rows.append(measure_row(case, mc, made_for[key], cached))
            kept.append((case, mc, made_for[key]))
            bar.update()
    finally:
        bar.close()
    return rows, kept


def _panel(case: Case, mc: dict, made: dict) -> dict:
    """Return what :func:`plot_medium` draws of one channel."""
    edges = mc["edges_mm"]
    inner = np.maximum(edges[:-1], edges[1] / 4.0)
    regions = _regions(mc, 1.0 / case.sigma_t_prime)
    return {"channel": "RGB"[case.channel], "centre": np.sqrt(inner * edges[1:]),
            "log_width": np.log(edges[1:] / inner), "walk": regions["energy"],
            "walk_se": mc["reflectance_se"] * np.pi * (edges[1:] ** 2 - edges[:-1] ** 2),
            "rings": regions["l1"], "radius_99": regions["radius_99"],
            "profiles": {name: ring_energy(candidate, edges, case.channel)
                         for name, candidate in made.items() if not isinstance(candidate, str)}}


def _plots(kept, media, folder: Path) -> list[str]:
    chosen = [name for name in PLOT_MEDIA if name in media] or list(media[:1])
    written = []
    for name in chosen:
        panels = [_panel(*entry) for entry in kept if entry[0].kind == "medium"
                  and entry[0].medium.name == name]
        path = plot_medium(folder / f"profiles_{name.lower()}.png", name, panels)
        written.append(f"{folder.name}/{path.name}")
    return written


def profiles_table(out, settings: Settings | None = None, *, json_path=None,
                   progress: bool = True, pngs: bool = True, command: str = "") -> dict:
    """Measure every profile against the walk; write JSON, Markdown and plots into ``out``.

    Parameters
    ----------
    out : str or PathLike
        Folder for ``profiles.json``, ``profiles.md`` and ``images/``.
    settings : Settings, optional
        From :func:`check_settings`; default the full grid and the 12 media.
    json_path : str or PathLike, optional
        Where the JSON goes; default ``out/profiles.json``.
    progress : bool
        Show a progress bar over the walks.
    pngs : bool
        Plot the media of :data:`PLOT_MEDIA` in the run (or its first medium).
    command : str
        The command line, recorded in the JSON.

    Returns
    -------
    dict
        ``settings``, ``rows`` (one :func:`measure_row` a walk row), ``burley``
        (:func:`burley_comparison`), ``summary`` (:func:`summarise`), ``timing``
        (:func:`time_profiles`), ``plots``, ``walks_cached``, ``seconds``.
    """
    settings = check_settings() if settings is None else settings
    out = check_output_folder(out, "--out")
    json_path = out / JSON_NAME if json_path is None else Path(json_path)
    started = time.perf_counter()
    cases = grid_cases(settings.albedos, settings.etas, settings.gs) + media_cases(
        settings.media)
    rows, kept = _measure_all(cases, settings, progress)
    result = {"benchmark": "profiles", "format": FORMAT, "command": command,
              "settings": {"albedos": list(settings.albedos), "etas": list(settings.etas),
                           "gs": list(settings.gs), "media": list(settings.media),
                           "photons": settings.photons, "batches": BATCHES,
                           "burley_albedos": list(settings.burley_albedos),
                           "burley_photons": settings.burley_photons,
                           "rings_per_decade": RINGS_PER_DECADE,
                           "within_noise": WITHIN_NOISE, "fraction": FRACTION,
                           "tail_from": TAIL_FROM},
              "profiles": list(PROFILE_NAMES), "metrics": list(METRICS),
              "normalisation": NORMALISATION, "noise_rule": NOISE_RULE,
              "rows": rows, "walks_cached": sum(row["mc"]["cached"] for row in rows),
              "burley": burley_comparison(settings.burley_albedos, settings.burley_photons,
                                          progress=progress),
              "summary": summarise(rows, settings.gs),
              "timing": time_profiles(settings.timing_radii, settings.timing_repeats),
              "plots": _plots(kept, settings.media, out / "images") if pngs else []}
    result["seconds"] = time.perf_counter() - started
    write_figures(json_path, "profiles", result)
    atomic_write_text(out / MARKDOWN_NAME, markdown(result))
    return result


# ---------------------------------------------------------------------- the command


def command_line(settings: Settings, *, quick: bool = False) -> str:
    """Return the command that measures ``settings`` again (output paths left out)."""
    def join(values):
        return ",".join(f"{v:g}" for v in values)

    return (f"translucent bench profiles{' --quick' if quick else ''} --albedos "
            f"{join(settings.albedos)} --etas {join(settings.etas)} --gs {join(settings.gs)} "
            f"--media {','.join(settings.media) or 'none'} --photons {settings.photons} "
            f"--burley-photons {settings.burley_photons}")


#: ``--quick``: a tiny table (two albedos, eta 1, g 0, Ketchup, 4,000 photons, 1e5 radii timed):
#: :data:`QUICK`, read by :func:`run`, since the Burley albedos are no option of their own.
QUICK_ARGUMENTS: dict = {}


def add_arguments(parser):
    """Options of ``translucent bench profiles``."""
    parser.add_argument("--out", default="bench_profiles",
                        help="folder for profiles.json, profiles.md and images/ "
                             "(default ./bench_profiles)")
    parser.add_argument("--albedos", default=None,
                        help="comma-separated single-scattering albedos in (0, 1] "
                             f"(default {','.join(f'{a:g}' for a in DEFAULT_ALBEDOS)})")
    parser.add_argument("--etas", default=None,
                        help="comma-separated relative indices in [1, 2] "
                             f"(default {','.join(f'{e:g}' for e in DEFAULT_ETAS)})")
    parser.add_argument("--gs", default=None,
                        help="comma-separated Henyey-Greenstein g in [-0.95, 0.95] "
                             f"(default {','.join(f'{g:g}' for g in DEFAULT_GS)})")
    parser.add_argument("--media", default=None,
                        help="comma-separated measured media, or 'none' (default: all 12 "
                             "of Jensen et al. 2001)")
    parser.add_argument("--photons", type=int, default=None,
                        help=f"photons per walk row (default {DEFAULT_PHOTONS:,})")
    parser.add_argument("--burley-photons", type=int, default=None,
                        help="photons per albedo of the Christensen-Burley comparison "
                             f"(default {BURLEY_PHOTONS:,})")
    parser.add_argument("--no-images", action="store_true", help="write no plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args) -> int:
    """Check the options, measure the table, print its summary, write it into ``--out``."""
    base = dict(QUICK) if args.quick else {}
    timing = {"timing_radii": 100_000, "timing_repeats": 2} if args.quick else {}
    chosen = {key: getattr(args, key) for key in ("albedos", "etas", "gs", "media", "photons",
                                                  "burley_photons")
              if getattr(args, key) is not None}
    settings = check_settings(**{**base, **chosen, **timing})
    out = Path(args.out)
    result = profiles_table(out, settings, json_path=args.json,
                            progress=not args.no_progress, pngs=not args.no_images,
                            command=command_line(settings, quick=args.quick))
    print(markdown(result, rows=False), end="")
    print(f"wrote {Path(args.json) if args.json else out / JSON_NAME} and "
          f"{out / MARKDOWN_NAME} in {result['seconds']:.1f} s")
    return 0
