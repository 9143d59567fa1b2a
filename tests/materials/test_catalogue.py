from pathlib import Path

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import MEASURED_MEDIA, Dipole, measured_medium, measured_medium_names
from translucent.materials.catalogue import (
    MEDIUM_ALIASES,
    NARASIMHAN_ETA,
    NARASIMHAN_MEDIA,
    canonical_medium_name,
    effective_g,
    measured_medium_entry,
)

# Jensen et al. 2001, Table 1, at the table's own precision (mm^-1): sigma_s', sigma_a.
PUBLISHED = {
    "Apple": ((2.29, 2.39, 1.97), (0.0030, 0.0034, 0.046)),
    "Chicken1": ((0.15, 0.21, 0.38), (0.015, 0.077, 0.19)),
    "Ketchup": ((0.18, 0.07, 0.03), (0.061, 0.97, 1.45)),
    "Marble": ((2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)),
    "Spectralon": ((11.6, 20.4, 14.9), (0.0, 0.0, 0.0)),
}


def test_twelve_materials():
    assert len(measured_medium_names()) == 12


@pytest.mark.parametrize("name", PUBLISHED)
def test_published_values(name):
    medium = measured_medium(name)
    sigma_s_prime, sigma_a = PUBLISHED[name]
    assert medium.sigma_s_prime.tolist() == pytest.approx(sigma_s_prime, abs=5e-5)
    assert medium.sigma_a.tolist() == pytest.approx(sigma_a, abs=5e-5)


def test_eta_is_1_3_except_marble():
    for name in MEASURED_MEDIA:
        assert measured_medium(name).eta == (1.5 if name == "Marble" else 1.3)
        assert measured_medium(name).g == 0.0


def test_chicken_red_absorption_is_pbrt_value_not_mitsuba_typo():
    assert measured_medium("chicken1").sigma_a[0] == 0.015
    assert measured_medium("chicken2").sigma_a[0] == 0.018


def test_names_are_case_insensitive():
    assert measured_medium("wHoLeMiLk").name == "Wholemilk"


def test_unknown_name_lists_valid_ones():
    with pytest.raises(InputError, match="valid names: Apple, Chicken1"):
        measured_medium("jelly")


# --- Narasimhan et al. 2006 ------------------------------------------------------------

# Narasimhan, Gupta, Donner, Ramamoorthi, Nayar, Jensen: "Acquiring scattering properties
# of participating media by dilution", SIGGRAPH 2006, Table 1: the media pbrt-v4
# (src/pbrt/media.cpp) and Mitsuba 0.6 (src/medium/materials.h) carry by name, in order,
# as pbrt-v4 spells them.
NARASIMHAN_NAMES = [
    "Lowfat Milk", "Reduced Milk", "Regular Milk", "Espresso", "Mint Mocha Coffee",
    "Lowfat Soy Milk", "Regular Soy Milk", "Lowfat Chocolate Milk", "Regular Chocolate Milk",
    "Coke", "Pepsi", "Sprite", "Gatorade", "Chardonnay", "White Zinfandel", "Merlot",
    "Budweiser Beer", "Coors Light Beer", "Clorox", "Apple Juice", "Cranberry Juice",
    "Grape Juice", "Ruby Grapefruit Juice", "White Grapefruit Juice", "Shampoo",
    "Strawberry Shampoo", "Head & Shoulders Shampoo", "Lemon Tea Powder", "Orange Powder",
    "Pink Lemonade Powder", "Cappuccino Powder", "Salt Powder", "Sugar Powder",
    "Suisse Mocha Powder", "Pacific Ocean Surface Water",
]

# pbrt-v4 src/pbrt/media.cpp, SubsurfaceParameterTable (natural concentration, mm^-1):
# sigma_prime_s, sigma_a, as printed there.
PBRT_V4 = {
    "Lowfat Milk": ((0.89187, 1.5136, 2.532), (0.002875, 0.00575, 0.0115)),
    "Espresso": ((0.72378, 0.84557, 1.0247), (4.7984, 6.5751, 8.8493)),
    "Coke": ((8.9053e-05, 8.372e-05, 0), (0.10014, 0.16503, 0.2468)),
    "Merlot": ((2.1129e-05, 0, 0), (0.11632, 0.25191, 0.29434)),
    "Head & Shoulders Shampoo": ((0.023805, 0.028804, 0.034306),
                                 (0.084621, 0.15688, 0.20365)),
    "Cappuccino Powder": ((1.8436, 2.5851, 2.1662), (35.844, 49.547, 61.084)),
    "Pacific Ocean Surface Water": ((0.0001764, 0.00032095, 0.00019617),
                                    (0.031845, 0.031324, 0.030147)),
}

