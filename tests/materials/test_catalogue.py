import pytest
from translucent.errors import InputError
from translucent.materials import MEASURED_MEDIA, measured_medium, measured_medium_names

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
