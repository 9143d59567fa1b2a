"""Translucent radiosity against Mitsuba volumetric path tracing (slow): regression gates."""

import pytest
from translucent.fast.radiosity import precompute
from translucent.materials.profiles import DipoleProfile

#: Samples per pixel of each reference pass and the number of passes (the variance of the
#: mean comes from the passes); unbounded path depth (the paper: 20). A depth limit of 64
#: darkens a high-albedo block by 16 % in red (measured at Skimmilk x 8): long diffusion
#: paths count.
REFERENCE_SPP, REFERENCE_PASSES, REFERENCE_DEPTH = 128, 4, -1

#: Regression gates, not accuracy claims: the values measured at 96 x 96 with the default
#: knobs against index-matched references (radiosity has no Fresnel reflection term, the
#: paper adds it in a separate pass), times 1.25. Cornell box: relative MSE 0.0078,
#: HDR-FLIP 0.162 (0.159 without the finite-object energy, whose gate 0.199 stays; floor
#: and walls within 1 % in their main channels, the block 6-9 % too dark, 11-14 % without,
#: the ceiling 8 % bright where the emitter's edge pixels differ). Bowl (Chicken1: a 6 mm
#: wall is one mean free path in red): relative MSE 0.0144, HDR-FLIP 0.193 (the bowl's
#: mean 1.08 / 0.89 / 0.77 of the reference; 0.83 / 0.62 / 0.63 and 0.024 / 0.267 without
#: the finite-object energy, where the dipole loses what leaves through the other face).
REFERENCE_GATES = {"cornell_block": {"relative_mse": 0.0097, "hdr_flip": 0.199},
                   "bowl": {"relative_mse": 0.018, "hdr_flip": 0.241}}


def _index_matched(scene, scale: float = 1.0):
    from translucent.materials import Dipole

    for obj in scene.objects:
        if isinstance(obj.material, Dipole):
            m = obj.material
            scene = scene.with_material(obj.name, Dipole(m.sigma_a, m.sigma_s_prime * scale,
                                                         1.0, m.g, name=m.name))
    return scene


def _reference(scene, **options):
    from translucent.reference import render

    return render(scene, spp=REFERENCE_SPP, passes=REFERENCE_PASSES,
                  max_depth=REFERENCE_DEPTH, progress=False, **options)


def _artifacts(tmp_path):
    import os
    from pathlib import Path

    folder = os.environ.get("TRANSLUCENT_ARTIFACTS")
    return Path(folder) / "radiosity" if folder else tmp_path


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(REFERENCE_GATES))
def test_against_volumetric_path_tracing(name, tmp_path):
    from translucent.reports.metrics.compute import evaluate
    from translucent.reports.metrics.maps import write_error_maps
    from translucent.scenes import load_scene

    scene = _index_matched(load_scene(name))
    reference = _reference(scene)
    test = precompute(scene).render()
    comparison = evaluate(reference, test)
    folder = _artifacts(tmp_path)
    write_error_maps(reference, test, folder, prefix=f"{name}_radiosity_")
    test.write(folder / f"{name}_radiosity.exr")
    reference.write(folder / f"{name}_reference.exr")
    metrics = comparison.metrics
    print(name, metrics)
    gate = REFERENCE_GATES[name]
    assert metrics.relative_mse <= gate["relative_mse"]
    assert metrics.hdr_flip <= gate["hdr_flip"]


#: The translucency sweep: Skimmilk's reduced scattering times these factors, from nearly
#: opaque (short mean free path) to very translucent; the target is the block's mean
#: radiance within 15 % of the reference at both ends. Measured (radiosity / reference,
#: R G B): x8 1.03 1.08 1.14, x0.25 0.96 0.94 0.90; without the finite-object energy
#: (knob ``finite_object_energy``) x8 1.00 1.05 1.12 and x0.25 0.77 0.81 0.72.
#:
#: Energy of the block's top patches, diffuse light entering:
#:
#: ======  =========================  ==========================  ==========================
#: scale   dipole total R_d (R G B)   S power column sums, mean   random walk in the 30 x 60
#:         (semi-infinite)            without the gain            x 30 mm box: light out
#: ======  =========================  ==========================  ==========================
#: x0.25   0.771 0.768 0.605          0.807 0.846 0.662           0.971 0.953 0.810
#: x1      0.878 0.877 0.778          0.949 0.925 0.796           0.973 0.958 0.865
#: x8      0.955 0.955 0.915          0.964 0.956 0.913           0.980 0.973 0.939
#: ======  =========================  ==========================  ==========================
#:
#: x0.25: a 5.7 mm mean free path (1 / sigma_tr = 37 mm in red) in a 30 mm block, where
#: the semi-infinite dipole sends 17-23 % of the light that the block re-emits into a
#: half-space that is not there (the limitation of Sheng et al. 2014, Sect. 7); the
#: diffusion gain in the block's own shape (translucent.fast.radiosity.diffusion_escape) gives back
#: 1.23 / 1.19 / 1.10 at the top face's centre, more near its edges.
#: x8: albedo 0.9997, where a reference with Russian roulette from depth 5 came out 4 / 11 /
#: 7 % darker than without (its heavy tail of long walks unconverged): the reference is
#: rendered without roulette (512 spp, relative standard error of the block mean 0.3 %;
#: about 30 minutes on 2 cores when the cache is cold).
SWEEP_BLOCK_RTOL = 0.15
SWEEP_SCALES = (8.0, 0.25)


@pytest.mark.slow
@pytest.mark.parametrize("scale", SWEEP_SCALES)
def test_translucency_sweep_matches_the_reference_at_both_ends(scale):
    """The block's mean radiance per channel against an index-matched reference."""
    from translucent.scenes import load_scene
    from translucent.scenes.gbuffer import gbuffer

    scene = _index_matched(load_scene("cornell_block"), scale)
    # no Russian roulette (the default above albedo 0.99): with roulette from depth 5 the
    # x8 reference came out 4 / 11 / 7 % darker (R, G, B), its heavy tail unconverged
    reference = _reference(scene)
    # the cut-off of the widest profile in the sweep (the default would be x1's, which
    # keeps 2.7 % of the x0.25 red profile beyond it)
    widest = min(SWEEP_SCALES)
    max_d = DipoleProfile(_index_matched(load_scene("cornell_block"), widest)
                          .object("block").material).support_radius(1e-3)
    state = precompute(_index_matched(load_scene("cornell_block")), max_distance_mm=max_d)
    test = state.render(material=scene.object("block").material)
    block = gbuffer(scene).mask("block")
    expected, got = reference.rgb[block].mean(axis=0), test.rgb[block].mean(axis=0)
    print(scale, expected, got, got / expected)
    assert got == pytest.approx(expected, rel=SWEEP_BLOCK_RTOL)


