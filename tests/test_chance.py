"""Chance levels: the best a policy with every skill and no memory can do on each task."""

import numpy as np
import pytest

from rmbench.eval.chance import (
    BATTERY_FLIP_STEPS,
    BATTERY_INSERTS,
    BATTERY_LIT_STEPS,
    absorbed,
    battery_flips,
    chance,
    disc_in_box,
    exact_presses,
    pick_among_looks,
    ranking_by_parity,
    ranking_swaps,
    swap_through_empty,
)
from rmbench.tasks.registry import ordered


def test_every_task_has_a_chance_level_and_an_unknown_one_is_named():
    for task in ordered():
        level = chance(task.name)
        assert 0 < level.rate <= 1 and level.basis
    with pytest.raises(KeyError, match="no chance level for 'stack_cups'; tasks: observe"):
        chance("stack_cups")


def test_one_guess_among_identical_places():
    from rmbench.tasks.put_back_block import MAT_DIRECTIONS

    assert chance("put_back_block").rate == 1 / len(MAT_DIRECTIONS)
    assert chance("rearrange_blocks").rate == 1 / 2
    assert chance("cover_blocks").rate == pytest.approx(1 / 3 * 1 / 2)


def test_battery_flips_match_a_simulated_random_walk():
    from rmbench.tasks.battery_try import BatteryTry

    assert battery_flips(100, (150, 150), (150, 150)) == 0.0  # no flip fits
    # one flip: the left one finds (1,0), the right one (0,1)
    assert battery_flips(150, (150, 150), (150, 150), left=1.0) == pytest.approx(1 / 3)
    assert battery_flips(150, (150, 150), (150, 150), left=0.5) == pytest.approx(1 / 3)
    # a failed flip costs more than a lit one: two flips need 200 + 150
    assert battery_flips(349, (200, 200), (150, 150), left=0.5) == pytest.approx(1 / 3)
    assert battery_flips(350, (200, 200), (150, 150), left=0.5) > 1 / 3
    rng = np.random.default_rng(0)
    pairs, hits, n = ((1, 0), (1, 1), (0, 1)), 0, 20000
    for _ in range(n):
        correct, state = pairs[rng.integers(3)], [0, 0]
        left = BatteryTry.step_limit - BATTERY_INSERTS
        while True:
            k = rng.integers(2)
            state[k] ^= 1
            if tuple(state) == correct:
                hits += BATTERY_LIT_STEPS[k] <= left
                break
            left -= BATTERY_FLIP_STEPS[k]
            if left < 0:
                break
    assert chance("battery_try").rate == pytest.approx(hits / n, abs=0.01)


def test_the_rows_parity_counts_for_blocks_ranking():
    """Alternating two swaps on the row's parity visits every order: five swaps find any
    target, four miss one order in five; random swaps need more."""
    assert ranking_by_parity(5) == 1.0
    assert ranking_by_parity(4) == pytest.approx(4 / 5)
    assert ranking_swaps(1) == pytest.approx(3 / 5 * 1 / 3)  # an odd target, hit at once
    assert ranking_swaps(7) < ranking_by_parity(7)


def test_swap_blocks_presses_after_three_rotations():
    assert swap_through_empty(2) == 0.0  # fewer than three moves cannot swap
    assert swap_through_empty(5) == pytest.approx(27 / 256, abs=1e-6)  # q = 1/4
    assert swap_through_empty(9) > swap_through_empty(5)  # the second swapped state counts


def test_presses_counted_by_chance():
    assert exact_presses(1) == 1 / 4  # push on a visit with probability 1/2, then stop
    assert exact_presses(2) == pytest.approx((2 / 3) ** 2 / 3)
    assert all(exact_presses(d) > exact_presses(d + 1) for d in range(1, 9))


def test_absorbed_counts_success_before_each_step():
    step = np.array([[0.0, 0.5], [0.0, 0.0]])  # state 0 goes to 1 half of the time
    start, good = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    assert absorbed(step, start, good, 0) == 0.0
    assert absorbed(step, start, good, 3) == 0.5


def test_geometric_parts():
    assert disc_in_box(1.0, 0.1, 0.1) == pytest.approx(1.0)
    assert disc_in_box(0.5, 1.0, 1.0) == pytest.approx(np.pi * 0.25 / 4, rel=1e-3)
    blind = 1 / 5
    assert blind < pick_among_looks(6, 6, 5, 0.8, tables=300) < 0.4
    # all distractors of the reference's shape in other colours: nothing tells them apart
    assert pick_among_looks(6, 6, 5, 0.0, tables=50) == pytest.approx(blind)


def test_the_report_puts_chance_last():
    from rmbench.eval.report import table

    run = {"name": "x", "summary": {"tasks": {"put_back_block": {"success_rate": 0.5,
                                                              "mean_progress": 0.6}}}}
    header, rows = table([run], ["Mem-0"], tasks=["put_back_block"], with_chance=True)
    assert header == ["task", "TMC", "x", "Mem-0 (published)", "chance (no memory)"]
    assert rows[0] == ["put_back_block", "M(1)", 50.0, 90, 25.0]
    header, _ = table([run], [], "mean_progress", tasks=["put_back_block"], with_chance=True)
    assert header == ["task", "TMC", "x"]  # a chance of progress is not defined