# Mitsuba 0.6 src/medium/materials.h, materialData (natural concentration, mm^-1 before
# its own x100): sigmaS, sigmaA, g, as printed there; eta 1.33 for all.
MITSUBA_0_6 = {
    "Lowfat Milk": ((13.1157, 15.4445, 17.9572), (0.00287, 0.00575, 0.01150),
                    (0.932, 0.902, 0.859)),
    "Espresso": ((7.78262, 8.13050, 8.53875), (4.79838, 6.57512, 8.84925),
                 (0.907, 0.896, 0.880)),
    "Coke": ((0.00254, 0.00299, 0.0), (0.10014, 0.16503, 0.24680), (0.965, 0.972, 0.0)),
    "Merlot": ((0.00081, 0.0, 0.0), (0.11632, 0.25191, 0.29434), (0.974, 0.0, 0.0)),
    "Head & Shoulders Shampoo": ((0.26747, 0.27696, 0.29574), (0.08462, 0.15688, 0.20365),
                                 (0.911, 0.896, 0.884)),
    "Cappuccino Powder": ((12.2094, 16.4659, 29.2727), (35.8441, 49.5470, 61.0844),
                          (0.849, 0.843, 0.926)),
    "Pacific Ocean Surface Water": ((0.00180, 0.00183, 0.00228), (0.03184, 0.03132, 0.03015),
                                    (0.902, 0.825, 0.914)),
}

#: How far two printings of one coefficient may differ, mm^-1: pbrt-v4 rounds to five
#: significant digits (at most 5e-5 relative), Mitsuba 0.6 to five decimals (5e-6).
PRINTING_RELATIVE = 5e-5
PRINTING_ABSOLUTE = 5e-6


def _agree_to_the_printings(ours, theirs):
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    return np.all(np.abs(ours - theirs) <= PRINTING_RELATIVE * np.abs(ours) + PRINTING_ABSOLUTE)


def test_narasimhan_table_is_the_renderers_set():
    assert measured_medium_names("narasimhan2006") == NARASIMHAN_NAMES
    assert list(NARASIMHAN_MEDIA) == NARASIMHAN_NAMES
    assert measured_medium_names("all") == [*MEASURED_MEDIA, *NARASIMHAN_NAMES]
    assert measured_medium_names() == list(MEASURED_MEDIA)  # the default stays Jensen's 12


def test_unknown_table_lists_valid_ones():
    with pytest.raises(InputError, match="valid: jensen2001, narasimhan2006, all"):
        measured_medium_names("narasimhan")


@pytest.mark.parametrize("name", measured_medium_names("all"))
def test_every_medium_loads(name):
    medium = measured_medium(name)
    assert isinstance(medium, Dipole) and medium.name == name
    assert 0.0 <= medium.g < 1.0
    profile = medium.profile(np.array([0.01, 1.0, 10.0]))
    assert np.all(np.isfinite(profile)) and np.all(profile >= 0)
    reflectance = medium.total_diffuse_reflectance()
    assert np.all((reflectance >= 0) & (reflectance <= 1))


@pytest.mark.parametrize("name", PBRT_V4)
def test_values_are_pbrt_v4s(name):
    """pbrt-v4's sigma_prime_s and sigma_a of Narasimhan et al. 2006, Table 1, as printed."""
    sigma_s_prime, sigma_a = PBRT_V4[name]
    entry, medium = measured_medium_entry(name), measured_medium(name)
    assert entry.sigma_s_prime.tolist() == list(sigma_s_prime)
    assert entry.sigma_a.tolist() == list(sigma_a)
    assert medium.sigma_s_prime.tolist() == list(sigma_s_prime)
    assert medium.sigma_a.tolist() == list(sigma_a)


