"""The directional dipole: against an independent 3D evaluation, its symmetries, its average."""

import numpy as np
import pytest
from translucent.errors import InputError
from translucent.materials import Dipole, measured_medium
from translucent.materials.profiles import DirectionalDipoleProfile, profile
from translucent.materials.profiles.boundary import exitance_weights

#: The extrapolation distance of Frisvad et al. 2014, Eq. 21: d_e = 2.131 D / sqrt(alpha').
EXTRAPOLATION_CONSTANT = 2.131


def _frisvad(medium, xi, ni, wi, xo, no):
    """Frisvad et al.'s BSSRDF S_d in 3D vectors, as appleseed's bssrdf() writes it.

    Returned times 4 pi C_phi(1 / eta): the exitance per unit power entering.
    """
    eta = medium.eta
    c_phi, c_e = exitance_weights(eta)
    c_phi_outside, _ = exitance_weights(1 / eta)
    a = (1 - c_e) / (2 * c_phi)
    x = xo - xi
    r2 = x @ x
    ni_star = np.cross(x / np.sqrt(r2), np.cross(ni, x) / np.linalg.norm(np.cross(ni, x)))
    # refraction into the medium (wi points away from the surface, outside)
    cos_i = wi @ ni
    sin2_t = (1 - cos_i**2) / eta**2
    wr = -wi / eta + (cos_i / eta - np.sqrt(1 - sin2_t)) * ni
    wv = wr - 2 * (wr @ ni_star) * ni_star
    out = []
    for c in range(3):
        sa, ss = medium.sigma_a[c], medium.sigma_s_prime[c]
        st = sa + ss
        d = 1 / (3 * st)
        sigma_tr = np.sqrt(3 * sa * st)
        de = EXTRAPOLATION_CONSTANT * d / np.sqrt(ss / st)
        cos_beta = -np.sqrt((r2 - (x @ wr) ** 2) / (r2 + de * de))
        mu0 = -(wr @ no)
        dr = np.sqrt(r2 + d * mu0 * (d * mu0 - 2 * de * cos_beta))
        xv = xi + 2 * a * de * ni_star
        xoxv = xo - xv
        dv = np.linalg.norm(xoxv)

        def term(dot_w_x, dot_w_n, dot_x_n, r, d=d, sigma_tr=sigma_tr):
            s = sigma_tr * r
            return np.exp(-s) / (4 * np.pi**2 * r**3) * (
                c_phi * (r * r / d + 3 * (1 + s) * dot_w_x)
                - c_e * (3 * d * (1 + s) * dot_w_n
                         - (1 + s + 3 * d * (3 * (1 + s) + s * s) / (r * r) * dot_w_x) * dot_x_n))

        sd = term(x @ wr, wr @ no, x @ no, dr) - term(wv @ xoxv, wv @ no, xoxv @ no, dv)
        out.append(max(sd / (4 * c_phi_outside), 0.0) * 4 * np.pi * c_phi_outside)
    return np.array(out)


@pytest.mark.parametrize("angle", [0.0, 0.4, 1.2])
def test_the_planar_profile_is_the_3d_formula(angle):
    medium = measured_medium("Skin1")
    made = DirectionalDipoleProfile(medium, angle)
    normal = np.array([0.0, 0.0, 1.0])
    incoming = np.array([-np.sin(angle), 0.0, np.cos(angle)])  # light travels towards +x
    for x, y in [(0.3, 0.0), (-0.7, 0.2), (0.05, -1.5), (2.0, 2.0)]:
        expected = _frisvad(medium, np.zeros(3), normal, incoming, np.array([x, y, 0.0]),
                            normal)
        assert made.evaluate(x, y) == pytest.approx(expected, rel=1e-12, abs=1e-300)


def test_normal_incidence_is_radial_and_oblique_incidence_leans_forward():
    medium = measured_medium("Marble")
    normal = DirectionalDipoleProfile(medium, 0.0)
    phi = np.linspace(0, 2 * np.pi, 9)
    ring = normal.evaluate(np.cos(phi), np.sin(phi))
    assert ring == pytest.approx(np.broadcast_to(ring[0], ring.shape), rel=1e-12)
    assert normal.radial_average().reflection(1.0) == pytest.approx(ring[0], rel=1e-4)
    oblique = DirectionalDipoleProfile(medium, 1.0)
    assert np.all(oblique.evaluate(1.0, 0.0) > oblique.evaluate(-1.0, 0.0))
    assert oblique.evaluate(0.5, 0.7) == pytest.approx(oblique.evaluate(0.5, -0.7), rel=1e-14)


def test_the_radial_average_is_the_mean_over_azimuth():
    made = DirectionalDipoleProfile(measured_medium("Skin1"), 0.8)
    average = made.radial_average()
    phi = np.linspace(0, 2 * np.pi, 4097)[:-1]
    for r in (0.05, 0.5, 3.0):
        mean = made.evaluate(r * np.cos(phi), r * np.sin(phi)).mean(axis=0)
        assert average.average(np.array([r]))[0] == pytest.approx(mean, rel=1e-6)
        assert average.reflection(r) == pytest.approx(mean, rel=1e-3)


def test_parameters_come_from_the_medium():
    medium = Dipole([0.01, 0.1, 1.0], 2.0, eta=1.4)
    made = profile("directional_dipole", medium)
    sigma_t = medium.sigma_a + 2.0
    assert made.diffusion == pytest.approx(1 / (3 * sigma_t))
    assert made.sigma_tr == pytest.approx(np.sqrt(3 * medium.sigma_a * sigma_t))
    assert made.extrapolation == pytest.approx(
        EXTRAPOLATION_CONSTANT * made.diffusion / np.sqrt(2.0 / sigma_t))
    assert made.direction[2] == pytest.approx(-1.0)
    tilted = DirectionalDipoleProfile(medium, np.pi / 3)
    assert tilted.direction[0] == pytest.approx(np.sin(np.pi / 3) / 1.4)  # Snell
    assert "d_e" in made.describe()


def test_bad_input_is_named():
    with pytest.raises(InputError, match="incident_angle = 1.6: must lie in \\[0, pi/2\\)"):
        DirectionalDipoleProfile(measured_medium("Marble"), 1.6)
    with pytest.raises(InputError, match="incident_angle = nan"):
        DirectionalDipoleProfile(measured_medium("Marble"), float("nan"))
