"""``import translucent``: the functions of the command line, and their Examples run."""

import doctest
import importlib

import pytest
import translucent


# Every other module's Examples run in tests/test_doctests.py. These render, precompute
# radiosity and fit a capture (26 s): slow tier; the functions they call are tested in the
# fast tier by the tests of their modules.
@pytest.mark.slow
def test_the_examples_run():
    module = importlib.import_module("translucent.api")
    failures, tried = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert tried > 0, "translucent.api has no Examples"
    assert failures == 0


def test_the_package_offers_the_commands_functions():
    for name in ("load_scene", "render", "compare", "approx", "method", "fit", "Image",
                 "InputError"):
        assert name in translucent.__all__ and callable(getattr(translucent, name)), name
    with pytest.raises(AttributeError):
        translucent.no_such_function  # noqa: B018


def test_bad_input_is_an_input_error_naming_the_field(tmp_path):
    with pytest.raises(translucent.InputError, match="scene"):
        translucent.load_scene("no_such_scene")
    with pytest.raises(translucent.InputError, match="unknown fast method"):
        translucent.approx("no_such_method", "sphere")
    with pytest.raises(translucent.InputError, match="reference"):
        translucent.compare(3, 4)
    with pytest.raises(translucent.InputError, match="budget_seconds"):
        translucent.render("furnace_sphere", budget_seconds=10)
    with pytest.raises(translucent.InputError, match="unknown knob"):
        translucent.approx("radiosity", "sphere", no_such_knob=1)
