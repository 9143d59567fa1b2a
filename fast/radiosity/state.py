"""The precomputed state: relighting and translucency editing (Sheng et al. 2014, Sect. 6)."""

from __future__ import annotations

import time
import warnings

import numpy as np
from scipy import sparse

from ...errors import InputError
from ...image import Image
from ...materials.homogeneous import Dipole, Lambertian
from ...materials.profiles import (
    MixedProfiles,
    profile_for,
)
from ...materials.solid import SolidMedium
from ..knobs import DEFAULT_PROFILE
from ..object_geometry import object_geometries
from ..solid_inputs import mixed_profiles_from_solid
from .knobs import COMPONENTS, WARM_START_FRAMES
from .lighting import AreaLightShadows, direct_irradiance, emitters_seen
from .scattering import ScatteringMatrix, scattering_matrix, scattering_profile
from .solve import (
    check_convergence,
    form_factor_bounds,
    form_factor_product,
    solve_radiosity,
    transfer_matrix,
    transfer_seconds_estimate,
)


def materials_of(scene, material) -> dict:
    """Material overrides by object name: one material for every translucent object, or a dict."""
    if material is None:
        return {}
    if isinstance(material, dict):
        overrides = dict(material)
        for name in material:
            scene.object(name)
    else:
        overrides = {o.name: material for o in scene.objects
                     if profile_for(o.material) is not None}
    # a solid medium is read at this object's faces (solid_inputs)
    return {name: mixed_profiles_from_solid(value, scene.object(name).mesh).material
            if isinstance(value, SolidMedium) else value for name, value in overrides.items()}


