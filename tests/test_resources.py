"""Memory estimated before work: jobs the machine cannot hold are refused, naming the option."""

import pytest
from translucent import resources
from translucent.errors import InputError
from translucent.reports.cli import main

#: What the tests pretend the machine has free (the estimates do not depend on it).
PRETEND_AVAILABLE = 8 * 2**30


@pytest.fixture
def eight_gib(monkeypatch):
    monkeypatch.setattr(resources, "available_memory", lambda: PRETEND_AVAILABLE)


def _sphere_file(tmp_path, size):
    from pathlib import Path

    from translucent.scenes import load_scene

    scene = Path(load_scene("sphere").source).read_text(encoding="utf-8")
    scene = scene.replace("width = 96", f"width = {size}").replace("height = 96",
                                                                    f"height = {size}")
    path = tmp_path / "big.toml"
    path.write_text(scene)
    return path


def test_a_render_too_large_for_the_machine_is_refused_before_work(eight_gib, tmp_path,
                                                                    capsys):
    out = tmp_path / "out.exr"
    code = main(["render", str(_sphere_file(tmp_path, 16384)), "--spp", "1", "--out",
                 str(out)])
    err = capsys.readouterr().err
    assert code == 2
    assert "camera = '16384 x 16384': a 16384 x 16384 render needs about 64.0 GiB" in err
    assert "8.0 GiB available" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("arguments, words", [
    (["--size", "20000"], "--size = 20000: a 20000 x 20000 capture needs about 71.5 GiB"),
    (["--photons", "1e15"], "--photons = 1000000000000000.0: a walk of 1e+15 photons at once"),
    (["--photons", "1e8"], "--photons = 100000000.0: a walk of 1e+08 photons at once needs "
                           "about 95.4 GiB"),
])
def test_a_capture_too_large_for_the_machine_is_refused(eight_gib, tmp_path, capsys, arguments,
                                                        words):
    out = tmp_path / "capture.json"
    assert main(["capture", "skin1", "--out", str(out), *arguments]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_the_photon_walk_checks_its_memory(eight_gib):
    from translucent.fitting.random_walk import photon_random_walk
    from translucent.materials import measured_medium

    with pytest.raises(InputError, match="photons = 10000000000: a walk of 10,000,000,000"):
        photon_random_walk(measured_medium("Skin1"), photons=10**10)


def test_what_fits_is_not_refused(eight_gib):
    resources.check_memory(PRETEND_AVAILABLE * 0.5, what="half", field="x", value=1)
    with pytest.raises(InputError, match="x = 1: more than is there needs about"):
        resources.check_memory(PRETEND_AVAILABLE * 0.9, what="more than is there", field="x",
                               value=1)


def test_available_memory_is_a_positive_count():
    available = resources.available_memory()
    assert available is None or available > 0


def test_a_radiosity_precomputation_too_large_is_refused_before_its_samples(eight_gib,
                                                                           capsys):
    # the sphere keeps all 5120^2 patch pairs: about 7.8 GiB at 320 bytes a pair
    assert main(["approx", "radiosity", "sphere", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "max_distance_mm = 28.67" in err and "26,219,520 scattering pairs" in err
    assert "needs about 7.8 GiB" in err and "Traceback" not in err


def test_the_radiosity_pair_count_bounds_the_stored_entries():
    from translucent.fast.conformance import tiny_sphere_text
    from translucent.fast.radiosity.form_factors import build_patches
    from translucent.fast.radiosity.method import precompute, scattering_pairs
    from translucent.scenes import loads_scene

    scene = loads_scene(tiny_sphere_text(size=16))
    state = precompute(scene, max_distance_mm=6.0)
    patches = build_patches(scene, triangles_per_patch=1, two_sided=[])
    pairs = scattering_pairs(patches, [0], [], 6.0)
    # the candidates by centroid: at least what is kept, and not much more (17320, 16040)
    assert state.geometry.nnz <= pairs <= 1.1 * state.geometry.nnz


def test_a_prt_transfer_too_large_is_refused_before_its_first_pass(eight_gib):
    from translucent.fast.prt.method import precompute
    from translucent.scenes import load_scene

    with pytest.raises(InputError, match=r"terms = 262144: the PRT transfer of 'sphere' "
                                         r"\(2562 vertices x 13 rows x 262144 coefficients "
                                         r"at most\) needs about 65.1 GiB"):
        precompute(load_scene("sphere"), terms=1 << 18, samples=1 << 18)
