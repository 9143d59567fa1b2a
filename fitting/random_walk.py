r"""Synthetic captures traced from the light: a vectorised photon random walk in a slab.

A path-traced camera sees a narrow beam's halo only through the few camera paths that
reach the beam (docs/references.md), so slab captures are traced from the light instead, as MCML
does in biomedical optics (Wang, Jacques & Zheng 1995):

* photons enter at normal incidence, at a point drawn from the Gaussian beam, with unit
  weight (the profile is per unit power *entering* the slab: the specular reflection at
  the entry, :math:`((\eta - 1)/(\eta + 1))^2`, is not part of it);
* free paths are exponential with :math:`\sigma_t = \sigma_a + \sigma_s`,
  :math:`\sigma_s = \sigma'_s / (1 - g)`; at each interaction the weight is multiplied by
  the single-scattering albedo (implicit absorption) and the direction drawn from the
  Henyey-Greenstein phase function;
* at a boundary the photon meets the exact unpolarised Fresnel reflectance of the smooth
  interface (index ``eta`` inside, 1 outside; total internal reflection included): the
  transmitted part :math:`w(1 - F_r)` is scored where it leaves, the rest is reflected
  specularly and walks on (the exponential free path is memoryless, so a fresh one is
  drawn);
* weights below :data:`ROULETTE_WEIGHT` play Russian roulette (survive with probability
  1 / :data:`ROULETTE_BOOST`, weight multiplied by it): unbiased;
* photons that wander further than ``r_kill_mm`` from the beam axis (or deeper than it in
  a semi-infinite slab) are dropped; the weight they carry is reported as ``lost``.

Scoring. The radial tally bins each exit by its distance from the photon's own entry
point: the pencil-beam profile :math:`R(r)` or :math:`T(r)` (mm^-2 per entering photon),
with standard errors from independent batches. The film bins each exit onto the pixels of
a capture (the beam-convolved exitance). Because the slab is invariant under rotation
about the vertical through the entry point, each exit is scored at ``rotations``
rotations about its entry point (equally spaced, from a random offset) with
``1/rotations`` of the weight: an unbiased variance reduction for the film.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..materials import Dipole
from ..materials.fresnel import fresnel_reflectance
from .synthetic import Camera, apply_camera, capture_spec, check_geometry, check_incident
from .walk_scoring import score_exits

__all__ = ["Film", "WalkTally", "photon_random_walk", "walk_capture"]

#: Russian roulette threshold and boost (MCML's defaults).
ROULETTE_WEIGHT = 1e-4
ROULETTE_BOOST = 10.0
#: Direction cosines closer to +-1 than this use the special-case rotation (MCML).
VERTICAL_COSINE = 0.99999
#: Default kill radius in transport lengths 1 / sigma_t' (when no film or tally sets one).
KILL_TRANSPORT_LENGTHS = 200.0


@dataclass(frozen=True)
class Film:
    """Where exits are binned into pixels.

    Parameters
    ----------
    shape : (int, int)
        ``(H, W)``.
    pixel_size_mm : float
    centre_px : (float, float)
        Beam axis ``(x, y)`` in pixels (top-left corner of the image at 0, 0).
    side : str
        ``"reflection"`` (exits through the lit surface) or ``"transmission"``.
    """

    shape: tuple[int, int]
    pixel_size_mm: float
    centre_px: tuple[float, float]
    side: str = "reflection"


@dataclass
class WalkTally:
    """What a random walk scored, per entering photon.

    Attributes
    ----------
    radial_edges_mm : ndarray, shape (n + 1,)
    reflectance, transmittance : ndarray, shape (n, 3)
        Pencil-beam exitance profiles, mm^-2, per bin (mean over the bin's area).
    reflectance_se, transmittance_se : ndarray, shape (n, 3)
        Their standard errors (from independent batches).
    total_reflectance, total_transmittance, lost : ndarray, shape (3,)
        Fractions of the entering power leaving each side, and carried beyond the kill
        radius.
    total_reflectance_se, total_transmittance_se : ndarray, shape (3,)
    film : ndarray, shape (H, W, 3) or None
        Exitance per pixel, mm^-2.
    photons : int
        Per channel.
    seconds : float
    """

    radial_edges_mm: np.ndarray
    reflectance: np.ndarray
    reflectance_se: np.ndarray
    transmittance: np.ndarray
    transmittance_se: np.ndarray
    total_reflectance: np.ndarray
    total_reflectance_se: np.ndarray
    total_transmittance: np.ndarray
    total_transmittance_se: np.ndarray
    lost: np.ndarray
    film: np.ndarray | None
    photons: int
    seconds: float

    @property
    def radius_mm(self) -> np.ndarray:
        """Area-weighted mean radius of each bin, mm."""
        inner, outer = self.radial_edges_mm[:-1], self.radial_edges_mm[1:]
        return 2.0 / 3.0 * (outer ** 3 - inner ** 3) / (outer ** 2 - inner ** 2)


def _scatter(rng, ux, uy, uz, g):
    """Draw new directions by Henyey-Greenstein scattering (MCML's rotation formulas)."""
    n = ux.size
    xi, eta_phi = rng.random((2, n))
    if g == 0.0:
        cos_t = 2.0 * xi - 1.0
    else:
        ratio = (1.0 - g * g) / (1.0 - g + 2.0 * g * xi)
        cos_t = np.clip((1.0 + g * g - ratio * ratio) / (2.0 * g), -1.0, 1.0)
    sin_t = np.sqrt(1.0 - cos_t * cos_t)
    phi = 2.0 * np.pi * eta_phi
    cos_p = np.cos(phi)
    sin_p = np.where(eta_phi < 0.5, 1.0, -1.0) * np.sqrt(1.0 - cos_p * cos_p)
    temp = np.sqrt(np.maximum(1.0 - uz * uz, 1e-300))
    a = sin_t / temp
    new_x = a * (ux * uz * cos_p - uy * sin_p) + ux * cos_t
    new_y = a * (uy * uz * cos_p + ux * sin_p) + uy * cos_t
    new_z = uz * cos_t - sin_t * cos_p * temp
    vertical = np.abs(uz) > VERTICAL_COSINE
    if vertical.any():  # the general formula divides by sin(theta_z) ~ 0 here
        new_x[vertical] = sin_t[vertical] * cos_p[vertical]
        new_y[vertical] = sin_t[vertical] * sin_p[vertical]
        new_z[vertical] = np.sign(uz[vertical]) * cos_t[vertical]
    return new_x, new_y, new_z


def _walk_channel(rng, photons, sigma_a, sigma_s, g, eta, thickness, beam_radius, r_kill,
                  edges, batches, film, rotations):
    """Trace one channel: (radial sums per side and batch, totals, lost, film sums).

    All photons walk together (photon i belongs to batch i mod ``batches``): the cost of a
    step is mostly numpy's per-call overhead once few photons are left, so one long array
    is far cheaper than several short ones.
    """
    sigma_t = sigma_a + sigma_s
    albedo = sigma_s / sigma_t if sigma_t > 0 else 0.0
    n_bins = edges.size - 1
    radial = np.zeros((2, batches, n_bins))
    totals = np.zeros((2, batches))
    lost = 0.0
    film_sum = None if film is None else np.zeros(film.shape[0] * film.shape[1])
    sigma_beam = 0.5 * beam_radius
    x0 = rng.normal(0.0, sigma_beam, photons) if sigma_beam > 0 else np.zeros(photons)
    y0 = rng.normal(0.0, sigma_beam, photons) if sigma_beam > 0 else np.zeros(photons)
    x, y, z = x0.copy(), y0.copy(), np.zeros(photons)
    ux, uy, uz = np.zeros(photons), np.zeros(photons), np.ones(photons)
    w = np.ones(photons)
    batch = np.arange(photons) % batches
    depth = np.inf if thickness is None else thickness

    def score(side, mask, weight):
        score_exits(rng, side, x[mask] - x0[mask], y[mask] - y0[mask], x0[mask], y0[mask],
                    weight, batch[mask], edges, film, rotations, radial, totals, film_sum)

    if sigma_t <= 0:  # nothing scatters: every photon crosses (or leaves) untouched
        return radial, totals, lost, film_sum
    while w.size:
        step = -np.log(rng.random(w.size)) / sigma_t
        with np.errstate(divide="ignore", invalid="ignore"):
            to_boundary = np.where(uz > 0, (depth - z) / uz, np.where(uz < 0, -z / uz, np.inf))
        hits = step >= to_boundary
        travel = np.minimum(step, to_boundary)
        x += travel * ux
        y += travel * uy
        z += travel * uz
        new_x, new_y, new_z = _scatter(rng, ux, uy, uz, g)
        if hits.any():
            index = np.flatnonzero(hits)
            top = uz[index] < 0
            z[index] = np.where(top, 0.0, depth)
            reflect = fresnel_reflectance(1.0 / eta, np.abs(uz[index]))
            leaving = w[index] * (1.0 - reflect)
            for side, chosen in ((0, top), (1, ~top)):
                if chosen.any():
                    mask = np.zeros(w.size, dtype=bool)
                    mask[index[chosen]] = True
                    score(side, mask, leaving[chosen])
            # a reflected photon keeps its direction mirrored and does not scatter
            new_x[index], new_y[index], new_z[index] = ux[index], uy[index], -uz[index]
            w *= albedo
            w[index] *= reflect / albedo if albedo > 0 else 0.0
        else:
            w *= albedo
        ux, uy, uz = new_x, new_y, new_z
        # Russian roulette on light photons, unbiased
        light = w < ROULETTE_WEIGHT
        if light.any():
            survive = rng.random(int(light.sum())) < 1.0 / ROULETTE_BOOST
            w[light] = np.where(survive, w[light] * ROULETTE_BOOST, 0.0)
        far = (np.abs(x) > r_kill) | (np.abs(y) > r_kill) | (z > r_kill)
        if far.any():
            lost += float(w[far].sum())
            w[far] = 0.0
        keep = w > 0
        if not keep.all():
            x, y, z, ux, uy, uz, w = (a[keep] for a in (x, y, z, ux, uy, uz, w))
            x0, y0, batch = x0[keep], y0[keep], batch[keep]
    return radial, totals, lost, film_sum


def photon_random_walk(material: Dipole, *, photons: int = 100_000,
                       thickness_mm: float | None = None, beam_radius_mm: float = 0.0,
                       radial_edges_mm=None, film: Film | None = None, rotations: int = 8,
                       batches: int = 10, r_kill_mm: float | None = None,
                       seed: int | None = None, channels=(0, 1, 2),
                       progress: bool = False, backend: str = "auto") -> WalkTally:
    """Trace ``photons`` per channel through a slab of ``material`` (see the module docstring).

    Parameters
    ----------
    material : Dipole
        sigma_a, sigma_s' (mm^-1), g and eta; sigma_s = sigma_s' / (1 - g).
    photons : int
        Photons per channel.
    thickness_mm : float or None
        Slab thickness (None: semi-infinite).
    beam_radius_mm : float
        1/e^2 radius of the Gaussian beam (0: pencil).
    radial_edges_mm : array_like, optional
        Bin edges of the radial tally (default: 100 bins to 20 transport lengths).
    film : Film, optional
        Also bin exits onto these pixels.
    rotations : int
        Random rotations per exit on the film (>= 1).
    batches : int
        Independent batches for the standard errors (>= 2).
    r_kill_mm : float, optional
        Kill radius (default: the film's farthest corner + 20 transport lengths, or
        :data:`KILL_TRANSPORT_LENGTHS` transport lengths).
    seed : int, optional
    channels : sequence of int
        Channels to trace (the others are left at zero).
    progress : bool
        Show a progress bar over channels (on stderr).
    backend : {"auto", "drjit", "numpy"}
        ``"drjit"``: the compiled kernel of :mod:`translucent.fitting.walk_kernel`
        (tens of times faster for high-albedo media); ``"numpy"``: the reference
        implementation in this module; ``"auto"``: Dr.Jit when its LLVM backend works.

    Returns
    -------
    WalkTally
    """
    began = time.perf_counter()
    if not np.isfinite(photons):
        raise InputError("must be a finite number of photons per channel", field="photons",
                         value=photons)
    photons = int(photons)
    if photons < batches or batches < 2:
        raise InputError(f"need photons >= batches >= 2 (batches = {batches})", field="photons",
                         value=photons)
    from ..resources import WALK_BYTES_PER_PHOTON, check_memory

    check_memory(photons * WALK_BYTES_PER_PHOTON, what=f"a walk of {photons:,} photons at once",
                 field="photons", value=photons)
    if thickness_mm is not None and not (np.isfinite(thickness_mm) and thickness_mm > 0):
        raise InputError("must be > 0 or None", field="thickness_mm", value=thickness_mm)
    if int(rotations) < 1:
        raise InputError("must be >= 1", field="rotations", value=rotations)
    sigma_t_prime = float(np.max(material.sigma_a + material.sigma_s_prime))
    transport = 1.0 / max(float(np.min(material.sigma_a + material.sigma_s_prime)), 1e-12)
    if radial_edges_mm is None:
        radial_edges_mm = np.linspace(0.0, 20.0 * transport, 101)
    edges = np.asarray(radial_edges_mm, dtype=np.float64)
    if r_kill_mm is None:
        reach = edges[-1]
        if film is not None:
            height, width = film.shape
            cx, cy = film.centre_px
            reach = max(reach, np.hypot(max(cx, width - cx), max(cy, height - cy))
                        * film.pixel_size_mm)
        r_kill_mm = max(reach + 20.0 * transport, KILL_TRANSPORT_LENGTHS / sigma_t_prime)
    rng = np.random.default_rng(seed)
    n_bins = edges.size - 1
    area = np.pi * (edges[1:] ** 2 - edges[:-1] ** 2)
    profiles = np.zeros((2, n_bins, 3))
    profiles_se = np.zeros((2, n_bins, 3))
    totals = np.zeros((2, 3))
    totals_se = np.zeros((2, 3))
    lost = np.zeros(3)
    film_image = None if film is None else np.zeros(film.shape + (3,))
    if backend not in ("auto", "drjit", "numpy"):
        raise InputError("must be 'auto', 'drjit' or 'numpy'", field="backend", value=backend)
    if backend == "auto":
        from .walk_kernel import drjit_available

        backend = "drjit" if drjit_available() else "numpy"
    # photon i is in batch i mod batches: the first photons % batches batches have one more
    sizes = np.full(batches, photons // batches, dtype=np.float64)
    sizes[:photons % batches] += 1
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(channels), desc="photon random walk", unit="channel", leave=False)
    try:
        for c in channels:
            arguments = (photons, float(material.sigma_a[c]), float(material.sigma_s[c]),
                         float(material.g), float(material.eta), thickness_mm,
                         float(beam_radius_mm), float(r_kill_mm), edges, batches, film,
                         int(rotations))
            if backend == "drjit":
                from .walk_kernel import walk_channel_drjit

                radial, total, lost_c, film_sum = walk_channel_drjit(rng, *arguments)
            else:
                radial, total, lost_c, film_sum = _walk_channel(rng, *arguments)
            batch_profiles = radial / (sizes[None, :, None] * area)  # (side, batch, bin)
            profiles[:, :, c] = batch_profiles.mean(axis=1)
            profiles_se[:, :, c] = batch_profiles.std(axis=1, ddof=1) / np.sqrt(batches)
            batch_totals = total / sizes[None, :]
            totals[:, c] = batch_totals.mean(axis=1)
            totals_se[:, c] = batch_totals.std(axis=1, ddof=1) / np.sqrt(batches)
            lost[c] = lost_c / photons
            if film is not None:
                film_image[..., c] = film_sum.reshape(film.shape) / (
                    photons * film.pixel_size_mm ** 2)
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    return WalkTally(radial_edges_mm=edges, reflectance=profiles[0],
                     reflectance_se=profiles_se[0], transmittance=profiles[1],
                     transmittance_se=profiles_se[1], total_reflectance=totals[0],
                     total_reflectance_se=totals_se[0], total_transmittance=totals[1],
                     total_transmittance_se=totals_se[1], lost=lost, film=film_image,
                     photons=photons, seconds=time.perf_counter() - began)


def walk_capture(material: Dipole, *, size: int | tuple[int, int] = 96,
                 pixel_size_mm: float = 0.1, incident_px=None, side: str = "reflection",
                 thickness_mm: float | None = None, beam_radius_mm: float = 0.0,
                 photons: int = 200_000, rotations: int = 1, camera: Camera | None = None,
                 seed: int | None = None, image_name: str = "capture.exr",
                 eta_known: bool = True, progress: bool = False):
    """Make a synthetic capture traced by :func:`photon_random_walk`, with camera defects.

    Parameters are those of :func:`~translucent.fitting.synthetic.dipole_capture`, plus
    ``photons`` (per channel), ``rotations`` (film scoring) and ``progress`` (a progress
    bar). ``rotations`` > 1 gives a smoother film, but its copies of an exit land in the
    same annulus: the walk's own error is then shared along each annulus, where the
    fitter's standard errors (from the scatter of an annulus's pixels) cannot see it. With
    the default 1 every exit lands on one pixel and the scatter holds the walk's error.

    Returns
    -------
    (ndarray, CaptureSpec, WalkTally)
        Stored values, the sidecar (truth under ``synthetic``) and the walk's tallies.
    """
    camera = Camera() if camera is None else camera
    height, width = (size, size) if np.isscalar(size) else size
    if incident_px is None:
        incident_px = (width / 2.0, height / 2.0)
    incident_px = check_incident(incident_px, width, height)
    check_geometry(pixel_size_mm, thickness_mm, beam_radius_mm)
    if side == "transmission" and thickness_mm is None:
        raise InputError("transmission needs a finite thickness", field="thickness_mm",
                         value=None)
    film = Film((height, width), float(pixel_size_mm), tuple(incident_px), side)
    rng = np.random.default_rng(seed)
    tally = photon_random_walk(material, photons=photons, thickness_mm=thickness_mm,
                               beam_radius_mm=beam_radius_mm, film=film, rotations=rotations,
                               seed=int(rng.integers(2**31)), progress=progress)
    stored, exposure = apply_camera(tally.film, camera, rng)
    spec = capture_spec(material, camera, image_name=image_name, pixel_size_mm=pixel_size_mm,
                         incident_px=incident_px, side=side, thickness_mm=thickness_mm,
                         beam_radius_mm=beam_radius_mm, exposure=exposure, eta_known=eta_known,
                         generator="photon random walk",
                         extra={"photons": int(photons), "rotations": int(rotations),
                                "lost": tally.lost.tolist(), "seconds": tally.seconds})
    return stored, spec, tally
