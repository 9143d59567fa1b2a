"""The photon random walk's profile, read from the table that moved to materials/data."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import RandomWalkProfile, profile
from translucent.materials.profiles.random_walk import TABLE_PATH, load_table

#: The per-channel lookup against the walk table read directly: nodes 0.68 % apart over a
#: profile that is piecewise linear in (ln r, ln R) between ring centres; measured at most
#: 3e-4 inside the radius holding 99 % of the energy (Marble, Skin1, Ketchup).
LOOKUP_RTOL = 1e-3


def test_the_table_ships_with_materials():
    assert TABLE_PATH.parent.name == "data" and TABLE_PATH.parent.parent.name == "materials"
    assert TABLE_PATH.is_file()
    table = load_table()
    assert table.etas[0] == 1.0 and table.etas[-1] == 2.0


def test_the_fitter_keeps_its_names():
    from translucent.fitting import walk_table

    assert walk_table.load_table() is load_table()
    assert walk_table.TABLE_PATH == TABLE_PATH
    for name in ("WalkProfileTable", "asymptotic_attenuation", "single_scattering",
                 "ring_edges", "attenuation_grid", "build_table", "save_table"):
        assert callable(getattr(walk_table, name))


def test_it_is_the_reduced_table_scaled_by_the_extinction():
    medium = measured_medium("Skin2")
    made = RandomWalkProfile(medium)
    table = load_table()
    sigma_t = medium.sigma_a + medium.sigma_s_prime
    r = np.array([0.01, 0.3, 2.0])
    for channel in range(3):
        albedo = medium.sigma_s_prime[channel] / sigma_t[channel]
        reduced = table.reduced_profile(sigma_t[channel] * r, albedo, medium.eta)
        assert made.reflection_exact(r)[:, channel] == pytest.approx(
            sigma_t[channel] ** 2 * reduced, rel=1e-12)


def test_the_lookup_reads_the_table():
    for name in ("Marble", "Skin1", "Ketchup"):
        made = profile("random_walk", name)
        inside = made.radius_containing(0.99)
        for channel in range(3):
            r = np.geomspace(1e-4, 1.0, 400) * inside[channel]
            assert made.reflection(r)[:, channel] == pytest.approx(
                made.reflection_exact(r)[:, channel], rel=LOOKUP_RTOL)


def test_the_total_is_the_tables_energy():
    # the table's own cumulative, walked out to 64 mean free paths: the profile integrates
    # its interpolated rows instead (0.26 % apart here, measured)
    medium = Dipole(0.05, 1.0, eta=1.3)
    made = RandomWalkProfile(medium)
    table = load_table()
    inside = table.reduced_cumulative(64.0, 1.0 / 1.05, 1.3)
    assert made.total()[0] == pytest.approx(float(inside), rel=0.01)


def test_an_eta_outside_the_table_is_refused():
    with pytest.raises(InputError, match="eta = 2.5: the walk table covers eta 1 .. 2"):
        RandomWalkProfile(Dipole(0.1, 1.0, eta=2.5))
