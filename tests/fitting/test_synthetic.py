"""Synthetic captures of the exact dipole model: what a bad argument does."""

import pytest
from translucent.errors import InputError
from translucent.fitting.synthetic import dipole_capture
from translucent.materials import Dipole

MEDIUM = Dipole(sigma_a=0.3, sigma_s_prime=1.0, eta=1.3, name="test")


@pytest.mark.parametrize("incident", [(40.0, 8.0), (8.0, -1.0), (float("nan"), 8.0)])
def test_an_incident_point_outside_the_image_is_refused(incident):
    # the fitter refuses such a sidecar; the generator must not write it
    with pytest.raises(InputError, match="must lie inside the 16 x 12 image") as error:
        dipole_capture(MEDIUM, size=(12, 16), pixel_size_mm=0.2, incident_px=incident)
    assert error.value.field == "incident_px"


@pytest.mark.parametrize("option, field", [
    ({"pixel_size_mm": float("inf")}, "pixel_size_mm"),
    ({"pixel_size_mm": 0.0}, "pixel_size_mm"),
    ({"thickness_mm": float("inf")}, "thickness_mm"),
    ({"beam_radius_mm": float("inf")}, "beam_radius_mm"),
    ({"beam_radius_mm": float("nan")}, "beam_radius_mm"),
])
def test_non_finite_geometry_names_its_field(option, field):
    # it failed later as "the exitance image is black", a field the caller never gave
    options = {"size": 16, "pixel_size_mm": 0.2, **option}
    with pytest.raises(InputError, match="finite") as error:
        dipole_capture(MEDIUM, **options)
    assert error.value.field == field


@pytest.mark.parametrize("field", ["peak_signal", "saturation_level", "gain", "read_noise",
                                   "black_level"])
def test_an_infinite_camera_setting_is_called_not_finite(field):
    from translucent.fitting.synthetic import Camera

    # "inf: must be > 0" told the user nothing
    with pytest.raises(InputError, match="must be finite and >") as error:
        Camera(**{field: float("inf")})
    assert error.value.field == field


@pytest.mark.parametrize("peak_signal, gain", [(1e20, 1.0), (1e6, 1e14)])
def test_shot_noise_of_a_huge_signal_is_simulated_not_a_crash(peak_signal, gain):
    import numpy as np
    from translucent.fitting.synthetic import Camera

    # numpy's Poisson sampler refuses means beyond ~9e18 ("lam value too large")
    stored, spec = dipole_capture(MEDIUM, size=16, pixel_size_mm=0.2, seed=1,
                                  camera=Camera(peak_signal=peak_signal, gain=gain,
                                                saturation_level=1e30))
    signal = stored - spec.black_level
    assert np.all(np.isfinite(stored))
    assert signal.max() == pytest.approx(peak_signal, rel=1e-3)
