"""Shared fixtures: a seeded RNG, a private cache folder."""

import numpy as np
import pytest


@pytest.fixture
def rng():
    """A seeded generator: every stochastic test is reproducible."""
    return np.random.default_rng(20260101)


@pytest.fixture(autouse=True)
def _private_cache(tmp_path_factory, monkeypatch):
    """Tests never touch the user's cache unless TRANSLUCENT_CACHE is set by the runner."""
    import os

    if not os.environ.get("TRANSLUCENT_CACHE"):
        monkeypatch.setenv("TRANSLUCENT_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))
