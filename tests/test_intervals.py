"""The intervals every reported rate carries (eval/intervals.py)."""

import pytest

from rmbench.eval.intervals import (
    difference,
    format_difference,
    format_rate,
    outside_noise,
    paired_difference,
    wilson,
)


def test_wilson_matches_the_closed_form_values():
    # Reference values computed by hand from the score-interval formula (Wilson 1927),
    # z = 1.96: 20/100 -> [0.1333, 0.2888]; 0/100 -> [0, 0.0370]; 50/100 -> [0.4038, 0.5962].
    assert wilson(20, 100) == pytest.approx((0.1333, 0.2888), abs=5e-4)
    assert wilson(0, 100) == pytest.approx((0.0, 0.0370), abs=5e-4)
    assert wilson(50, 100) == pytest.approx((0.4038, 0.5962), abs=5e-4)
    assert wilson(100, 100) == pytest.approx((0.9630, 1.0), abs=5e-4)


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


def test_a_paired_difference_of_uncorrelated_pairs_is_the_independent_one():
    # 25 both, 25 first only, 25 second only, 25 neither: phi = 0
    assert paired_difference(25, 25, 25, 100) == pytest.approx(difference(50, 100, 50, 100))
    with pytest.raises(ValueError, match="exceed n=10"):
        paired_difference(5, 4, 3, 10)


def test_a_paired_difference_covers_at_its_level_where_the_independent_one_overcovers():
    """Pairs that mostly agree (a probe that changes few outcomes): the paired interval holds
    the true difference about 95% of the time and is about half as wide; the independent
    one, built for two separate samples, nearly always does and is twice as wide."""
    import numpy as np

    rng = np.random.default_rng(0)
    n, p, rho = 100, 0.5, 0.8  # both rates 0.5, outcomes correlated 0.8
    both = p * p + rho * p * (1 - p)
    counts = rng.multinomial(n, [both, p - both, p - both, 1 - 2 * p + both], size=2000)
    paired = np.array([paired_difference(a, b, c, n)[1:] for a, b, c, _ in counts])
    apart = np.array([difference(a + b, n, a + c, n)[1:] for a, b, c, _ in counts])
    covered = [np.mean((ci[:, 0] <= 0) & (0 <= ci[:, 1])) for ci in (paired, apart)]
    width = [np.mean(ci[:, 1] - ci[:, 0]) for ci in (paired, apart)]
    assert 0.93 <= covered[0] <= 0.97 and covered[1] > 0.99
    assert width[0] < 0.55 * width[1]


def test_format_rate():
    assert format_rate(20, 100) == "20 [13, 29]"


def test_an_interval_end_that_is_not_zero_never_prints_as_zero():
    """'-9 [-18, -0.2]', never '[-18, 0]' beside an interval that excludes zero nor
    '[-18, -0]'; a difference that is zero prints without a sign."""
    from rmbench.eval.intervals import format_difference, signed

    assert format_difference(-0.09, -0.18, -0.004) == "-9 [-18, -0.4]"
    assert format_difference(-0.09, -0.18, -0.00004) == "-9 [-18, -0.004]"
    assert format_difference(0.0, -0.02, 0.02) == "0 [-2, +2]"
    assert format_difference(0.0, 0.0, 0.02) == "0 [0, +2]"
    assert format_difference(0.66, 0.54, 0.75) == "+66 [+54, +75]"
    assert signed(-0.04, 1) == "0.0" and signed(-0.05001, 1) == "-0.1" and signed(0.4) == "0"
    # press_button's Mem-0 (136/200) minus gt_classifier (154/200): an upper end of -0.24 points
    assert format_difference(*difference(136, 200, 154, 200)) == "-9 [-18, -0.2]"


def test_a_share_stores_its_rate_and_interval_and_nothing_where_nothing_was_counted():
    from rmbench.eval.intervals import share

    s = share(43, 100)
    assert (s["count"], s["of"], s["rate"]) == (43, 100, 0.43)
    assert s["ci95"] == [round(x, 4) for x in wilson(43, 100)]
    assert share(0, 0) == {"count": 0, "of": 0, "rate": None, "ci95": None}


def test_a_difference_is_rounded_once_from_its_counts():
    """163/200 against 7/100: the interval's low end is 0.654976, so +65 (4 decimals first
    made it 0.6550 and +66); 151/200 - 68/100 is 7.5 points exactly, which a float holds as
    7.4999999999999991 and must still round as the tie it is (to even, as the rates do)."""
    assert format_difference(*difference(163, 200, 7, 100)) == "+74 [+65, +80]"
    assert format_difference(*difference(16, 200, 16, 200)) == "0 [-5, +5]"
    assert format_difference(*difference(151, 200, 68, 100)).startswith("+8 [")
