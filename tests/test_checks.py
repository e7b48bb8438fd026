"""Known answers and properties of the shared argument checks."""

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from wheelloader.estimator.checks import check_choice, check_finite, check_int, check_optional_int, check_range
from wheelloader.estimator.errors import ParameterError, PlanningError


def test_check_int_accepts_and_converts():
    import numpy as np

    assert check_int("n", 3) == 3
    assert type(check_int("n", np.int64(4))) is int
    assert check_int("n", 0, minimum=0) == 0
    assert check_optional_int("n", None) is None


@pytest.mark.parametrize("bad", [0, -1, 1.0, "2", True, None])
def test_check_int_refuses_with_one_line(bad):
    with pytest.raises(ParameterError, match=r"^n must be an int >= 1, got "):
        check_int("n", bad)


def test_check_int_bounds_and_error_class():
    with pytest.raises(PlanningError, match=r"in \[4, 400\], got 401"):
        check_int("intervals", 401, minimum=4, maximum=400, error=PlanningError)


def test_check_range_intervals():
    assert check_range("dt", 0.5, 0, 1, low_open=True) == 0.5
    with pytest.raises(ParameterError, match=r"dt must be in \(0, 1\], got 0"):
        check_range("dt", 0, 0, 1, low_open=True)
    with pytest.raises(ParameterError, match="finite"):
        check_range("dt", math.nan, 0, 1)


def test_check_choice_lists_choices():
    assert check_choice("mode", "a", ("a", "b")) == "a"
    with pytest.raises(ParameterError, match="one of 'a', 'b', got 'c'"):
        check_choice("mode", "c", ("a", "b"))


@given(st.integers(min_value=-10**6, max_value=10**6))
def test_check_int_agrees_with_its_domain(n):
    if n >= 1:
        assert check_int("n", n) == n
    else:
        with pytest.raises(ParameterError):
            check_int("n", n)


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_check_finite_agrees_with_math(x):
    if math.isfinite(x):
        assert check_finite("x", x) == x
    else:
        with pytest.raises(ParameterError):
            check_finite("x", x)
