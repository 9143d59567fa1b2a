r"""The object's own transport at the scale of its surface clusters: photon random walks.

The correction of :mod:`translucent.scenes.object_diffusion` is diffusion's, and diffusion
does not describe a wall as thin as a transport length (Chicken1's red in the bowl's 6 mm
wall: there every cluster keeps the half-space). It also keeps the profile's own energy,
and a profile's energy is a second model error of its own (the dipole returns 15-20 % less
light than transport from Chicken1's green and blue). This module measures, with transport
itself, what the object returns beyond a method's profile, on the same surface clusters:
photon random walks inside the object's closed mesh (isotropic scattering with the reduced
coefficients and a smooth Fresnel boundary of relative index eta, the walk of
:mod:`translucent.materials.profiles.random_walk`'s table), entering at points spread over
the surface in the directions of diffuse light refracted through that boundary
(cosine-distributed at eta 1, as Cycles' random walk enters), and kept as the difference
from the profile:

.. math:: C_{mk} = \frac{1}{P_k A_m}\int W_m(x_o) \int W_k(x_i)\,
          \big(T(x_i \to x_o) - R(\lVert x_o - x_i\rVert)\big)\,dA_i\,dA_o

:math:`T` is the walks' exitance in the object (Monte Carlo: each exit's weight after the
boundary's Fresnel transmittance, deposited on the clusters by the exit point's weights),
:math:`R` the method's profile summed on the object's surface as the method sums it (a
quadrature over area-uniform surface points, with the tangent plane's own integral of the
profile inside the quadrature's spacing), :math:`P_k = \int W_k\,dA` the cluster's entry
area and :math:`A_m = \int W_m\,dA` its exit area. A method adds
:math:`\sum_m W_{om} \sum_k C_{mk} P_k` to its profile's sum: at the clusters' scale it
then returns the walk's transport in the object (through a thin wall, round a convex
surface, none past a fold, and the walk's energy), below it the profile's shape, which
changes fastest there. Unlike diffusion's correction it is not zero on a plane: there it is
the walk's half-space against the profile's (a test checks that the walk's own table gets
nothing on a box's face).

Lengths in mm, coefficients in mm^-1, :math:`C` in mm^-2 (an exitance per unit entering
power), as :meth:`~translucent.scenes.object_diffusion.ObjectDiffusion.response`.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass

import numpy as np

from ..cache import Cache, content_hash
from ..errors import InputError, check_count
from ..materials.fresnel import fresnel_reflectance, fresnel_transmittance
from .lighting import tangent_frames
from .mesh_shape import stratified_surface_points
from .scene import Mesh

__all__ = ["DEFAULT_WALKS", "QUADRATURE_POINTS", "SURFACE_OFFSET", "WALK_FORMAT",
           "quadrature_sizes",
           "WALKS_PER_ENTRY", "SurfaceSums", "WalkPaths", "surface_sums", "walk_correction",
           "walk_exits", "walk_paths", "walk_response"]

#: Walks per object and channel (:data:`WALKS_PER_ENTRY` from each entry point).
DEFAULT_WALKS = 32768
#: Walks from each entry point.
WALKS_PER_ENTRY = 8
#: Area-uniform surface points of the profile's quadrature.
QUADRATURE_POINTS = 32768
#: The profile's entry points (the quadrature is smooth in them; the walks' are many more).
QUADRATURE_ENTRIES = 2048


def quadrature_sizes(walks: int) -> tuple[int, int]:
    """Return the profile quadrature's (entry points, exit points) for ``walks`` walks.

    :data:`QUADRATURE_ENTRIES` and :data:`QUADRATURE_POINTS` at :data:`DEFAULT_WALKS` and
    more; fewer walks (a smoke run's) get a quadrature as coarse as their own estimate.
    """
    scale = min(1.0, int(walks) / DEFAULT_WALKS)
    return (max(64, int(QUADRATURE_ENTRIES * scale)),
            max(256, int(QUADRATURE_POINTS * scale)))
#: A walk whose weight falls below this plays Russian roulette (survives with probability
#: weight / this, at this weight).
ROULETTE_WEIGHT = 0.05
#: Steps after which the walks still going are given up (counted in the statistics).
MAX_STEPS = 100000
#: Points leave the surface inwards by this fraction of the object's bounding diagonal.
SURFACE_OFFSET = 1e-6
#: Nodes of the profile's log-radius lookup per decade.
LOOKUP_PER_DECADE = 64
#: The disk cache's namespace, and the version of the walks' estimator: a change makes
#: every cached response, and every committed model reference rendered with it, stale.
CACHE_NAMESPACE = "object_walk"
WALK_FORMAT = 3
#: Responses kept in memory per process.
KEPT_RESPONSES = 16
#: Objects' walks kept in memory per process (one per object, sigma_s' and eta).
KEPT_PATHS = 4
#: The walks are made with this fraction of the medium's absorption (their Russian
#: roulette's): an edit to any absorption at or above it re-weighs them exactly.
FLOOR_FRACTION = 0.5


def _triangle_mesh(triangles) -> Mesh:
    triangles = np.ascontiguousarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    return Mesh(triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3),
                name="object")


def _isotropic(rng, count: int) -> np.ndarray:
    cos_theta = 1.0 - 2.0 * rng.random(count)
    phi = 2.0 * math.pi * rng.random(count)
    sin_theta = np.sqrt(np.maximum(0.0, 1.0 - cos_theta ** 2))
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta], axis=1)


def _diffuse_entry(normals, eta: float, rng) -> np.ndarray:
    """Directions into the medium of diffuse light refracted through the boundary.

    Outside, cosine-distributed about the normal and weighted by the Fresnel transmittance
    of relative index ``eta`` (drawn by rejection); inside, refracted by Snell's law (at
    eta 1: cosine-distributed about ``-normals``).
    """
    count = len(normals)
    cos_out = np.empty(count)
    todo = np.arange(count)
    while len(todo):
        cosine = np.sqrt(1.0 - rng.random(len(todo)))
        accepted = rng.random(len(todo)) < fresnel_transmittance(eta, cosine)
        cos_out[todo[accepted]] = cosine[accepted]
        todo = todo[~accepted]
    sin_in = np.sqrt(np.maximum(0.0, 1.0 - cos_out ** 2)) / eta
    cos_in = np.sqrt(np.maximum(0.0, 1.0 - sin_in ** 2))
    phi = 2.0 * math.pi * rng.random(count)
    tangent, bitangent = tangent_frames(normals)
    # the frame's opposite axes: the directions these walks were first drawn about
    return (sin_in[:, None] * (np.cos(phi)[:, None] * -tangent
                               + np.sin(phi)[:, None] * -bitangent)
            - cos_in[:, None] * normals)


def walk_exits(engine, points, normals, sigma_s_prime: float, eta: float, walks: int, rng,
               offset: float, sigma_a_floor: float = 0.0):
    r"""Walk ``walks`` photons from each entry point; return their exits and path lengths.

    Path lengths as in white Monte Carlo (Alerstam et al. 2008): the walks fly and scatter
    with the reduced scattering coefficient alone, absorbed continuously by
    ``sigma_a_floor`` (which lets Russian roulette end them), and record their path
    length, so that any absorption :math:`\sigma_a \ge` ``sigma_a_floor`` weighs an exit
    by :math:`e^{-(\sigma_a - \sigma_{floor}) L}` afterwards (the same expectation as
    walks in the medium of absorption :math:`\sigma_a`, and never a larger weight).

    Parameters
    ----------
    engine : RayEngine
        The object's closed mesh (mm).
    points, normals : ndarray, shape (S, 3)
        Entry points on the surface and their outward unit normals.
    sigma_s_prime : float
        mm^-1, > 0.
    eta : float
        The medium's index over the outside's.
    walks : int
        From each entry point, in the directions of diffuse light refracted in
        (:func:`_diffuse_entry`).
    rng : numpy.random.Generator
    offset : float
        How far inside the surface a walk starts, or goes on after a reflection, mm.
    sigma_a_floor : float
        mm^-1, >= 0: the least absorption the walks will be weighed for.

    Returns
    -------
    source : ndarray of int, (E,)
        The entry point of each exit.
    position, normal : ndarray, (E, 3)
        Where it left, and the surface's outward normal there.
    weight : ndarray, (E,)
        The power that left there per unit power entering, with the absorption
        ``sigma_a_floor`` (after the Fresnel transmittance out).
    length : ndarray, (E,)
        The path's length inside the medium up to that exit, mm.
    statistics : dict
        ``walks``, ``steps`` (free flights traced), ``leaks`` (walks that met the surface
        from outside, through a crack, and were dropped), ``given_up`` (still going after
        :data:`MAX_STEPS` flights).
    """
    source = np.repeat(np.arange(len(points)), walks)
    position = np.repeat(points - offset * normals, walks, axis=0)
    direction = _diffuse_entry(np.repeat(normals, walks, axis=0), eta, rng)
    weight = np.ones(len(source))
    length = np.zeros(len(source))
    exits = {"source": [], "position": [], "normal": [], "weight": [], "length": []}
    stats = {"walks": len(source), "steps": 0, "leaks": 0, "given_up": 0}
    for _ in range(MAX_STEPS):
        if not len(source):
            break
        stats["steps"] += len(source)
        free = -np.log1p(-rng.random(len(source))) / sigma_s_prime
        hits = engine.trace(position, direction, free)
        inside = ~hits.hit
        flight = np.where(inside, free, hits.t)
        length += flight
        weight *= np.exp(-sigma_a_floor * flight)
        # a scattering inside the medium: move, turn isotropically
        position[inside] += free[inside, None] * direction[inside]
        direction[inside] = _isotropic(rng, int(inside.sum()))
        # the boundary: out by the Fresnel transmittance, the rest reflected back in
        at = np.flatnonzero(hits.hit)
        normal = hits.geometric_normal[at]
        cosine = np.einsum("nd,nd->n", direction[at], normal)
        leaked = cosine <= 0.0
        stats["leaks"] += int(leaked.sum())
        reflect = np.where(leaked, 0.0, fresnel_reflectance(1.0 / eta, np.abs(cosine)))
        out = ~leaked
        exits["source"].append(source[at[out]])
        exits["position"].append(hits.position[at[out]])
        exits["normal"].append(normal[out])
        exits["weight"].append(weight[at[out]] * (1.0 - reflect[out]))
        exits["length"].append(length[at[out]])
        weight[at] = np.where(leaked, 0.0, weight[at] * reflect)
        direction[at] -= 2.0 * cosine[:, None] * normal
        position[at] = hits.position[at] - offset * normal
        low = weight < ROULETTE_WEIGHT
        survive = rng.random(len(weight)) * ROULETTE_WEIGHT < weight
        weight = np.where(low, np.where(survive, ROULETTE_WEIGHT, 0.0), weight)
        keep = weight > 0.0
        source, position, direction, weight, length = (
            source[keep], position[keep], direction[keep], weight[keep], length[keep])
    stats["given_up"] = int(len(source))
    if not exits["source"]:
        return (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
                np.zeros(0), stats)
    return (np.concatenate(exits["source"]).astype(np.int64),
            np.concatenate(exits["position"]).reshape(-1, 3),
            np.concatenate(exits["normal"]).reshape(-1, 3),
            np.concatenate(exits["weight"]), np.concatenate(exits["length"]), stats)


@functools.lru_cache(maxsize=1)
def _compiled_distance_histogram():
    import numba

    @numba.njit(cache=True)
    def histogram(entries, entry_index, entry_weight, points, index, weight, near, log_r0,
                  per_step, out):  # pragma: no cover - compiled
        """out[k, m, b] += W_sk W_tm over pairs beyond ``near``, split linearly in ln r."""
        nodes = out.shape[2]
        local = np.zeros((out.shape[1], nodes))
        for s in range(len(entries)):
            local[:, :] = 0.0
            for t in range(len(points)):
                dx = points[t, 0] - entries[s, 0]
                dy = points[t, 1] - entries[s, 1]
                dz = points[t, 2] - entries[s, 2]
                r = math.sqrt(dx * dx + dy * dy + dz * dz)
                if r <= near:
                    continue
                u = (math.log(r) - log_r0) / per_step
                if u >= nodes - 1:
                    continue
                i = int(u)
                f = u - i
                for j in range(index.shape[1]):
                    w = weight[t, j]
                    if w != 0.0:
                        local[index[t, j], i] += (1.0 - f) * w
                        local[index[t, j], i + 1] += f * w
            for q in range(entry_index.shape[1]):
                w = entry_weight[s, q]
                if w != 0.0:
                    out[entry_index[s, q]] += w * local

    return histogram


def _padded_rows(matrix):
    """Return a CSR matrix's rows as (index, value) arrays of its widest row's width."""
    matrix = matrix.tocsr()
    count = np.diff(matrix.indptr)
    width = int(count.max()) if len(count) else 1
    index = np.zeros((matrix.shape[0], width), dtype=np.int64)
    value = np.zeros((matrix.shape[0], width))
    slot = np.arange(matrix.nnz) - np.repeat(matrix.indptr[:-1], count)
    rows = np.repeat(np.arange(matrix.shape[0]), count)
    index[rows, slot] = matrix.indices
    value[rows, slot] = matrix.data
    return index, value


@dataclass(eq=False)
class SurfaceSums:
    r"""How an object's surface sums any radial profile between its clusters.

    The profile's part of the correction, :math:`\int W_m(x_o) \int W_k(x_i)
    R(\lVert x_o - x_i\rVert)\,dA_i\,dA_o / P_k`, over :data:`QUADRATURE_ENTRIES` entry and
    ``quadrature`` exit points spread over the surface, kept as what does not depend on the
    profile: the pairs' cluster weights binned on a geometric grid of distances (each pair
    split between its two nodes as linear interpolation in ln r would weigh the profile
    there), and, inside twice the quadrature's spacing, the entry points' own weights (the
    surface there is its tangent plane, and the profile's integral over the disc is its
    cumulative total). A profile then costs one product (:meth:`profile_sum`): an edit of
    the material does not sum the surface again.

    Attributes
    ----------
    radius : ndarray, shape (B,)
        The distance nodes, mm.
    histogram : ndarray, shape (K, K, B)
        Entry cluster k, exit cluster m, node: the pairs' weights times the exit points'
        area, per unit entry weight of k.
    near : float
        The tangent-plane disc's radius, mm.
    near_weights : ndarray, shape (K, K)
        :math:`\sum_s W_{sk} W_{sm}` per unit entry weight of k.
    exit_area : ndarray, shape (K,)
        :math:`A_m = \int W_m\,dA`, mm^2.
    """

    radius: np.ndarray
    histogram: np.ndarray
    near: float
    near_weights: np.ndarray
    exit_area: np.ndarray

    def profile_sum(self, profile) -> np.ndarray:
        """Return the profile summed on the surface per unit power entering at k, (K, K, C).

        Indexed ``[m, k, c]`` (exit, entry, channel); ``profile`` in mm^-2.
        """
        table = np.asarray(profile.reflection(self.radius), np.float64)        # (B, C)
        near_total = np.asarray(profile.total(max_radius=self.near), np.float64)
        far = np.einsum("kmb,bc->mkc", self.histogram, table)
        return far + self.near_weights.T[:, :, None] * near_total[None, None, :]


def surface_sums(clusters, mesh, diagonal: float, quadrature: int, rng,
                 entries: int = QUADRATURE_ENTRIES) -> SurfaceSums:
    """Make an object's :class:`SurfaceSums` (one compiled pass over the point pairs)."""
    entry_point, entry_normal, area = stratified_surface_points(mesh, int(entries), rng)
    point, normal, _ = stratified_surface_points(mesh, quadrature, rng)
    point_area = area / quadrature
    entry_weights = clusters.weights(entry_point, entry_normal)
    weights = clusters.weights(point, normal)
    exit_area = point_area * np.asarray(weights.sum(axis=0)).ravel()
    index, value = _padded_rows(weights)
    entry_index, entry_value = _padded_rows(entry_weights)
    near = 2.0 * math.sqrt(point_area)
    largest = 1.01 * diagonal
    nodes = max(2, int(math.ceil(LOOKUP_PER_DECADE * math.log10(largest / near))) + 1)
    radius = np.geomspace(near, largest, nodes)
    histogram = np.zeros((clusters.clusters, clusters.clusters, nodes))
    _compiled_distance_histogram()(entry_point, entry_index, entry_value, point, index,
                                   value, near, math.log(near),
                                   math.log(radius[1] / radius[0]), histogram)
    dense = entry_weights.toarray()
    share = dense.sum(axis=0)
    share = np.where(share > 0, share, np.inf)  # a cluster no entry point reaches: 0
    histogram *= point_area / share[:, None, None]
    near_weights = (dense.T @ dense) / share[:, None]
    return SurfaceSums(radius, histogram, near, near_weights, exit_area)


@dataclass(eq=False)
class WalkPaths:
    r"""One object's white walks for one reduced scattering per channel and one eta.

    Made by :func:`walk_paths`; :meth:`transport` weighs them by any absorption.

    Attributes
    ----------
    entry_power : ndarray, shape (K,)
        :math:`P_k = \int W_k\,dA` over the walks' entry points, mm^2.
    channels : dict
        Channel -> ``(exits, sources, length, floor)``: each exit's cluster weights times
        its weight (CSR, (E, K)), its entry point's cluster weights times the entry area
        per walk (CSR, (E, K)), its path length (mm, (E,)), and the absorption the walks
        were made with (mm^-1; :meth:`transport` takes any at or above it).
    statistics : dict
        Channel -> :func:`walk_exits`' statistics.
    """

    entry_power: np.ndarray
    channels: dict
    statistics: dict

    def serves(self, sigma_a) -> bool:
        """Return whether every channel's walks can be weighed for the absorption."""
        return all(float(sigma_a[c]) >= item[3] for c, item in self.channels.items())

    def transport(self, channel: int, sigma_a: float) -> np.ndarray:
        """Return the power leaving at cluster m per unit entering at cluster k, (K, K)."""
        size = len(self.entry_power)
        if channel not in self.channels:
            return np.zeros((size, size))
        exits, sources, length, floor = self.channels[channel]
        if float(sigma_a) < floor:
            raise InputError(f"the walks were made for an absorption of at least {floor} "
                             "mm^-1", field="sigma_a", value=float(sigma_a))
        weighed = exits.multiply(np.exp(-(float(sigma_a) - floor) * length)[:, None])
        return np.asarray((weighed.T @ sources).todense()) / self.entry_power[None, :]


def walk_paths(triangles, clusters, sigma_s_prime, eta: float, sigma_a_floor=0.0, *,
               walks: int = DEFAULT_WALKS, seed: int = 0) -> WalkPaths:
    """Walk an object's photons without absorption, per channel (:func:`walk_exits`).

    Parameters
    ----------
    triangles : ndarray, shape (F, 3, 3)
        The object's closed surface, mm, counter-clockwise seen from outside.
    clusters : ObjectDiffusion
        The clusters and their weights.
    sigma_s_prime : array_like, shape (C,)
        mm^-1, >= 0 (a channel without scattering has no walks).
    eta : float
        > 0.
    sigma_a_floor : array_like, shape (C,) or float
        mm^-1, >= 0: the least absorption each channel's walks will serve.
    walks : int
        Per channel (:data:`WALKS_PER_ENTRY` from each entry point).
    seed : int

    Returns
    -------
    WalkPaths
    """
    from .raycast import RayEngine

    check_count(walks, "geometry_walks", minimum=WALKS_PER_ENTRY)
    eta = float(eta)
    if not (math.isfinite(eta) and eta > 0.0):
        raise InputError("must be finite and > 0", field="eta", value=eta)
    mesh = _triangle_mesh(triangles)
    engine = RayEngine([mesh])
    rng = np.random.default_rng([int(seed), 1])
    entries = max(1, int(walks) // WALKS_PER_ENTRY)
    entry_point, entry_normal, area = stratified_surface_points(mesh, entries, rng)
    entry_weights = clusters.weights(entry_point, entry_normal).tocsr()
    entry_area = area / entries
    entry_power = entry_area * np.asarray(entry_weights.sum(axis=0)).ravel()
    channels, statistics = {}, {}
    sigma_s_prime = np.atleast_1d(np.asarray(sigma_s_prime, np.float64))
    floors = np.broadcast_to(np.asarray(sigma_a_floor, np.float64), sigma_s_prime.shape)
    for c in np.flatnonzero(sigma_s_prime > 0):
        source, position, normal, weight, length, stats = walk_exits(
            engine, entry_point, entry_normal, float(sigma_s_prime[c]), eta, WALKS_PER_ENTRY,
            rng, SURFACE_OFFSET * engine.diagonal, float(floors[c]))
        exits = clusters.weights(position, normal).multiply(weight[:, None]).tocsr()
        sources = (entry_weights[source] * (entry_area / WALKS_PER_ENTRY)).tocsr()
        channels[int(c)] = (exits, sources, length, float(floors[c]))
        statistics[int(c)] = {**stats, "exits": int(len(weight))}
    return WalkPaths(np.where(entry_power > 0, entry_power, np.inf), channels, statistics)


def walk_correction(triangles, clusters, medium, profile, *, walks: int = DEFAULT_WALKS,
                    quadrature: int | None = None, seed: int = 0,
                    paths: WalkPaths | None = None, sums: SurfaceSums | None = None,
                    statistics: dict | None = None) -> np.ndarray:
    r"""Return the walks' transport beyond ``profile`` between the clusters, (K, K, 3).

    Parameters
    ----------
    triangles : ndarray, shape (F, 3, 3)
        The object's closed surface, mm, counter-clockwise seen from outside.
    clusters : ObjectDiffusion
        The clusters and their weights (:meth:`ObjectDiffusion.weights`).
    medium : Dipole
        sigma_a, sigma_s' (mm^-1, per channel) and eta (any: the walks need no table; the
        profile ``random_walk`` takes 1 to 2).
    profile : RadialProfile
        The method's profile of ``medium`` (mm^-2): what the correction is beyond.
    walks : int
        Per channel (:data:`WALKS_PER_ENTRY` from each entry point).
    quadrature : int, optional
        Surface points of the profile's sum on the surface (default: as many as
        :func:`quadrature_sizes` gives ``walks``; its entry points always so).
    seed : int
    paths : WalkPaths, optional
        The object's walks for ``medium``'s sigma_s' and eta (:func:`walk_paths`), when
        already made: an edit of the absorption re-weighs them.
    sums : SurfaceSums, optional
        The object's :func:`surface_sums` for ``quadrature`` and ``seed``, when already
        made.
    statistics : dict, optional
        Filled with each channel's walk statistics (:func:`walk_exits`), its exits and
        the energy they carried out per unit entering power.

    Returns
    -------
    ndarray
        :math:`C_{mk}` in mm^-2 (module docstring); zero in a channel without scattering.
    """
    if quadrature is not None:
        check_count(quadrature, "quadrature", minimum=16)
    if paths is None:
        paths = walk_paths(triangles, clusters, medium.sigma_s_prime, medium.eta,
                           FLOOR_FRACTION * np.asarray(medium.sigma_a, np.float64),
                           walks=walks, seed=seed)
    if sums is None:
        sums = _object_sums(triangles, clusters, walks, seed, quadrature)
    profile_sum, exit_area = sums.profile_sum(profile), sums.exit_area
    sigma_a = np.atleast_1d(np.asarray(medium.sigma_a, np.float64))
    out = np.zeros((clusters.clusters, clusters.clusters, len(sigma_a)))
    for c in paths.channels:
        transport = paths.transport(c, float(sigma_a[c]))
        out[:, :, c] = (transport - profile_sum[:, :, c]) \
            / np.where(exit_area > 0, exit_area, np.inf)[:, None]
        if statistics is not None:
            statistics[c] = {**paths.statistics[c], "energy": float(
                (transport * paths.entry_power[None, :]).sum()
                / paths.entry_power[np.isfinite(paths.entry_power)].sum())}
    return out


_KEPT: dict = {}
_PATHS: dict = {}
_SUMS: dict = {}


def _keep(store: dict, key, value, limit: int):
    """Keep ``value`` under ``key``, dropping the oldest entry beyond ``limit``."""
    if key not in store and len(store) >= limit:
        store.pop(next(iter(store)))
    store[key] = value
    return value


def _object_sums(triangles, clusters, walks: int, seed: int,
                 quadrature: int | None = None) -> SurfaceSums:
    """Make an object's :class:`SurfaceSums` at the walks' quadrature sizes."""
    entries, points = quadrature_sizes(walks)
    mesh = _triangle_mesh(triangles)
    diagonal = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    return surface_sums(clusters, mesh, diagonal, points if quadrature is None else quadrature,
                        np.random.default_rng([int(seed), 2]), entries)


def walk_response(clusters, triangles, medium, profile, *, walks: int = DEFAULT_WALKS,
                  seed: int = 0, cache: bool = True) -> np.ndarray:
    """Return :func:`walk_correction`, kept per object, medium, profile and settings.

    In memory (the last :data:`KEPT_RESPONSES`) and, where ``clusters`` has a key and
    ``cache`` is true, in the disk cache (namespace ``object_walk``). The walks themselves
    are kept in memory per object, sigma_s' and eta (the last :data:`KEPT_PATHS`), made
    with :data:`FLOOR_FRACTION` of the absorption: a new absorption at or above that
    re-weighs them (and makes the profile's sum on the surface once more), a lower one
    walks again. The floor of the walks used is part of the key: a material reached by
    editing is another estimate than the same material made fresh, and each is kept as
    what it is (a model reference and a method's own material are always made fresh).
    """
    triangles = np.ascontiguousarray(triangles, dtype=np.float64)
    # a keyed object's clusters already name its triangles: no hashing them every frame
    object_key = clusters.key or hashlib.sha256(
        np.ascontiguousarray(clusters.cluster_point).tobytes()
        + triangles.tobytes()).hexdigest()
    shape_key = (object_key, int(walks), int(seed))
    paths_key = shape_key + (np.asarray(medium.sigma_s_prime, np.float64).tobytes(),
                             float(medium.eta))
    paths = _PATHS.get(paths_key)
    if paths is None or not paths.serves(medium.sigma_a):
        paths = None
        floors = [float(f) for f in FLOOR_FRACTION * np.atleast_1d(
            np.asarray(medium.sigma_a, np.float64))]
    else:
        floors = [float(item[3]) for item in paths.channels.values()]
    # the walks' floor is part of what was computed: kept walks made for a lower
    # absorption give another (equally valid) estimate than fresh ones
    key = content_hash("object walk response", WALK_FORMAT, *shape_key, medium.cache_key(),
                       profile.cache_key(), floors)
    held = _KEPT.get(key)
    if held is not None:
        return held
    shape = (clusters.clusters, clusters.clusters, len(np.atleast_1d(medium.sigma_a)))

    def make():
        made = paths
        if made is None:
            made = walk_paths(triangles, clusters, medium.sigma_s_prime, medium.eta,
                              FLOOR_FRACTION * np.asarray(medium.sigma_a, np.float64),
                              walks=walks, seed=seed)
            _keep(_PATHS, paths_key, made, KEPT_PATHS)
        sums = _SUMS.get(shape_key)
        if sums is None:
            sums = _keep(_SUMS, shape_key, _object_sums(triangles, clusters, walks, seed),
                         KEPT_PATHS)
        return walk_correction(triangles, clusters, medium, profile, walks=walks, seed=seed,
                               paths=made, sums=sums)

    if cache and clusters.key:
        out, _ = Cache(CACHE_NAMESPACE).load_or_make(
            key, make, valid=lambda value: isinstance(value, np.ndarray)
            and value.shape == shape, what="the walks' correction of an object")
    else:
        out = make()
    return _keep(_KEPT, key, out, KEPT_RESPONSES)
