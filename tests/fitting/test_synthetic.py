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
