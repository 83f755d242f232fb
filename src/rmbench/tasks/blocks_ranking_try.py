"""blocks_ranking_try — M(n).

Task: three cubes of three vivid colours stand in three slots on a row; a hidden target
order ranks them. Press the button to ask whether the row is in the target order: the lamp
beside it turns green (solved) or red (not yet). While it is red, apply the next swap of the
fixed sequence (middle,right), (left,right), (left,middle), (middle,right), (left,right) —
a swap parks one cube on a spot 0.1 m in front — and press again.

Randomization: colours at hues h0, h0 + 1/3, h0 + 2/3 with h0 ~ U[0, 1); slot row x0 + (0,
0.12, 0.24) with x0 ~ U[-0.06, -0.02], y ~ U[-0.12, -0.08] (the benchmark's x = 0.04..0.28
shifted towards the centre so both arms reach every slot); the initial order uniformly of the
six, the target uniformly of the five others; cube yaws ~ U[-0.2, 0.2]; button
x ~ U[-0.34, -0.28], y ~ U[-0.12, -0.04] with its lamp 6 cm behind it.

Success: the three cubes rest in the slots in the target order and the button is pressed in
that state (the lamp turns green), no finger touching a cube.
Failure: a cube off the table; a cube resting on another.

Memory: TMC M(n). Aliasing point: between tries the row looks like any other wrong order with
a red lamp; only the past tells how far along the swap sequence the robot is (the memory
grows with the number of tries). The sequence needs that memory, the task does not: the row's
order shows its parity (which way its hues run round the colour wheel), and swapping left and
middle on one parity, middle and right on the other visits all six orders in five swaps
(``eval/chance.py``).
"""

from __future__ import annotations

import colorsys
import itertools

import numpy as np

from rmbench.sim.fixtures import Button, Lamp
from rmbench.sim.objects import Cube
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m, rad), in the order drawn (after the hue)
ROW_X0 = Uniform(-0.06, -0.02)  # slot 0; slots 1 and 2 follow SLOT_SPACING apart
ROW_Y = Uniform(-0.12, -0.08)
CUBE_YAW = Uniform(-0.2, 0.2)
BUTTON_X = Uniform(-0.34, -0.28)
BUTTON_Y = Uniform(-0.12, -0.04)

SLOT_SPACING = 0.12
SLOT_TOL = 0.03
PARK_OFFSET = 0.10  # the temporary spot, in front of a slot
SWAPS = ((1, 2), (0, 2), (0, 1), (1, 2), (0, 2))  # slot pairs, the fixed trial sequence
PERMUTATIONS = tuple(itertools.permutations(range(3)))
CHECK = 0  # subtask index of "press the button"
SWAP_SUBTASK = {(1, 2): 1, (0, 2): 2, (0, 1): 3}


def swapped(order: tuple[int, ...], pair: tuple[int, int]) -> tuple[int, ...]:
    out = list(order)
    out[pair[0]], out[pair[1]] = out[pair[1]], out[pair[0]]
    return tuple(out)


def trial_orders(initial: tuple[int, ...], target: tuple[int, ...]) -> list[tuple[int, ...]]:
    """The rows pressed in turn, from the initial one until the target."""
    orders = [tuple(initial)]
    for pair in SWAPS:
        if orders[-1] == tuple(target):
            break
        orders.append(swapped(orders[-1], pair))
    return orders


