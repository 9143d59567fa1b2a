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