@pytest.mark.parametrize("name", MITSUBA_0_6)
def test_values_agree_with_mitsuba_0_6(name):
    """Mitsuba 0.6's sigma_s, sigma_a and g of Narasimhan et al. 2006, Table 1.

    g is Table 1's, to its three decimals: equal. sigma_s = sigma_s' / (1 - g) and sigma_a
    agree to the two renderers' roundings.
    """
    sigma_s, sigma_a, g = MITSUBA_0_6[name]
    entry = measured_medium_entry(name)
    assert entry.g.tolist() == list(g)
    assert _agree_to_the_printings(entry.sigma_s, sigma_s)
    assert _agree_to_the_printings(entry.sigma_a, sigma_a)
    assert entry.eta == NARASIMHAN_ETA == measured_medium(name).eta == 1.33


@pytest.mark.parametrize("name", NARASIMHAN_NAMES)
def test_g_and_the_reduced_coefficient(name):
    entry, medium = measured_medium_entry(name), measured_medium(name)
    assert entry.table == "narasimhan2006"
    assert np.all((entry.g >= 0) & (entry.g < 1))
    assert entry.sigma_s_prime == pytest.approx(entry.sigma_s * (1 - entry.g), rel=1e-12)
    # the Dipole keeps the published sigma_s' per channel and one g ...
    assert np.array_equal(medium.sigma_s_prime, entry.sigma_s_prime)
    assert medium.g == effective_g(entry.sigma_s_prime, entry.g)
    assert medium.sigma_s_prime == pytest.approx(medium.sigma_s * (1 - medium.g), rel=1e-12)
    # ... for which the channels' summed sigma_s is the table's
    assert medium.sigma_s.sum() == pytest.approx(entry.sigma_s.sum(), rel=1e-12)
    scattering = entry.sigma_s > 0
    assert entry.g[scattering].min() - 1e-12 <= medium.g <= entry.g[scattering].max() + 1e-12


def test_effective_g():
    assert effective_g([1.0, 2.0, 3.0], [0.8, 0.8, 0.8]) == pytest.approx(0.8, abs=1e-15)
    assert effective_g([0.0, 0.0, 0.0], [0.9, 0.9, 0.9]) == 0.0
    # a channel that does not scatter has no say
    assert effective_g([0.1, 0.1, 0.0], [0.9, 0.9, 0.0]) == pytest.approx(0.9, abs=1e-15)
    # weighted by sigma_s = sigma_s' / (1 - g): (1 * 0.5 + 1 * 0.75) / (1 + 1)
    assert effective_g([0.5, 0.25, 0.0], [0.5, 0.75, 0.0]) == pytest.approx(0.625, abs=1e-15)


def test_jensen_entries_have_no_anisotropy():
    entry = measured_medium_entry("marble")
    assert entry.table == "jensen2001" and entry.g.tolist() == [0.0, 0.0, 0.0]
    assert np.array_equal(entry.sigma_s, entry.sigma_s_prime)
    assert measured_medium("Marble").g == 0.0


@pytest.mark.parametrize("spelling, name", [
    ("lowfat milk", "Lowfat Milk"), ("LOWFAT_MILK", "Lowfat Milk"), ("LowfatMilk", "Lowfat Milk"),
    ("lowfat-milk", "Lowfat Milk"), ("  Espresso ", "Espresso"),
    ("head_and_shoulders_shampoo", "Head & Shoulders Shampoo"),
    ("Head&Shoulders Shampoo", "Head & Shoulders Shampoo"),
    ("Orange Juice Powder", "Orange Powder"), ("Budweiser Beder", "Budweiser Beer"),
    ("skin_1", "Skin1"), ("Whole Milk", "Wholemilk"), ("apple", "Apple"),
    ("apple_juice", "Apple Juice"),
])
def test_names_are_found_however_spelled(spelling, name):
    assert canonical_medium_name(spelling) == name
    assert measured_medium(spelling).name == name


