"""The intervals every reported rate carries (eval/intervals.py)."""

import pytest

from rmbench.eval.intervals import difference, format_rate, outside_noise, wilson


def test_wilson_matches_the_closed_form_values():
    # Reference values computed by hand from the score-interval formula (Wilson 1927),
    # z = 1.96: 20/100 -> [0.1333, 0.2888]; 0/100 -> [0, 0.0370]; 50/100 -> [0.4038, 0.5962].
    assert wilson(20, 100) == pytest.approx((0.1333, 0.2888), abs=5e-4)
    assert wilson(0, 100) == pytest.approx((0.0, 0.0370), abs=5e-4)
    assert wilson(50, 100) == pytest.approx((0.4038, 0.5962), abs=5e-4)
    assert wilson(100, 100)[1] == 1.0


def test_wilson_is_symmetric_and_narrows_with_more_episodes():
    lo, hi = wilson(30, 100)
    lo2, hi2 = wilson(70, 100)
    assert lo == pytest.approx(1 - hi2) and hi == pytest.approx(1 - lo2)
    assert wilson(300, 1000)[1] - wilson(300, 1000)[0] < hi - lo


def test_wilson_refuses_impossible_counts():
    with pytest.raises(ValueError, match="at least one episode"):
        wilson(0, 0)
    with pytest.raises(ValueError, match="outside"):
        wilson(5, 4)


def test_difference_of_two_cells():
    # Newcombe (1998), Table II, example (e): 56/70 - 48/80 -> 0.2, [0.0524, 0.3339].
    d, lo, hi = difference(56, 70, 48, 80)
    assert d == pytest.approx(0.2)
    assert (lo, hi) == pytest.approx((0.0524, 0.3339), abs=5e-4)
    assert outside_noise(56, 70, 48, 80)
    assert not outside_noise(23, 100, 20, 100)  # three points apart at 100 episodes: noise


def test_format_rate():
    assert format_rate(20, 100) == "20 [13, 29]"
