"""The helper modules this folder's tests share (``bssrdf_checks.py``, ...) are imported by name.

The tests run with ``--import-mode=importlib``, which puts no test folder on ``sys.path``;
this folder is put there for them.
"""

import sys
from pathlib import Path

import pytest

if str(Path(__file__).parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def bssrdf_mi():
    """Mitsuba with ``bssrdf_path`` registered (skipped under a scalar variant)."""
    from translucent.backend import mitsuba
    from translucent.reference import bssrdf_path

    module = mitsuba()
    if not module.variant().startswith(("llvm_", "cuda_")):
        pytest.skip("bssrdf_path needs a JIT variant")
    bssrdf_path.register()
    return module