def test_no_two_names_fold_together():
    """Every name and alias of both tables is found as itself: none shadows another."""
    names = measured_medium_names("all")
    assert all(canonical_medium_name(name) == name for name in names)
    assert all(canonical_medium_name(alias) == name for alias, name in MEDIUM_ALIASES.items())
    assert len(set(names) | set(MEDIUM_ALIASES)) == len(names) + len(MEDIUM_ALIASES) == 49
    assert canonical_medium_name("jelly") is None


def test_unknown_name_lists_both_tables():
    with pytest.raises(InputError, match="Wholemilk, Lowfat Milk, .*Pacific Ocean Surface Water"):
        measured_medium("Lowfat Jelly")


def test_a_scene_file_names_one(tmp_path):
    from translucent.scenes import load_scene

    path = tmp_path / "milk.toml"
    path.write_text(SPHERE_SCENE.format(name="lowfat_milk"), encoding="utf-8")
    material = load_scene(path).objects[0].material
    assert material.name == "Lowfat Milk" and material.eta == 1.0
    assert np.array_equal(material.sigma_s_prime, measured_medium("Lowfat Milk").sigma_s_prime)
    assert material.g == measured_medium("Lowfat Milk").g > 0.8
    path.write_text(SPHERE_SCENE.format(name="Lowfat Jelly"), encoding="utf-8")
    with pytest.raises(InputError, match="objects\\[0\\].material.name.*valid names: Apple"):
        load_scene(path)


SPHERE_SCENE = """
[scene]
mm_per_unit = 10.0

[camera]
origin = [0.0, 0.0, 5.0]
target = [0.0, 0.0, 0.0]
width = 8
height = 8

[[objects]]
name = "sphere"
mesh = {{ type = "icosphere", subdivisions = 1 }}
material = {{ type = "measured", name = "{name}", eta = 1.0 }}

[[lights]]
type = "point"
position = [3.0, 4.0, 4.0]
intensity = 100.0
"""


def test_the_commands_take_a_narasimhan_medium_by_its_name(tmp_path, capsys):
    from translucent.reports.cli import main

    # the name the command is given, with its space, is the catalogue's
    assert measured_medium("Lowfat Milk").name == "Lowfat Milk"
    assert main(["approx", "prt", "sphere", "--material", "Lowfat Jelly", "--out",
                 str(tmp_path / "jelly.exr")]) == 2
    assert "valid names: Apple" in capsys.readouterr().err
    assert not (tmp_path / "jelly.exr").exists()


@pytest.mark.slow  # 12 s of PRT's kernels in this process; the fast tier keeps the name check
def test_the_prt_command_renders_one(tmp_path, capsys):
    from translucent.image import Image
    from translucent.reports.cli import main
    from translucent.scenes import load_scene

    # the built-in sphere at 16 x 16 pixels on its coarsest mesh: the name is what is checked
    scene = tmp_path / "tiny.toml"
    scene.write_text(Path(load_scene("sphere").source).read_text(encoding="utf-8")
                     .replace("width = 96", "width = 16").replace("height = 96", "height = 16")
                     .replace("subdivisions = 4", "subdivisions = 1"), encoding="utf-8")
    out = tmp_path / "milk.exr"
    assert main(["approx", "prt", str(scene), "--material", "Lowfat Milk", "--samples", "256",
                 "--no-progress", "--out", str(out)]) == 0
    rgb = Image.read(out).rgb
    assert np.all(np.isfinite(rgb)) and rgb.mean() > 0
    assert main(["approx", "prt", str(scene), "--material", "Lowfat Jelly", "--out",
                 str(tmp_path / "jelly.exr")]) == 2
    assert "valid names: Apple" in capsys.readouterr().err


def test_a_narasimhan_medium_is_saved_by_its_name():
    from translucent.materials.factory import material_from_dict, material_to_dict

    milk = measured_medium("lowfat_milk")
    saved = material_to_dict(milk)
    assert saved == {"type": "measured", "name": "Lowfat Milk"}
    loaded = material_from_dict(saved)
    for field in ("sigma_a", "sigma_s_prime"):
        assert np.array_equal(getattr(loaded, field), getattr(milk, field))
    assert (loaded.g, loaded.eta, loaded.name) == (milk.g, milk.eta, milk.name)
