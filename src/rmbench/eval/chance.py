"""Each task's chance level: the success rate of the best guess a policy without memory can
make.

Such a policy has every skill the demonstrations show and sees what the cameras see now;
where that decides the next step it acts as the expert does, and where only the past would
decide it chooses among what the demonstrations do at such a view, the same view getting the
same (possibly random) choice every time it comes back. It leaves no marks in the scene or in
its own pose to remember by. Chance is the best success rate such a policy can reach, given
the task's randomisation and its step limit: the level a memoryless baseline with every
skill scores (``no_memory``, and near it DP's and ACT's windows of a step or two), and the
ceiling a policy without memory cannot pass. It is computed exactly, except for
observe_and_pickup (a fixed-seed sample of its tables, the posterior of each exact).

Trial-and-error tasks allow as many tries as the step limit leaves after the expert's own
durations: measured on 10 demonstrations per task (``rmbench collect TASK --episodes 10
--seed 0``, subtask segments), battery_try's two inserts take 367 steps, a flip that fails
200 (left) or 203 (right) with the arm's way back home, and one that lights the lamp 147 or
151 (it ends as the cell goes in; four flips fit in 1200), a swap and its press in
blocks_ranking_try 451-511 (7 fit in 3500), a move in swap_blocks 149-191 before a press of
85 (5 moves fit in 1000).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import cache

import numpy as np

# what the step limit leaves a perfect guesser (measured as the module docstring says)
BATTERY_INSERTS = 367  # steps to insert both cells, both arms back home
BATTERY_FLIP_STEPS = (199.7, 203.3)  # mean steps of a left and a right flip that fails ...
BATTERY_LIT_STEPS = (147.3, 151.0)  # ... and that lights the lamp (no way back)
RANKING_SWAPS = 7
SWAP_BLOCKS_MOVES = 5


@dataclass(frozen=True)
class Chance:
    rate: float
    """Success rate of the best memoryless policy with every skill, 0-1."""
    basis: str
    """How it guesses, in words."""


@cache
def chance(task: str) -> Chance:
    """The chance level of ``task`` (a task name); a KeyError names the known ones."""
    if task not in _LEVELS:
        raise KeyError(f"no chance level for {task!r}; tasks: {', '.join(_LEVELS)}")
    return _LEVELS[task]()


# ------------------------------------------------------------------------------ M(1)
def _observe_and_pickup() -> Chance:
    from rmbench.sim.objects import SHAPE_COLOURS, SHAPES
    from rmbench.tasks.observe_and_pickup import N_OBJECTS, OTHER_SHAPE_P

    rate = pick_among_looks(len(SHAPES), len(SHAPE_COLOURS), N_OBJECTS, OTHER_SHAPE_P)
    return Chance(rate, f"the most likely reference among the {N_OBJECTS} objects, from how "
                        f"the distractors are drawn (most share no shape with it); "
                        f"1/{N_OBJECTS} blind")


def _rearrange_blocks() -> Chance:
    return Chance(1 / 2, "after the press, one of the two blocks on the mats")


def _put_back_block() -> Chance:
    return Chance(1 / 4, "with the cube at the centre, one of the four mats")


def _swap_blocks() -> Chance:
    rate = swap_through_empty(SWAP_BLOCKS_MOVES)
    return Chance(rate, f"always the cube next to the empty tray in one turning direction "
                        f"into it (three such moves swap the cubes), pressing at every view "
                        f"with the best fixed probability; {SWAP_BLOCKS_MOVES} moves fit")


def _swap_T() -> Chance:
    from rmbench.tasks.swap_t import POS_TOL, YAW_TOL

    # starts: x +-1 cm about +-0.09, y ~ U[-0.15, -0.10], yaw ~ U[-0.75, 0.75] (tasks/swap_t.py);
    # the best guess is the middle of each range
    xy = disc_in_box(POS_TOL, 0.01, 0.025)
    yaw = min(1.0, YAW_TOL / 0.75)
    return Chance((xy * yaw) ** 2, "each T set down at the middle of the starting ranges: "
                                   "within tolerance of the other's pose for both")


# ------------------------------------------------------------------------------- M(n)
def _battery_try() -> Chance:
    from rmbench.tasks.battery_try import BatteryTry

    budget = BatteryTry.step_limit - BATTERY_INSERTS
    rate, left = max((battery_flips(budget, left=q / 100), q / 100) for q in range(101))
    return Chance(rate, f"insert both positive first, then flip the left battery with "
                        f"probability {left:.2f} and the right otherwise while the lamp stays "
                        f"off (after the inserts and after every failed try the arms are home, "
                        f"the lamp is off and the holder hides the cells' ends)")


def _blocks_ranking_try() -> Chance:
    rate = ranking_by_parity(RANKING_SWAPS)
    return Chance(rate, f"swap left and middle when the row's hues run one way round the "
                        f"colour wheel, middle and right when they run the other: the row "
                        f"itself counts, and five swaps visit every order ({RANKING_SWAPS} "
                        f"fit; swapping at random: {100 * ranking_swaps(RANKING_SWAPS):.0f}%)")


def _cover_blocks() -> Chance:
    return Chance(1 / 6, "with all three covered, uncover one of three for red, then one of "
                         "two for green")


def _press_button() -> Chance:
    # d1 ~ U{1..9}, d2 ~ U{1..10-d1} (tasks/press_button.py); the digits are shown
    total = 0.0
    for d1 in range(1, 10):
        total += sum(exact_presses(d1) * exact_presses(d2) for d2 in range(1, 11 - d1)) \
            / (10 - d1)
    return Chance(total / 9, "each button pushed on each visit with the probability that "
                             "best hits the digit shown (a released button looks the same "
                             "after any number of pushes)")


_LEVELS = {"observe_and_pickup": _observe_and_pickup, "rearrange_blocks": _rearrange_blocks,
           "put_back_block": _put_back_block, "swap_blocks": _swap_blocks, "swap_T": _swap_T,
           "battery_try": _battery_try, "blocks_ranking_try": _blocks_ranking_try,
           "cover_blocks": _cover_blocks, "press_button": _press_button}


# --------------------------------------------------------------------------- the models
def exact_presses(d: int) -> float:
    """Best chance of stopping after exactly ``d`` pushes when the button looks the same
    before the first push and after any other, so each visit pushes with one fixed
    probability r: max over r of r^d (1 - r), at r = d / (d + 1)."""
    r = d / (d + 1)
    return r ** d * (1 - r)


def disc_in_box(radius: float, half_x: float, half_y: float, n: int = 2001) -> float:
    """Fraction of the box [-half_x, half_x] x [-half_y, half_y] within ``radius`` of its
    centre (midpoint rule over x)."""
    x = (np.arange(n) + 0.5) / n * 2 * half_x - half_x
    inside = np.minimum(2 * np.sqrt(np.maximum(radius ** 2 - x ** 2, 0.0)), 2 * half_y)
    return float(inside.mean() / (2 * half_y))


def absorbed(step: np.ndarray, start: np.ndarray, good: np.ndarray, steps: int) -> float:
    """Probability of ending in ``good`` within ``steps`` transitions of the sub-stochastic
    matrix ``step`` (rows: from; what is missing from a row ends the episode otherwise),
    ``good[i]``: the probability of succeeding from state i before the next transition."""
    p, total = start.astype(float), 0.0
    for _ in range(steps + 1):
        total += float(p @ good)
        p = p @ step
    return total


def battery_flips(budget: float, fail: tuple[float, float] = BATTERY_FLIP_STEPS,
                  lit: tuple[float, float] = BATTERY_LIT_STEPS, left: float = 0.5) -> float:
    """battery_try: both cells go in positive first; after the inserts and after every failed
    try the view is the same (both arms home, lamp off, the cells' ends hidden), so every flip
    is of the left cell with one probability ``left`` and of the right otherwise. A flip
    that lights the lamp counts if it ends within what ``budget`` has left (``lit``: its steps
    for the left and the right cell); one that fails costs ``fail``."""

    def hit(state, correct, remaining):
        total = 0.0
        for k, p in ((0, left), (1, 1.0 - left)):
            moved = tuple(b ^ (i == k) for i, b in enumerate(state))
            if moved == correct:
                total += p * (lit[k] <= remaining)
            elif fail[k] <= remaining:
                total += p * hit(moved, correct, remaining - fail[k])
        return total

    from rmbench.tasks.battery_try import PAIRS, TRIES

    return sum(hit(TRIES[0], correct, budget) for correct in PAIRS) / len(PAIRS)


def swapped(order: tuple, pair: tuple[int, int]) -> tuple:
    """``order`` with the entries at the two positions of ``pair`` exchanged."""
    q = list(order)
    q[pair[0]], q[pair[1]] = q[pair[1]], q[pair[0]]
    return tuple(q)


def ranking_swaps(swaps: int) -> float:
    """blocks_ranking_try: the target order is one of the five the row did not start in;
    after each failed press, swap one of the three pairs at random."""
    perms = list(itertools.permutations(range(3)))
    pairs = list(itertools.combinations(range(3), 2))

    total, cases = 0.0, 0
    for initial in perms:
        for target in perms:
            if target == initial:
                continue
            step = np.zeros((6, 6))
            for i, p in enumerate(perms):
                if p != target:
                    for pair in pairs:
                        step[i, perms.index(swapped(p, pair))] += 1 / 3
            start = np.eye(6)[perms.index(initial)]
            good = np.eye(6)[perms.index(target)]
            total += absorbed(step, start, good, swaps)
            cases += 1
    return total / cases


def ranking_by_parity(swaps: int) -> float:
    """blocks_ranking_try with the row's parity as the rule: an order and its parity are seen
    (up to which hue is first, a rotation, which keeps the parity), so the policy may swap
    (left, middle) on even orders and (middle, right) on odd ones; the two alternate, their
    product is a 3-cycle, and the walk passes through all six orders."""
    perms = list(itertools.permutations(range(3)))

    def parity(p):
        return sum(p[i] > p[j] for i in range(3) for j in range(i + 1, 3)) % 2

    hits = 0
    for initial in perms:
        seen, p = [], initial
        for _ in range(swaps):
            p = swapped(p, (0, 1) if parity(p) == 0 else (1, 2))
            seen.append(p)
        hits += sum(target in seen for target in perms if target != initial)
    return hits / (len(perms) * (len(perms) - 1))


def swap_through_empty(moves: int) -> float:
    """swap_blocks: with identical cubes every view is two full trays and an empty one, and
    the only thing a memoryless policy sees change is which tray is empty. Moving always the
    cube on one fixed side (cyclically) of the empty tray into it swaps the cubes every three
    moves and undoes the swap three moves later; a press ends the episode, so the policy
    presses with one probability q at every view, best q chosen: sum over the swapped states
    (after 3, 9, ... moves) of q (1-q)^m."""
    swapped = [m for m in range(moves + 1) if m % 6 == 3]
    qs = np.linspace(0.0, 1.0, 10001)
    rates = sum(qs * (1 - qs) ** m for m in swapped) if swapped else np.zeros_like(qs)
    return float(np.max(rates))


def pick_among_looks(shapes: int, colours: int, objects: int, other_shape_p: float,
                     tables: int = 4000, seed: int = 0) -> float:
    """observe_and_pickup: the reference is one look (shape, colour) drawn uniformly; each
    distractor is, with probability ``other_shape_p``, a look of another shape, else the
    reference's shape in a colour drawn at random; looks never repeat (tasks/
    observe_and_pickup.py). For ``tables`` tables drawn so, the exact posterior of each object
    being the reference given the table's looks; the mean of its maximum is the best
    memoryless guess's success rate."""
    rng = np.random.default_rng(seed)

    # one attempt draws a look of another shape with weight p / (shapes * colours) (the
    # same-shape draws of that branch are redrawn) and one of the reference's shape with
    # (1 - p) / colours; a look already on the table is redrawn too
    def weight(look, ref):
        if look[0] == ref[0]:
            return (1 - other_shape_p) / colours
        return other_shape_p / (shapes * colours)

    every = 1 - other_shape_p / shapes  # the weight of all looks together

    def likelihood(table, ref):
        others = [look for look in table if look != ref]
        total = 0.0
        for order in itertools.permutations(others):
            left, p = every - weight(ref, ref), 1.0
            for look in order:
                w = weight(look, ref)
                p *= w / left
                left -= w
            total += p
        return total

    hits = 0.0
    for _ in range(tables):
        ref = (int(rng.integers(shapes)), int(rng.integers(colours)))
        table = [ref]
        while len(table) < objects:
            if rng.uniform() < other_shape_p:
                look = (int(rng.integers(shapes)), int(rng.integers(colours)))
                if look[0] == ref[0]:
                    continue
            else:
                look = (ref[0], int(rng.integers(colours)))
            if look not in table:
                table.append(look)
        post = np.array([likelihood(table, r) for r in table])
        hits += post.max() / post.sum()
    return hits / tables

