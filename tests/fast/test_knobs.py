"""The declarative knob spec: validation, cache keys, flags and ladders from one list."""

import argparse
import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from translucent.errors import InputError
from translucent.fast.base import METHODS, method
from translucent.fast.knobs import Knob, KnobSpec
from translucent.reports.cli import main

SPEC = KnobSpec([
    Knob("samples", 64, "samples per pixel", kind="int", low=1, high=4096, ladder=(4, 16)),
    Knob("radius_mm", None, "a cut-off (None: derived)", kind="float", positive=True,
         unit="mm", optional=True),
    Knob("mode", "fast", "how, at 50 % of the cost", kind="choice", choices=("fast", "exact")),
    Knob("shadows", True, "cast shadows", kind="bool"),
    Knob("workers", 2, "threads", kind="int", low=1, keyed=False),
], checks=[lambda knobs: knobs.update(samples=max(knobs["samples"], 1))])


def test_defaults_resolve_and_convert():
    assert SPEC.defaults == {"samples": 64, "radius_mm": None, "mode": "fast",
                             "shadows": True, "workers": 2}
    resolved = SPEC.resolve({"samples": 16.0, "radius_mm": 2})
    assert resolved["samples"] == 16 and isinstance(resolved["samples"], int)
    assert resolved["radius_mm"] == 2.0 and isinstance(resolved["radius_mm"], float)


@pytest.mark.parametrize("knobs, words", [
    ({"sample": 1}, r"knobs = \['sample'\]: unknown knob; valid: samples, radius_mm"),
    ({"samples": 0}, r"samples = 0: must be an integer in \[1, 4096\]"),
    ({"samples": 2.5}, r"samples = 2.5: must be an integer"),
    ({"samples": True}, r"samples = True: must be an integer"),
    ({"samples": "many"}, r"samples = 'many': must be an integer"),
    ({"radius_mm": -1.0}, r"radius_mm = -1.0: must be > 0 mm"),
    ({"radius_mm": math.inf}, r"radius_mm = inf: must be a finite number > 0 mm \(or None\)"),
    ({"mode": "slow"}, r"mode = 'slow': must be one of 'fast', 'exact'"),
    ({"shadows": "yes"}, r"shadows = 'yes': must be true or false"),
    ({"workers": 0}, r"workers = 0: must be an integer >= 1"),
])
def test_a_bad_value_names_the_knob_and_the_value(knobs, words):
    with pytest.raises(InputError, match=words):
        SPEC.resolve(knobs)


@given(st.integers(-10_000, 10_000))
def test_an_integer_is_accepted_exactly_inside_its_bounds(value):
    if 1 <= value <= 4096:
        assert SPEC.resolve({"samples": value})["samples"] == value
    else:
        with pytest.raises(InputError, match="samples"):
            SPEC.resolve({"samples": value})


def test_unkeyed_knobs_stay_out_of_the_cache_key():
    assert SPEC.unkeyed == ("workers",)
    assert SPEC.keyed(SPEC.resolve({"workers": 8})) == SPEC.keyed(SPEC.resolve({}))
    assert SPEC.keyed(SPEC.resolve({"samples": 8})) != SPEC.keyed(SPEC.resolve({}))


def test_ladders_end_at_the_defaults():
    assert SPEC.ladders == {"samples": [{"samples": 4}, {"samples": 16}, {}]}
    with pytest.raises(ValueError, match="unknown knobs"):
        KnobSpec([Knob("a", 1, "a")], ladders={"x": [{"b": 2}, {}]})
    with pytest.raises(ValueError, match="declared twice"):
        KnobSpec([Knob("a", 1, "a"), Knob("a", 2, "a")])