@register
class BlocksRankingTry(Task):
    name = "blocks_ranking_try"
    gym_id = "rmbench/BlocksRankingTry-v1"
    tmc = "M(n)"
    step_limit = 3500
    subtasks = ("press the button to check the order", "swap the middle and right blocks",
                "swap the left and right blocks", "swap the left and middle blocks")
    instructions_seen = (
        "Find the right order of the three blocks: press the button to check, and swap blocks "
        "until the light turns green.",
        "Rearrange the coloured blocks by trial: check with the button after every swap until "
        "the order is accepted.",
        "Press the button to test the block order and keep swapping blocks until it is right.",
        "Sort the three blocks into the hidden order, using the button to check each attempt.",
    )
    instructions_unseen = (
        "Try block orders one swap at a time, pressing the button each time, until the lamp "
        "goes green.",
        "Discover the correct ranking of the blocks by swapping them and checking with the "
        "button.",
    )
    aliasing_point = "after a red verdict: the row looks like any other wrong order"
    aliasing_stage = 1
    hidden_keys = ("initial_order", "target_order")
    # the row's order while every cube rests in a slot, [] while one is held or parked: a cube
    # lifted and set back in its own slot leaves the row as it was
    place_predicates = ("row",)
    # after a red verdict, the arm over the button: the same row reached by one swap and
    # shown at the start (the headline), and reached by two swaps
    aliasing_pairs = (
        (({"initial_order": (0, 1, 2), "target_order": (2, 1, 0)}, 3, 1),
         ({"initial_order": (0, 2, 1), "target_order": (2, 1, 0)}, 1, 1)),
        (({"initial_order": (0, 1, 2), "target_order": (2, 1, 0)}, 5, 1),
         ({"initial_order": (1, 2, 0), "target_order": (2, 1, 0)}, 1, 1)))

    # The state observation: the three cubes left to right, each with its colour (RGB), the
    # button and the lamp. The target order and the tries made are not in it.
    state_names = (*(n for p in ("left", "middle", "right") for n in (
                       *S.pose_names(f"cube_{p}", S.CUBE_SYMMETRY), *S.rgb_names(f"cube_{p}"))),
                   *S.button_names("button"), *S.lamp_names("lamp"))

    def __init__(self):
        super().__init__()
        self.cubes = tuple(Cube(f"cube{k}", size=0.04) for k in range(3))
        self.button = Button("button", cap_rgba=(0.2, 0.2, 0.8, 1.0))
        self.lamp = Lamp("lamp")
        self.slots = np.zeros((3, 2))
        self.initial: tuple[int, ...] = (0, 1, 2)
        self.target: tuple[int, ...] = (0, 1, 2)
        self.orders: list[tuple[int, ...]] = []
        self.pressed: list[tuple[int, ...] | None] = []
        self.is_stacked = False
        self.cursor = 0

    @property
    def pieces(self):
        return (*self.cubes, self.button, self.lamp)

    def initialize(self, rng: np.random.Generator) -> None:
        h0 = rng.uniform()
        for k, cube in enumerate(self.cubes):  # colour k: the cube's rank in the target order
            cube.paint(self.model, (*colorsys.hsv_to_rgb((h0 + k / 3) % 1.0, 0.85, 0.9), 1.0))
        x0, y = ROW_X0.draw(rng), ROW_Y.draw(rng)
        self.slots = np.array([[x0 + k * SLOT_SPACING, y] for k in range(3)])
        initial = PERMUTATIONS[int(rng.integers(6))]
        others = [p for p in PERMUTATIONS if p != initial]
        target = others[int(rng.integers(5))]
        self.initial = tuple(self.choose("initial_order", initial, PERMUTATIONS))
        self.target = tuple(self.choose("target_order", target, PERMUTATIONS))
        if self.target == self.initial:
            raise ValueError(f"{self.name}: the target order must differ from the initial one")
        yaws = CUBE_YAW.draw(rng, 3)
        for slot, colour in enumerate(self.initial):
            self.cubes[colour].place(self.data, self.slots[slot], yaw=yaws[slot])
        bx, by = BUTTON_X.draw(rng), BUTTON_Y.draw(rng)
        self.button.move(self.model, (bx, by))
        self.button.reset()
        self.lamp.move(self.model, (bx, by + 0.06))
        self.lamp.set(self.model, "off")
        self.orders = trial_orders(self.initial, self.target)
        self.pressed = []
        self.cursor = 0  # index into plan() of the subtask in progress
        self.is_stacked = False

    def plan(self) -> list[int]:
        out = [CHECK]
        for pair in SWAPS[: len(self.orders) - 1]:
            out += [SWAP_SUBTASK[pair], CHECK]
        return out

    def environment_state(self) -> np.ndarray:
        m, d = self.model, self.data
        return S.assemble(self.state_names, [
            *((S.pose(c, d, S.CUBE_SYMMETRY), m.geom_rgba[c.geom_id][:3])
              for c in S.left_to_right(self.cubes, d)),
            S.button(self.button, m, d), S.lamp(self.lamp)])

    def hidden_state(self) -> dict:
        return {"target_order": list(self.target), "initial_order": list(self.initial),
                "tries": len(self.orders)}

    def row(self) -> tuple[int, ...] | None:
        """Colours in the slots left to right, if every cube rests released in a slot."""
        out = [None, None, None]
        for colour, cube in enumerate(self.cubes):
            if not self.released(cube):
                return None
            xy = cube.pos(self.data)[:2]
            slot = next((k for k in range(3)
                         if np.linalg.norm(xy - self.slots[k]) <= SLOT_TOL), None)
            if slot is None or out[slot] is not None:
                return None
            out[slot] = colour
        return tuple(out)

    def on_substep(self) -> None:
        if self.button.update(self.data):
            row = self.row()
            self.pressed.append(row)
            self.lamp.set(self.model, "green" if row == self.target else "red")
            plan = self.plan()
            if self.cursor < len(plan) and plan[self.cursor] == CHECK and \
                    row == self.orders[self.cursor // 2]:
                self.cursor += 1

    def evaluate(self) -> Evaluation:
        if self.lamp.state == "red" and any(self.touched_by_fingers(c.body_id)
                                            for c in self.cubes):
            self.lamp.set(self.model, "off")  # a verdict holds until the row is touched
        row = self.row()
        self.is_stacked = self.is_stacked or self.stacked(self.cubes)
        solved = bool(self.pressed) and self.pressed[-1] == self.target and row == self.target
        # Ground-truth stage: a swap ends when the next row of the sequence stands in the
        # slots; a check ends with the press (see on_substep).
        plan = self.plan()
        if self.cursor < len(plan) and plan[self.cursor] != CHECK and \
                row == self.orders[self.cursor // 2 + 1]:
            self.cursor += 1
        reason = ""
        if self.is_stacked:
            reason = "a cube was left resting on another"
        elif self.fell_off(self.cubes):
            reason = "a cube fell off the table"
        success = solved and not reason
        stage, progress = self.advance(self.cursor, self.cursor / len(plan), solved=success)
        preds = {"row": list(row) if row else [], "target_order": list(self.target),
                 "presses": self.button.count, "lamp": self.lamp.state,
                 "tries_needed": len(self.orders)}
        return Evaluation(success=success, failure=bool(reason),
                          progress=progress, stage=stage, failure_reason=reason,
                          predicates=preds)
