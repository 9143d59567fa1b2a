"""Shared fixtures: a seeded RNG, a private cache folder."""

import os

import numpy as np
import pytest


def pytest_configure(config):
    """Tests never touch the user's cache unless the runner sets TRANSLUCENT_CACHE.

    Set here, before any fixture (module- and session-scoped ones too) can precompute
    something and store it.
    """
    if not os.environ.get("TRANSLUCENT_CACHE"):
        base = config._tmp_path_factory.getbasetemp() if hasattr(config, "_tmp_path_factory") \
            else None
        if base is None:
            import tempfile

            base = tempfile.mkdtemp(prefix="translucent-test-")
        os.environ["TRANSLUCENT_CACHE"] = os.path.join(str(base), "cache")


@pytest.fixture
def rng():
    """A seeded generator: every stochastic test is reproducible."""
    return np.random.default_rng(20260101)


@pytest.fixture
def write_foreign_exr():
    """Write an EXR as another program would: no checksum, NaN and Inf kept.

    :func:`translucent.image.write_exr` refuses non-finite pixels and always writes R, G
    and B, so files that a reader must refuse are made this way. ``channels`` is an
    (H, W, 3) array (written as RGB) or a dict of channel name to plane.
    """
    def write(path, channels):
        import OpenEXR

        if not isinstance(channels, dict):
            channels = {"RGB": channels}
        planes = {name: np.ascontiguousarray(plane, np.float32)
                  for name, plane in channels.items()}
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, planes) as exr:
            exr.write(str(path))
        return path

    return write
