"""Every module's numpydoc Examples run as tests, found in the sources (no hand-kept list).

A module whose source has an Example (a ``>>>`` line) is imported and its examples run
with :func:`doctest.testmod`; the suite's own package is walked from the repository, so a
new module's Examples are run without an edit here. ``translucent.api``'s Examples, which
render and fit, run in tests/test_api.py (a file of their own, so that the two test
processes share the cost).
"""

import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Folders that are not the package.
NOT_PACKAGE = {"tests", "examples", "docs", "build"}

#: Run elsewhere (tests/test_api.py).
ELSEWHERE = {"translucent.api"}


def _modules_with_examples() -> list[str]:
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT).parts
        if parts[0] in NOT_PACKAGE or any(p.startswith(".") for p in parts):
            continue
        if ">>> " not in path.read_text(encoding="utf-8"):
            continue
        name = ".".join(("translucent",) + path.relative_to(ROOT).with_suffix("").parts)
        name = name.removesuffix(".__init__")
        if name not in ELSEWHERE:
            found.append(name)
    return found


MODULES = _modules_with_examples()


def test_examples_are_found_in_every_concept():
    concepts = {name.split(".")[1] for name in MODULES}
    assert {"fast", "materials", "reports", "scenes"} <= concepts, concepts


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_run(name):
    module = importlib.import_module(name)
    failures, tried = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0, f"{name} has a '>>> ' line but no Example doctest finds"
    assert failures == 0
