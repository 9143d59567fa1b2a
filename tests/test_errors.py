"""The shared input checks of translucent.errors."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from translucent.errors import InputError, check_count, check_finite, check_positive


@given(st.integers(min_value=-5, max_value=50), st.integers(min_value=0, max_value=10))
def test_check_count_accepts_exactly_the_integers_at_or_above_the_minimum(value, minimum):
    if value >= minimum:
        assert check_count(value, "n", minimum) == value
        assert type(check_count(np.int64(value), "n", minimum)) is int
        assert check_count(float(value), "n", minimum) == value
    else:
        with pytest.raises(InputError, match=rf"n = {value}: must be an integer >= {minimum}"):
            check_count(value, "n", minimum)


@pytest.mark.parametrize("value", [True, 2.5, "3", None, float("nan"), float("inf")])
def test_check_count_refuses_what_is_not_a_count(value):
    with pytest.raises(InputError, match="must be an integer >= 1 .because"):
        check_count(value, "spp", why=" (because)", file="scene.toml")


@pytest.mark.parametrize(("value", "match"), [
    ("x", "must be a number, not text"), ("2.5", "must be a number, not text"),
    (["1", "b"], "must be a number or an array of numbers"),
    ({"a": 1}, "must be a number or an array of numbers"),
    ([1.0, float("nan")], r"must be finite \(no NaN or Inf\)")])
def test_check_finite_refuses_what_is_not_a_finite_number(value, match):
    with pytest.raises(InputError, match=match) as error:
        check_positive(value, "sigma_a", file="medium.toml")
    assert "medium.toml: sigma_a = " in str(error.value)


@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=5))
def test_check_finite_returns_the_numbers_as_float64(values):
    array = check_finite(values, "x")
    assert array.dtype == np.float64 and np.array_equal(array, np.asarray(values))