def test_flags_come_from_the_spec_and_absent_flags_leave_the_defaults():
    parser = argparse.ArgumentParser()
    SPEC.add_arguments(parser)
    assert "50 % of the cost" in parser.format_help()  # % is escaped for argparse
    args = parser.parse_args(["--samples", "16", "--no-shadows", "--mode", "exact"])
    assert SPEC.from_arguments(args) == {"samples": 16, "shadows": False, "mode": "exact"}
    assert SPEC.from_arguments(parser.parse_args([])) == {}


@pytest.mark.parametrize("name", sorted(METHODS))
def test_each_builtin_method_derives_its_knobs_from_its_spec(name, capsys):
    module = method(name)
    assert module.KNOBS.defaults == module.DEFAULT_KNOBS
    assert module.KNOBS.resolve({}) == module.KNOBS.resolve(module.KNOBS.defaults)
    try:
        code = main(["approx", name, "--help"])
    except SystemExit as stop:
        code = stop.code
    assert code == 0
    shown = capsys.readouterr().out
    flags = [knob.flag for knob in module.KNOBS if knob.name != "progress"]
    assert all(flag in shown for flag in flags), [f for f in flags if f not in shown]
    for ladder in module.LADDERS.values():
        assert ladder[-1] == {} or {} in ladder
        for point in ladder:
            module.KNOBS.resolve(point)  # every ladder point is a valid setting


def test_an_unbounded_integer_knob_is_still_a_32_bit_count():
    from translucent.fast.knobs import MAX_COUNT, Knob, KnobSpec

    spec = KnobSpec([Knob("rays", 16, "rays per patch", kind="int", low=1)])
    assert spec.resolve({"rays": MAX_COUNT}) == {"rays": MAX_COUNT}
    with pytest.raises(InputError, match=r"rays = 99999999999999999999: must be at most"):
        spec.resolve({"rays": 99999999999999999999})


# ------------------------------------------------------------------ refused values, profiles


def test_a_refused_value_is_an_input_error_with_its_reason_and_passes_the_flag():
    spec = KnobSpec([Knob("mode", "fast", "how", kind="choice", choices=("fast", "exact"),
                          refused=(("magic", "mode 'magic' is not taken: it does not exist"),))])
    with pytest.raises(InputError, match="mode = 'magic': mode 'magic' is not taken"):
        spec.resolve({"mode": "magic"})
    with pytest.raises(InputError, match="must be one of 'fast', 'exact'"):
        spec.resolve({"mode": "other"})
    parser = argparse.ArgumentParser()
    spec.add_arguments(parser)
    assert "{fast,exact}" in parser.format_help() and "magic" not in parser.format_help()
    # the command line lets it through, so that resolve() says why it is refused
    assert spec.from_arguments(parser.parse_args(["--mode", "magic"])) == {"mode": "magic"}
    with pytest.raises(ValueError, match="refused values"):
        Knob("mode", "fast", "how", kind="choice", choices=("fast",), refused=(("fast", "no"),))
    with pytest.raises(ValueError, match="refused values"):
        Knob("count", 1, "how many", kind="int", refused=((2, "no"),))


def test_profile_names_are_the_registrys_radial_ones_then_the_averages():
    from translucent.fast.knobs import (
        directional_profile_names,
        radial_profile,
        radial_profile_names,
    )
    from translucent.materials.profiles import PROFILES, RadialProfile, profile

    names = radial_profile_names()
    assert names[0] == "dipole"
    assert set(names) == {n for n, e in PROFILES.items() if not e.directional} | {
        n + "_average" for n in directional_profile_names()}
    assert directional_profile_names() == ("directional_dipole",)
    average = radial_profile("directional_dipole_average", "Skin1")
    assert isinstance(average, RadialProfile)
    assert np.array_equal(average.total(),
                          profile("directional_dipole", "Skin1", radial=True).total())
    with pytest.raises(InputError, match="radial_average"):
        radial_profile("directional_dipole", "Skin1")
    with pytest.raises(InputError, match="unknown profile"):
        radial_profile("dipole_average", "Skin1")
