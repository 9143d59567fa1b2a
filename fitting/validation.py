"""Validation studies of the fitter: coverage on exact-model captures, and the dipole's bias.

* :func:`coverage_study` fits dipole-forward captures of random true parameters and counts
  how often the truth lies inside the 95 % credible interval. A calibrated posterior puts
  it there 95 % of the time; the suite asks for at least :data:`COVERAGE_TARGET`.
* :func:`model_bias_table` fits captures of the measured media of Jensen et al. 2001 made
  by a transport solver (the photon random walk, ``generator="walk"``, or Mitsuba 3
  volumetric path tracing, ``generator="volpath"``) with the dipole and tabulates
  recovered against true coefficients: the dipole's own bias, since both generators solve
  the transport the dipole approximates.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import InputError
from ..materials import Dipole, measured_medium, measured_medium_names
from .capture import Capture
from .fit import fit_dipole
from .models import SIGMA_A_RANGE, SIGMA_S_PRIME_RANGE
from .profile import measure_profile
from .synthetic import Camera, default_pixel_size, dipole_capture

__all__ = ["BIAS_GENERATORS", "COVERAGE_TARGET", "BiasRow", "CoverageResult", "coverage_study",
           "model_bias_table", "bias_table_text"]

#: Fraction of parameters whose truth must lie inside its 95 % interval.
COVERAGE_TARGET = 0.90
#: Ranges the random true coefficients are drawn from (log-uniform), mm^-1: the span of
#: the measured media without the extremes (Spectralon, Ketchup blue).
TRUTH_SIGMA_A = (0.003, 0.5)
TRUTH_SIGMA_S_PRIME = (0.3, 5.0)
#: Transport solvers :func:`model_bias_table` can make its captures with.
BIAS_GENERATORS = ("walk", "volpath")


@dataclass
class CoverageResult:
    """Outcome of :func:`coverage_study`.

    Attributes
    ----------
    inside : ndarray of bool, shape (captures, 6)
        Truth inside the 95 % interval, per capture and parameter (sigma_a RGB, sigma_s' RGB).
    converged : ndarray of bool, shape (captures,)
    z : ndarray, shape (captures, 6)
        (ln median - ln truth) / half the 68 % width, for a look at calibration.
    seconds : float
    misfit : ndarray of bool, shape (captures,)
        Fits the goodness-of-fit tests flagged as a model misfit: false alarms, since the
        captures are made by the fitted model itself.
    fit_seconds : ndarray, shape (captures,)
        Wall time of each fit (profile, MAP, chain, goodness of fit).
    """

    inside: np.ndarray
    converged: np.ndarray
    z: np.ndarray
    seconds: float
    misfit: np.ndarray | None = None
    fit_seconds: np.ndarray | None = None

    @property
    def fraction(self) -> float:
        """Fraction of parameters whose truth lies inside its 95 % interval."""
        return float(self.inside.mean())


def coverage_study(captures: int = 20, *, seed: int = 0, size: int = 48,
                   camera: Camera | None = None, walkers: int | None = 16,
                   progress: bool = False, placement: str = "centre",
                   generator: str = "dipole", photons: int = 1_000_000) -> CoverageResult:
    """Fit ``captures`` synthetic captures with random truth; count 95 % coverage.

    Parameters
    ----------
    captures : int
    seed : int
    size : int
        Image size, pixels (the pixel size follows the material, see
        :func:`~translucent.fitting.synthetic.default_pixel_size`).
    camera : Camera, optional
        Default: ``Camera(peak_signal=40000)``, exposure unknown.
    walkers : int, optional
    progress : bool
    placement : {"centre", "off_centre", "border"}
        Where the beam enters: the image centre; a random point a quarter of the image
        from it; or a random point on the image's edge (half the profile cut off).
    generator : {"dipole", "walk"}
        The captures' maker and the fitted model together: the independent dipole
        convolution (:func:`~translucent.fitting.synthetic.dipole_capture`) fitted with
        the dipole, or the photon random walk (``photons`` per channel) fitted with the
        tabulated walk.

    Returns
    -------
    CoverageResult
    """
    if placement not in PLACEMENTS:
        raise InputError(f"must be one of {', '.join(PLACEMENTS)}", field="placement",
                         value=placement)
    if generator not in ("dipole", "walk"):
        raise InputError("must be 'dipole' or 'walk'", field="generator", value=generator)
    began = time.perf_counter()
    camera = Camera(peak_signal=40000) if camera is None else camera
    rng = np.random.default_rng(seed)
    inside = np.zeros((captures, 6), dtype=bool)
    z = np.zeros((captures, 6))
    converged = np.zeros(captures, dtype=bool)
    misfit = np.zeros(captures, dtype=bool)
    fit_seconds = np.zeros(captures)
    for index in range(captures):
        sigma_a = np.exp(rng.uniform(*np.log(TRUTH_SIGMA_A), size=3))
        sigma_s_prime = np.exp(rng.uniform(*np.log(TRUTH_SIGMA_S_PRIME), size=3))
        material = Dipole(sigma_a=sigma_a, sigma_s_prime=sigma_s_prime, eta=1.3)
        incident = _placement(placement, size, rng)
        common = {"size": size, "pixel_size_mm": default_pixel_size(material, size),
                  "camera": camera, "seed": int(rng.integers(2**31)),
                  "incident_px": incident}
        if generator == "walk":
            from .random_walk import walk_capture

            pixels, spec, _ = walk_capture(material, photons=photons, **common)
        else:
            pixels, spec = dipole_capture(material, **common)
        result = fit_dipole(Capture(spec, pixels), walkers=walkers,
                            seed=int(rng.integers(2**31)), progress=progress,
                            forward=generator)
        fit_seconds[index] = result.seconds
        converged[index] = result.converged
        misfit[index] = result.misfit
        truth = np.concatenate([sigma_a, sigma_s_prime])
        for i, summary in enumerate(result.parameters[:6]):
            inside[index, i] = summary.low95 <= truth[i] <= summary.high95
            half = 0.5 * (np.log(summary.high68) - np.log(summary.low68))
            z[index, i] = (np.log(summary.median) - np.log(truth[i])) / half
    return CoverageResult(inside, converged, z, time.perf_counter() - began, misfit,
                          fit_seconds)


#: Where :func:`coverage_study` puts the beam.
PLACEMENTS = ("centre", "off_centre", "border")


def _placement(placement, size, rng) -> tuple[float, float]:
    """Incident point (x, y), pixels, for :func:`coverage_study`."""
    if placement == "centre":
        return (size / 2.0, size / 2.0)
    if placement == "off_centre":
        angle = rng.uniform(0.0, 2.0 * np.pi)
        return (size / 2.0 + 0.25 * size * np.cos(angle),
                size / 2.0 + 0.25 * size * np.sin(angle))
    along = rng.uniform(0.25 * size, 0.75 * size)
    return [(along, 0.5), (0.5, along), (along, size - 0.5), (size - 0.5, along)][
        int(rng.integers(4))]


@dataclass
class BiasRow:
    """One measured medium: true and recovered coefficients (mm^-1), per channel."""

    material: str
    true_sigma_a: list
    fit_sigma_a: list
    fit_sigma_a_68: list
    true_sigma_s_prime: list
    fit_sigma_s_prime: list
    fit_sigma_s_prime_68: list
    status: list
    converged: bool
    tau_max: float
    r_min_mm: float
    pixel_size_mm: float
    photons: int
    seconds: float
    generator: str = "photon random walk"
    spp: int = 0
    beam_radius_mm: float = 0.0
    relative_standard_error: list | None = None
    forward: str = "dipole"
    covered: list | None = None
    misfit: bool = False
    exposure_known: bool = False

    def to_json(self) -> dict:
        """JSON-able dict."""
        return asdict(self)


def model_bias_table(materials=None, *, photons: int = 100_000, size: int = 96,
                     rotations: int = 1, seed: int = 0, walkers: int | None = None,
                     r_min_transport_lengths=(0.0,), progress: bool = False,
                     on_row=None, generator: str = "walk", spp: int = 4096,
                     pass_spp: int | None = None,
                     beam_radius_fraction: float | None = None,
                     forward: str = "dipole", exposure_known: bool = False) -> list[BiasRow]:
    """Fit transport-solver captures of measured media; recovered against true coefficients.

    Each capture: ``size`` x ``size`` pixels spanning ~12 diffusion lengths
    (:func:`~translucent.fitting.synthetic.default_pixel_size`), eta known, exposure
    unknown, the default camera; a pencil beam for the walk, a Gaussian beam of
    ``beam_radius_fraction`` of the field for volpath (which needs one; the fitter
    convolves its model with it). The solver and the dipole share the boundary (eta), the
    coefficients and g = 0; what differs is transport against diffusion.

    Parameters
    ----------
    materials : sequence of str, optional
        Catalogue names (default: all twelve).
    photons : int
        Photons per channel (walk).
    size, rotations, seed, walkers, progress
    r_min_transport_lengths : sequence of float
        Fit each capture once per entry, leaving out the annuli inside that many transport
        lengths (1 / sigma_t' of the least scattering channel): 0 fits the whole profile,
        3 only where diffusion holds.
    on_row : callable, optional
        Called with each :class:`BiasRow` as it is done (progress reports, incremental
        output).
    generator : {"walk", "volpath"}
        The photon random walk (:func:`~translucent.fitting.random_walk.walk_capture`) or
        Mitsuba volpath (:func:`~translucent.fitting.volpath_capture.volpath_capture`).
    spp : int
        Samples per pixel (volpath).
    pass_spp : int, optional
        Samples per pixel of one render pass (volpath; default
        :data:`~translucent.fitting.volpath_capture.DEFAULT_PASS_SPP`).
    beam_radius_fraction : float, optional
        Beam 1/e^2 radius as a fraction of the field width (volpath; default
        :data:`~translucent.fitting.volpath_capture.DEFAULT_BEAM_FRACTION`).
    forward : str
        The fitted profile: a coefficient model of :data:`~translucent.fitting.fit.MODELS`
        (see :func:`~translucent.fitting.fit.fit_dipole`).
    exposure_known : bool
        Write the camera's exposure into each capture's sidecar, so the fit does not sample
        it. A Christensen-Burley profile needs it: one shape per channel (its scale d)
        times an amplitude A(albedo), so with the exposure free every channel's albedo
        trades against it along a ridge of equally good fits (7 unknowns, 6 constraints).

    Returns
    -------
    list of BiasRow
    """
    if generator not in BIAS_GENERATORS:
        raise InputError(f"must be one of {', '.join(BIAS_GENERATORS)}", field="generator",
                         value=generator)
    names = measured_medium_names() if materials is None else list(materials)
    rng = np.random.default_rng(seed)
    rows = []
    for name in names:
        began = time.perf_counter()
        material = measured_medium(name)
        pixel = default_pixel_size(material, size)
        pixels, spec, extra = _solver_capture(generator, material, size=size, pixel=pixel,
                                              photons=photons, rotations=rotations, spp=spp,
                                              pass_spp=pass_spp,
                                              beam_radius_fraction=beam_radius_fraction,
                                              seed=int(rng.integers(2**31)), progress=progress,
                                              camera=Camera(exposure_known=exposure_known))
        capture = Capture(spec, pixels)
        for lengths in r_min_transport_lengths:
            r_min = float(lengths * np.max(material.mean_free_path))
            fit_seed = int(rng.integers(2**31))
            try:
                profile = measure_profile(capture, r_min_mm=r_min)
            except InputError:  # nothing left outside r_min: a row that says so
                row = _empty_row(material, r_min, pixel, photons, began, extra)
            else:
                result = fit_dipole(capture, walkers=walkers, seed=fit_seed, progress=progress,
                                    profile=profile, forward=forward)
                row = _bias_row(material, result, r_min, pixel, photons, began,
                                {**extra, "exposure_known": exposure_known})
            rows.append(row)
            if on_row is not None:
                on_row(row)
    return rows


def _solver_capture(generator, material, *, size, pixel, photons, rotations, spp, pass_spp,
                    beam_radius_fraction, seed, progress, camera):
    """Make one capture for the bias table: (pixels, spec, BiasRow fields of the solver)."""
    if generator == "walk":
        from .random_walk import walk_capture

        pixels, spec, _ = walk_capture(material, size=size, pixel_size_mm=pixel,
                                       photons=photons, rotations=rotations, seed=seed,
                                       camera=camera)
        return pixels, spec, {"photons": int(photons)}
    from .volpath_capture import DEFAULT_BEAM_FRACTION, DEFAULT_PASS_SPP, volpath_capture

    fraction = DEFAULT_BEAM_FRACTION if beam_radius_fraction is None else beam_radius_fraction
    beam = fraction * size * pixel
    pass_spp = DEFAULT_PASS_SPP if pass_spp is None else pass_spp  # 0 is refused, not replaced
    pixels, spec, render = volpath_capture(material, size=size, pixel_size_mm=pixel, spp=spp,
                                           pass_spp=pass_spp,
                                           beam_radius_mm=beam, seed=seed, progress=progress,
                                           camera=camera)
    return pixels, spec, {"photons": 0, "generator": "mitsuba volpath", "spp": render.spp,
                          "beam_radius_mm": beam,
                          "relative_standard_error": render.relative_standard_error().tolist()}


def _bias_row(material, result, r_min, pixel, photons, began, extra=None) -> BiasRow:
    """One row of the bias table from a fit."""
    get = result.parameter
    # a truth outside the prior's support (Spectralon's sigma_a = 0) counts at its bound
    truth = np.concatenate([np.clip(material.sigma_a, *SIGMA_A_RANGE),
                            np.clip(material.sigma_s_prime, *SIGMA_S_PRIME_RANGE)])
    covered = [bool(s.low95 <= t <= s.high95) for s, t in
               zip(result.parameters[:6], truth, strict=True)]
    return BiasRow(
        material=material.name, true_sigma_a=material.sigma_a.tolist(),
        fit_sigma_a=[get(f"sigma_a[{c}]").median for c in "RGB"],
        fit_sigma_a_68=[[get(f"sigma_a[{c}]").low68, get(f"sigma_a[{c}]").high68]
                        for c in "RGB"],
        true_sigma_s_prime=material.sigma_s_prime.tolist(),
        fit_sigma_s_prime=[get(f"sigma_s_prime[{c}]").median for c in "RGB"],
        fit_sigma_s_prime_68=[[get(f"sigma_s_prime[{c}]").low68,
                               get(f"sigma_s_prime[{c}]").high68] for c in "RGB"],
        status=[s.status for s in result.parameters[:6]], converged=result.converged,
        tau_max=float(result.chains[0].tau.max()), r_min_mm=r_min, pixel_size_mm=pixel,
        **{"photons": int(photons), **(extra or {})}, seconds=time.perf_counter() - began,
        forward=result.kind, covered=covered, misfit=bool(result.misfit))


def _empty_row(material, r_min, pixel, photons, began, extra=None) -> BiasRow:
    """Return a row for a capture with no usable annulus outside ``r_min``."""
    nan3 = [float("nan")] * 3
    return BiasRow(material=material.name, true_sigma_a=material.sigma_a.tolist(),
                   fit_sigma_a=nan3, fit_sigma_a_68=[nan3[:2]] * 3,
                   true_sigma_s_prime=material.sigma_s_prime.tolist(), fit_sigma_s_prime=nan3,
                   fit_sigma_s_prime_68=[nan3[:2]] * 3, status=["no usable annuli"] * 6,
                   converged=False, tau_max=float("nan"), r_min_mm=r_min, pixel_size_mm=pixel,
                   **{"photons": int(photons), **(extra or {})},
                   seconds=time.perf_counter() - began)


def _ratios(fit, true, status) -> str:
    """``fit / true`` per channel; * marks a parameter the data did not fully constrain."""
    parts = []
    for value, truth, verdict in zip(fit, true, status, strict=True):
        text = f"{value / truth:.2f}" if truth > 0 else f"{value:.1e} (true 0)"
        parts.append(text + ("" if verdict == "constrained" else "*"))
    return " ".join(parts)


def bias_table_text(rows) -> str:
    """Format the bias table as Markdown: recovered / true per coefficient and channel."""
    lines = ["| material | r_min (mm) | sigma_a fit/true R G B | sigma_s' fit/true R G B | "
             "truth in 95 % | verdict | converged |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        sigma_a = _ratios(row.fit_sigma_a, row.true_sigma_a, row.status[:3])
        sigma_s = _ratios(row.fit_sigma_s_prime, row.true_sigma_s_prime, row.status[3:])
        covered = "-" if row.covered is None else f"{sum(row.covered)} / 6"
        lines.append(f"| {row.material} | {row.r_min_mm:.2g} | {sigma_a} | {sigma_s} | "
                     f"{covered} | {'misfit' if row.misfit else 'fits'} | "
                     f"{'yes' if row.converged else 'no'} |")
    return "\n".join(lines)
