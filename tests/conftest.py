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
    """Write an RGB EXR as another program would: no checksum, NaN and Inf kept.

    :func:`translucent.image.write_exr` refuses non-finite pixels, so files that a reader
    must refuse are made this way.
    """
    def write(path, rgb):
        import OpenEXR

        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        with OpenEXR.File(header, {"RGB": np.ascontiguousarray(rgb, np.float32)}) as exr:
            exr.write(str(path))
        return path

    return write
