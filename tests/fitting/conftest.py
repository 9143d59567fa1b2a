"""Shared fixtures of the fitting tests: small synthetic captures written to disk."""

import json

import numpy as np
import pytest
from translucent.fitting.capture import CaptureSpec, write_capture


def _sidecar(**changes):
    data = {"image": "capture.exr", "pixel_size_mm": 0.1, "incident_px": [16.0, 16.0],
            "side": "reflection", "thickness_mm": None, "eta": 1.3, "beam_radius_mm": 0.0,
            "black_level": 10.0, "saturation_level": 60000.0, "exposure": None}
    data.update(changes)
    return data


@pytest.fixture
def sidecar_data():
    """A valid sidecar as a dict (its image is written by ``write_sidecar``)."""
    return _sidecar()


@pytest.fixture
def write_sidecar(tmp_path):
    """Write a sidecar dict (and a 32 x 32 EXR beside it) and return the sidecar's path."""

    def write(data, *, image=True):
        path = tmp_path / "capture.json"
        if image:
            pixels = np.full((32, 32, 3), 100.0)
            spec = CaptureSpec(image="capture.exr", pixel_size_mm=0.1, incident_px=(16, 16))
            write_capture(path, pixels, spec)
        path.write_text(json.dumps(data))
        return path

    return write


@pytest.fixture(scope="module")
def small_capture():
    """A small dipole capture (40 x 40 px), its measured profile and its material."""
    from translucent.fitting.capture import Capture
    from translucent.fitting.profile import measure_profile
    from translucent.fitting.synthetic import Camera, dipole_capture
    from translucent.materials import Dipole

    material = Dipole(sigma_a=[0.05, 0.1, 0.2], sigma_s_prime=[1.0, 1.5, 2.0], eta=1.3)
    pixels, spec = dipole_capture(material, size=40, pixel_size_mm=0.2, seed=3,
                                  camera=Camera(peak_signal=30000))
    capture = Capture(spec, pixels)
    return capture, measure_profile(capture), material