class RadiosityState:
    """The result of :func:`precompute`: relights and changes translucency interactively.

    Attributes
    ----------
    scene : Scene
    patches : Patches
    form_factors : scipy.sparse.csr_matrix or None
        None when no patch sees another.
    geometry : ScatteringGeometry
    knobs : dict
    log : StageLog
    S : ScatteringMatrix
        For the current materials.
    transfer : list of ndarray or None
        :math:`T = (I - SF)^{-1}S` per channel when it fits ``transfer_budget_mb``.
    convergence : dict
        The report of :func:`check_convergence` for the current materials.
    """

    def __init__(self, scene, patches, F, geometry, knobs, log):
        self.scene = scene
        self.patches = patches
        self.form_factors = F
        self.geometry = geometry
        self.knobs = knobs
        self.log = log
        self.materials: dict = {}
        self.transfer = None
        # the patch centroids, nudged off the surface, and the patch rows per light-sample
        # group: fixed by the geometry, so every frame's patch_irradiance reuses them
        self._patch_points = patches.centroid + 1e-6 * patches.radius[:, None] * patches.normal
        translucent = np.isin(patches.object_of, list(geometry.objects))
        self._translucent_rows = np.flatnonzero(translucent)
        self._diffuse_rows = np.flatnonzero(~translucent)
        self._solved = None                 # (B, F B) of the last solve, for image()
        # the F half of the bound of Eq. 15 does not change with the materials
        self._form_factor_facts = form_factor_bounds(F, patches)
        self._inter_reflects = F is not None and F.nnz > 0  # else T would be S itself
        self._shadow_points: dict = {}      # AreaLightShadows per point set and engine
        self._interreflected = None         # S F B of the last solve (warm start)
        self._cached_gbuffer = None
        self._cached_image_operators = None
        # the geometry correction of each closed Dipole object (knob geometry): made once
        # here, its response solved per material in set_material (and kept by the cache)
        self.object_shapes = object_geometries(
            scene, [scene.objects[i].name for i in geometry.objects], knobs, log)
        self.set_material(None)

    # -- materials ---------------------------------------------------------------------

    def set_material(self, material) -> float:
        """Rebuild S for new materials; return the seconds it took.

        ``material``: one material for every translucent object, or a dict by object name.
        This is the translucency-change step of Sheng et al. 2014, Sect. 5.2.
        """
        started = time.perf_counter()
        overrides = materials_of(self.scene, material)
        self.materials = {**self.materials, **overrides}
        self.S = scattering_matrix(self.geometry, self.scene, self.patches, self.materials,
                                   profile=self.knobs["profile"],
                                   geometries=self.object_shapes)
        self._say_profile()
        self.convergence = check_convergence(self.S, self.form_factors, self.patches,
                                             form_factor_facts=self._form_factor_facts)
        self._say_energy_excess()
        self._energy_beyond_cutoff()
        self.transfer = None
        self._transfer_materials = None
        self._frames = []  # (E, B - SE) of earlier frames: stale once S changes
        self._solve_seconds = 0.0  # spent solving for these materials (T's rental)
        return time.perf_counter() - started

    def _say_profile(self) -> None:
        """Note the profile S is filled from; say where the finite-object gain is left out."""
        chosen = self.knobs["profile"]
        self.log.notes["profile"] = chosen
        sentence = (f"finite_object_energy: the diffusion escape of the object's own shape "
                    f"corrects the dipole only; profile {chosen!r} fills S as the "
                    "semi-infinite profile it is")
        if chosen != DEFAULT_PROFILE and self.knobs["finite_object_energy"] and \
                sentence not in self.log.skipped:
            self.log.skip(sentence)

    def _say_energy_excess(self) -> None:
        """Say where Eq. 15 is broken but not needed (no inter-reflection: B = SE)."""
        report = self.convergence
        prefix = "the energy condition of Eq. 15"
        self.log.skipped[:] = [s for s in self.log.skipped if not s.startswith(prefix)]
        if report["energy_conserving"]:
            return
        self.log.skip(f"{prefix}: patch {report['patch']} of "
                      f"'{report['object']}' sends {report['max_scattering_column_sum']:.4f} "
                      f"of the light it receives back out ({report['channel']}); nothing "
                      "inter-reflects, so there is no series to diverge and B = SE is the "
                      "material's as its profile gives it")

    def _energy_beyond_cutoff(self):
        max_d = self.geometry.grid.max_radius
        lost = {}
        for index in self.geometry.objects:
            obj = self.scene.objects[index]
            profile = scattering_profile(self.materials.get(obj.name, obj.material),
                                         self.knobs["profile"])
            profiles = profile.profiles if isinstance(profile, MixedProfiles) else (profile,)
            for item in profiles:
                total = item.total()
                inside = item.total(max_radius=max_d)
                fraction = float(np.max(1.0 - inside / np.where(total > 0, total, 1.0)))
                lost[obj.name] = max(lost.get(obj.name, 0.0), fraction)
        self.log.notes["energy_beyond_max_d"] = lost
        worst = max(lost.values(), default=0.0)
        if worst > 10 * self.knobs["profile_energy_cutoff"]:
            warnings.warn(f"the profile keeps {worst:.1%} of its energy beyond max_d = "
                          f"{max_d:g} mm; precompute with a larger max_distance_mm",
                          stacklevel=3)

    def _scene_with_materials(self):
        scene = self.scene
        for name, material in self.materials.items():
            scene = scene.with_material(name, material)
        return scene

    # -- solving -----------------------------------------------------------------------

    def transfer_fits(self) -> bool:
        """Return True when 3 P^2 float32 numbers fit ``transfer_budget_mb`` (the rule for T).

        Memory decides whether T may be built, since T's cost is its size: 12 P^2 bytes
        read per frame and an O(P^3) solve that holds about five P x P float64 arrays at
        once. Whether it is worth building is :meth:`transfer_pays`.
        """
        size = len(self.patches)
        return 3 * size * size * 4 <= self.knobs["transfer_budget_mb"] * 2**20

    def transfer_pays(self) -> bool:
        """Return True once T's build is cheaper than the solves it would have saved.

        The rule of ``transfer="auto"``, the ski-rental rule: iterate until the solves for
        the current materials have taken as long as building T is estimated to take
        (:func:`~translucent.fast.radiosity.solve.transfer_seconds_estimate`), then build
        it. However many frames follow, that costs at most twice the better of the two
        choices made in hindsight (with an exact estimate). Without form factors it never
        pays: T would be S itself, a dense copy of what one sparse product already applies.
        A T-product frame saves at most its solve; the measured figures are in
        docs/radiosity.md.
        """
        return self._inter_reflects and \
            self._solve_seconds >= transfer_seconds_estimate(len(self.patches))

    def precompute_transfer(self) -> float | None:
        """Compute T for the current materials when it fits; returns seconds (None: skipped)."""
        if not self.transfer_fits():
            sentence = (f"no precomputed T: 3 x {len(self.patches)}^2 float32 = "
                        f"{3 * len(self.patches) ** 2 * 4 / 2**20:.0f} MB exceeds "
                        f"transfer_budget_mb = {self.knobs['transfer_budget_mb']}; relighting "
                        "iterates instead")
            if sentence not in self.log.skipped:
                self.log.skip(sentence)
            return None
        started = time.perf_counter()
        self.transfer = transfer_matrix(self.S, self.form_factors)
        return time.perf_counter() - started

    def _say_relighting_iterates(self) -> None:
        """Say once, among what was skipped, that relit frames iterate until T pays."""
        if any(s.startswith("T not built yet") for s in self.log.skipped):
            return
        self.log.skip(f"T not built yet: relit frames iterate until their solves have cost "
                      f"its estimated build of "
                      f"{transfer_seconds_estimate(len(self.patches)):.1f} s (transfer='auto', "
                      "the ski-rental rule; transfer='never' never builds it)")

    def patch_irradiance(self, lights=None) -> np.ndarray:
        """Direct irradiance E of every patch (at its centroid), shape (P, 3).

        Translucent patches take ``light_samples`` per area light; diffuse ones take
        ``diffuse_light_samples`` when it is set: their E reaches the image only through the
        form factors, which average it over everything a pixel's surface sees (the image's
        own direct light is per pixel), so fewer shadow rays cost little there. It stays
        off by default; what it saves and costs, measured, is in docs/radiosity.md.

        Rectangular area lights go through :class:`AreaLightShadows` (set up once per point
        set), other lights through :func:`direct_irradiance`; the two agree to round-off.
        """
        p = self.patches
        samples = self.knobs["light_samples"]
        diffuse_samples = self.knobs.get("diffuse_light_samples")
        everything = np.arange(len(p))
        groups = [("all", everything, samples)]
        if diffuse_samples is not None and diffuse_samples != samples:
            groups = [("translucent", self._translucent_rows, samples),
                      ("diffuse", self._diffuse_rows, diffuse_samples)]
        lights = self.scene.lights if lights is None else tuple(lights)
        E = np.zeros((len(p), 3))
        groups = [(name, rows, count, None) for name, rows, count in groups]
        entries = self._directional_entries()
        if entries:  # those objects' patches are lit through their boundary instead
            taken = np.concatenate([rows for _, rows, _ in entries])
            names = tuple(name for name, _, _ in entries)
            groups = [((name, "without") + names, np.setdiff1d(rows, taken), count, None)
                      for name, rows, count, _ in groups]
            groups += [(name, rows, samples, response) for name, rows, response in entries]
        for name, rows, count, response in groups:
            E[rows] = self._direct_irradiance(("patches", name), self._patch_points[rows],
                                              p.normal[rows], lights, count, self.knobs["seed"],
                                              response=response)
        return E

    def _directional_boundaries(self) -> list:
        """Return ``(object index, eta, 1 / T_in(eta))`` per object behind a dielectric.

        The homogeneous objects whose eta is not 1, where the knob ``boundary`` is
        directional (else none).
        """
        if self.knobs.get("boundary", "diffuse") != "directional":
            return []
        from ...materials.profiles.base import diffuse_entry_transmittance

        found = []
        for index in self.geometry.objects:
            item = self.scene.objects[index]
            material = self.materials.get(item.name, item.material)
            if isinstance(material, Dipole) and material.eta != 1.0:
                eta = float(material.eta)
                found.append((index, eta, 1.0 / float(diffuse_entry_transmittance(eta))))
        return found

    def _directional_entries(self) -> list:
        r"""Objects whose lights' light enters through a dielectric at its own angle.

        S carries the diffuse entry :math:`T_{in}(\eta)` in every column (Sheng et al. 2014,
        Sect. 3.2), right for the inter-reflected light F B, which arrives from every
        direction. A light's direct light arrives from one direction and enters with
        :math:`F_t(\eta, \mu)`, as the BSSRDF of Jensen et al. 2001 has it: with the knob
        ``boundary`` at ``"directional"`` the direct irradiance of a homogeneous object's
        patches is weighted :math:`F_t(\eta, \mu)\,\mu / T_{in}(\eta)` per light sample,
        so that S times it is the light that entered.

        Returns
        -------
        list of (name, rows, response)
            Empty with ``boundary`` diffuse; index-matched objects (:math:`F_t = T_{in} = 1`)
            are left out.
        """
        from ...materials.fresnel import transmitted_cosine

        entries = []
        for index, eta, scale in self._directional_boundaries():

            def response(cosine, eta=eta, scale=scale):
                return transmitted_cosine(eta, cosine) * scale

            item = self.scene.objects[index]
            rows = self.patches.of_object(index)
            entries.append((item.name, rows, response))
        return entries

    def _direct_irradiance(self, key, points, normals, lights, samples, seed,
                           response=None) -> np.ndarray:
        """:func:`direct_irradiance` at a fixed point set, named by ``key``.

        Rectangular area lights go through the point set's :class:`AreaLightShadows`, built
        once per key and ray engine; other lights, and a receiver's own ``response`` (a
        dielectric's entry, which the compiled path does not weigh), through
        :func:`direct_irradiance`.
        """
        if response is not None or not AreaLightShadows.handles(lights):
            return direct_irradiance(self.scene, points, normals, lights=lights,
                                     samples=samples, seed=seed, response=response)
        key = key + (self.knobs["shadow_ray_engine"],)
        if key not in self._shadow_points:
            self._shadow_points[key] = AreaLightShadows(self.scene, points, normals,
                                                        self.knobs["shadow_ray_engine"])
        return self._shadow_points[key].irradiance(lights, samples, seed)

    def solve(self, irradiance, component: str = "both") -> tuple[np.ndarray, dict]:
        """Radiosity B (P, 3) for patch irradiance E, for one bounce component (Fig. 6)."""
        if component not in COMPONENTS:
            raise InputError(f"unknown component; valid: {', '.join(COMPONENTS)}",
                             field="component", value=component)
        if component in ("direct", "interreflection"):
            local = self.S.power_column_sums(self.patches.area)
            diagonal = ScatteringMatrix(np.arange(len(local) + 1), np.arange(len(local)),
                                        local)
            source = local * irradiance
            if component == "direct":
                return source, {"iterations": 0, "solver": "none"}
            return self._solve(diagonal, source)
        source = self.S.dot(irradiance)
        if component == "subsurface":
            return source, {"iterations": 0, "solver": "none"}
        if self.transfer is not None:
            B = np.stack([self.transfer[c] @ irradiance[:, c].astype(np.float32)
                          for c in range(3)], axis=1).astype(np.float64)
            return B, {"iterations": 0, "solver": "transfer"}
        initial = self._warm_start(irradiance, source) if self.knobs["warm_start"] else None
        B, info = self._solve(self.S, source, initial)
        self._interreflected = B - source
        self._frames = (self._frames + [(np.array(irradiance, dtype=np.float64), B - source)])[
            -WARM_START_FRAMES:]
        info["warm_start"] = initial is not None
        return B, info

    def forget_frames(self) -> None:
        """Drop the earlier frames that warm-start the next solve (a cold start follows)."""
        self._frames = []
        self._interreflected = None

    def _warm_start(self, irradiance, source):
        r"""Return the starting guess from earlier frames (None: the first frame).

        Relighting: B is linear in E, so the new E is projected on the last frames'
        irradiances, :math:`E \approx \sum_k \alpha_k E_k` (least squares per channel), and
        the guess is :math:`\sum_k \alpha_k B_k + S(E - \sum_k \alpha_k E_k)` (the projection
        of earlier solutions of Fischer 1998, Comput. Methods Appl. Mech. Engrg. 163). After a
        translucency change (S new, E the same) the last inter-reflected part
        :math:`SFB` is added to the new :math:`SE`. The residual test decides either way.
        """
        if self._frames:
            guess = np.array(source, dtype=np.float64)
            for c in range(3):
                irradiances = np.stack([E[:, c] for E, _ in self._frames])   # (k, P)
                # least squares through the k x k normal equations (matrix products): the
                # SVD of lstsq on (P, k) and einsum cost more than the rest of the frame
                weights = np.linalg.lstsq(irradiances @ irradiances.T,
                                          irradiances @ irradiance[:, c], rcond=None)[0]
                # sum_k a_k B_k + S(E - sum_k a_k E_k) = SE + sum_k a_k (B_k - S E_k): the
                # frames keep their inter-reflected parts, so the guess needs no product of S
                guess[:, c] += weights @ np.stack([part[:, c] for _, part in self._frames])
            return guess
        return None if self._interreflected is None else source + self._interreflected

    def _solve(self, S, source, initial=None):
        """Solve with the knobs; keep F B of the result for :meth:`image`."""
        B, info = solve_radiosity(S, self.form_factors, source, solver=self.knobs["solver"],
                                  tolerance=self.knobs["tolerance"],
                                  max_iterations=self.knobs["max_iterations"], initial=initial)
        global_irradiance = info.pop("global_irradiance", None)
        self._solved = (B, global_irradiance) if global_irradiance is not None else None
        return B, info

    # -- images ------------------------------------------------------------------------

    def _gbuffer(self):
        if self._cached_gbuffer is None:
            from ...scenes.gbuffer import gbuffer

            self._cached_gbuffer = gbuffer(self.scene)
        return self._cached_gbuffer

    def _image_operators(self, scene) -> dict:
        """Per-camera linear maps from patch values to pixels, built once (:meth:`image`).

        The vertex averages of :meth:`Patches.vertex_values` followed by the barycentric
        interpolation of the G-buffer are linear in the patch values: their product is one
        sparse (pixels x patches) matrix per kind of surface, so a frame's image costs two
        sparse products instead of an average and an interpolation per object.
        """
        lambertian = tuple(obj.material if isinstance(obj.material, Lambertian) else None
                           for obj in scene.objects)
        cached = self._cached_image_operators
        if cached is not None and cached["lambertian"] == lambertian:
            return cached
        gb = self._gbuffer()
        object_id = gb.object_id.reshape(-1)
        behind = np.einsum("hwd,hwd->hw", gb.geometric_normal, gb.view_direction).reshape(-1) < 0
        diffuse, diffuse_weights, translucent, translucent_weights = [], [], [], []
        translucent_object = []
        for index, obj in enumerate(scene.objects):
            pixels = np.flatnonzero(object_id == index)
            if not len(pixels):
                continue
            if lambertian[index] is not None:
                diffuse.append(pixels)
                diffuse_weights.append(self._pixel_weights(gb, index, obj.mesh, pixels))
                continue
            if index in self.geometry.sheets:
                # a two-sided sheet shows the face turned towards the camera
                pixels = np.concatenate([pixels[~behind[pixels]], pixels[behind[pixels]]])
                weights = sparse.vstack([
                    self._pixel_weights(gb, index, obj.mesh, pixels[~behind[pixels]]),
                    self._pixel_weights(gb, index, obj.mesh, pixels[behind[pixels]],
                                        back=True)])
            else:
                weights = self._pixel_weights(gb, index, obj.mesh, pixels)
            translucent.append(pixels)
            translucent_weights.append(weights)
            translucent_object.append(np.full(len(pixels), index))
        size = len(self.patches)

        def stacked(blocks):
            return sparse.vstack(blocks).tocsr() if blocks else sparse.csr_matrix((0, size))

        diffuse = np.concatenate(diffuse) if diffuse else np.zeros(0, dtype=np.int64)
        albedo = np.zeros((len(diffuse), 3))
        for index, material in enumerate(lambertian):
            if material is not None:
                albedo[object_id[diffuse] == index] = material.albedo
        points = gb.position.reshape(-1, 3)[diffuse]
        normals = gb.geometric_normal.reshape(-1, 3)[diffuse]
        facing = np.sign(np.einsum("ij,ij->i", normals,
                                   gb.view_direction.reshape(-1, 3)[diffuse]))
        shading = gb.normal.reshape(-1, 3)[diffuse] * np.where(facing == 0, 1.0, facing)[:, None]
        translucent = np.concatenate(translucent) if translucent else np.zeros(0, dtype=np.int64)
        # the cosine of the view at each translucent pixel, for a directional exit
        exit_cosine = np.abs(np.einsum("ij,ij->i", gb.normal.reshape(-1, 3)[translucent],
                                       gb.view_direction.reshape(-1, 3)[translucent]))
        self._cached_image_operators = {
            "lambertian": lambertian, "diffuse": diffuse, "diffuse_weights":
            stacked(diffuse_weights), "translucent": translucent,
            "translucent_weights": stacked(translucent_weights),
            "translucent_object": np.concatenate(translucent_object) if translucent_object
            else np.zeros(0, dtype=np.int64), "exit_cosine": np.clip(exit_cosine, 0.0, 1.0),
            "albedo_over_pi": albedo / np.pi, "points": points + 1e-6 * normals * facing[:, None],
            "shading": shading}
        return self._cached_image_operators

    def _exit_factor(self, operators) -> np.ndarray:
        r"""Per translucent pixel: :math:`F_t(\eta, \mu_o) / T_{in}(\eta)`, or 1.

        The exit of the BSSRDF the model reference renders (reference/bssrdf_path.py):
        the exitance B leaves distributed as :math:`F_t(\eta, \mu_o)\,\mu_o`, normalised
        by :math:`1 - F_{dr} = T_{in}`, where the paper's :math:`B/\pi` leaves it
        Lambertian. 1 for index-matched objects and with ``boundary`` diffuse.
        """
        from ...materials.fresnel import fresnel_transmittance

        factor = np.ones(len(operators["translucent"]))
        for index, eta, scale in self._directional_boundaries():
            where = operators["translucent_object"] == index
            factor[where] = fresnel_transmittance(eta, operators["exit_cosine"][where]) * scale
        return factor

    def _pixel_weights(self, gb, index, mesh, pixels, back=False) -> sparse.csr_matrix:
        """(pixels x patches) weights: area-weighted vertex averages, then barycentrics."""
        to_vertices = self.patches.vertex_average(index, mesh, back=back)
        triangles = gb.triangle_id.reshape(-1)[pixels]
        to_pixels = sparse.csr_matrix(
            (gb.barycentrics.reshape(-1, 3)[pixels].ravel(),
             (np.repeat(np.arange(len(pixels)), 3), np.asarray(mesh.faces)[triangles].ravel())),
            shape=(len(pixels), len(mesh.vertices)))
        return (to_pixels @ to_vertices).tocsr()

    def image(self, B, lights=None, component: str = "both") -> np.ndarray:
        r"""Compose the image (H, W, 3) from the patch radiosity B.

        Diffuse surfaces: :math:`\rho/\pi (E_{direct} + FB)` with the direct part per pixel;
        translucent surfaces: :math:`B/\pi` interpolated from the vertices (both through
        the per-camera weights of :meth:`_image_operators`).
        """
        gb = self._gbuffer()
        scene = self._scene_with_materials()
        operators = self._image_operators(scene)
        lights = scene.lights if lights is None else tuple(lights)
        rgb = np.zeros((gb.shape[0] * gb.shape[1], 3))
        if self.form_factors is None or component not in ("interreflection", "both"):
            global_irradiance = np.zeros_like(B)
        elif self._solved is not None and self._solved[0] is B:
            # the solver's last product: F B of exactly this B
            global_irradiance = self._solved[1]
        else:
            global_irradiance = form_factor_product(self.form_factors, B)
        diffuse = operators["diffuse"]
        rgb[operators["translucent"]] = operators["translucent_weights"] @ B / np.pi \
            * self._exit_factor(operators)[:, None]
        if len(diffuse):
            direct = self._direct_irradiance(("pixels",), operators["points"],
                                             operators["shading"], lights,
                                             self.knobs["light_samples"], self.knobs["seed"] + 1)
            rgb[diffuse] = operators["albedo_over_pi"] * (
                operators["diffuse_weights"] @ global_irradiance + direct)
        rgb = rgb.reshape(gb.shape + (3,))
        rgb += emitters_seen(scene.with_lights(lights), gb)
        return rgb

    def render(self, lights=None, material=None, component: str = "both") -> Image:
        """Render with new lights and/or material (None keeps the current ones).

        A new material rebuilds S (the translucency change of Sect. 5.2) and drops T; new
        lights recompute E and solve, or multiply by T (Sect. 6.4). With the knob
        ``transfer="auto"`` a relighting computes T when it fits ``transfer_budget_mb``
        (:meth:`transfer_fits`) and the solves since the last material change have taken
        as long as its build would (:meth:`transfer_pays`); translucency changes always
        iterate, since T would have to be inverted again.
        """
        started = time.perf_counter()
        facts = {}
        if material is not None:
            facts["material_seconds"] = self.set_material(material)
        if lights is not None and self.transfer is None and self.knobs["transfer"] == "auto" \
                and component == "both" and self.transfer_fits():
            if self.transfer_pays():
                # relighting: one O(P^3) solve now, one product per channel per frame after
                facts["transfer_seconds"] = self.precompute_transfer()
            elif self._inter_reflects:
                self._say_relighting_iterates()
        light_started = time.perf_counter()
        E = self.patch_irradiance(lights)
        facts["irradiance_seconds"] = time.perf_counter() - light_started
        solve_started = time.perf_counter()
        B, info = self.solve(E, component)
        facts["solve_seconds"] = time.perf_counter() - solve_started
        if component == "both" and info.get("solver") != "transfer":
            self._solve_seconds += facts["solve_seconds"]
        image_started = time.perf_counter()
        rgb = self.image(B, lights, component)
        facts["image_seconds"] = time.perf_counter() - image_started
        seconds = time.perf_counter() - started
        return Image(rgb.astype(np.float32), metadata={
            "producer": "radiosity", "component": component,
            "knobs": {k: v for k, v in self.knobs.items()}, "seconds": seconds,
            "patches": len(self.patches), "iterations": info.get("iterations", 0),
            "solver": info.get("solver"), "residual": info.get("residual"),
            "convergence": self.convergence, "skipped": list(self.log.skipped), **facts})

    def components(self, lights=None) -> dict[str, Image]:
        """Render the bounce decomposition of Sheng et al. 2014, Fig. 6, as images."""
        E = self.patch_irradiance(lights)
        out = {}
        for component in COMPONENTS:
            B, info = self.solve(E, component)
            out[component] = Image(self.image(B, lights, component).astype(np.float32),
                                   metadata={"producer": "radiosity", "component": component,
                                             "iterations": info.get("iterations", 0)})
        return out


