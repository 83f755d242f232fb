"""swap_blocks — M(1).

Task: three identical trays in a row hold two identical cubes; one tray is empty. Swap the
cubes through the empty tray — the first cube (the one nearer the empty tray, the left one
on a tie) to the empty tray, the second cube into the first one's tray, the first cube into
the second one's tray — then press the button.

Randomization: tray row centre x ~ U[-0.02, 0.02], y ~ U[-0.09, -0.05], trays 0.14 m apart;
the empty tray uniformly of the three; each cube offset in its tray by U[-0.008, 0.008] in x
and in y, with yaw ~ U[-0.2, 0.2]; button x ~ U[-0.05, 0.05], y ~ U[-0.24, -0.20] (the benchmark's y = -0.28,
brought 4-8 cm nearer the trays so the arms press it from above).

Success: each cube rests in the tray where the other started, the cubes were never stacked,
then exactly one press, no finger touching a cube.
Failure: a press before the swap is complete; a second press; one cube resting on the
other; a cube off the table.

Memory: TMC M(1). Aliasing point: mid-sequence the table again shows two full trays and an
empty one, as at the start of some other episode; only the past tells which move comes next
and where each cube started. Every move ends with its arm home and its fingers open as at
reset (v2; v1 left them at the half-open tray opening, which told a later moment from the
first).
"""

from __future__ import annotations

import numpy as np

from rmbench.sim.fixtures import Button, Tray
from rmbench.sim.objects import Cube
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m, rad), in the order drawn
ROW_X = Uniform(-0.02, 0.02)  # the middle tray's centre
ROW_Y = Uniform(-0.09, -0.05)
CUBE_OFFSET = Uniform(-0.008, 0.008)  # a cube from its tray's centre, in x and in y
CUBE_YAW = Uniform(-0.2, 0.2)
BUTTON_X = Uniform(-0.05, 0.05)
BUTTON_Y = Uniform(-0.24, -0.20)

TRAY_SPACING = 0.14
CUBE_RGBA = (0.95, 0.55, 0.1, 1.0)


def roles(empty: int) -> tuple[int, int]:
    """(tray of the first cube, tray of the second) for a given empty tray: the first cube is
    the one nearer the empty tray, the left one on a tie."""
    first = {0: 1, 1: 0, 2: 1}[empty]
    return first, 3 - empty - first


@register
class SwapBlocks(Task):
    name = "swap_blocks"
    gym_id = "rmbench/SwapBlocks-v2"
    tmc = "M(1)"
    step_limit = 1000
    subtasks = ("move the first block to the empty tray",
                "move the second block into the first block's tray",
                "move the first block into the second block's tray",
                "press the button")
    instructions_seen = (
        "Swap the two blocks using the empty tray, then press the button.",
        "Exchange the positions of the two cubes through the free tray and press the button.",
        "Use the empty tray to swap the blocks' trays, then push the button once.",
        "Make the two blocks trade trays with the help of the empty one, and finish by "
        "pressing the button.",
    )
    instructions_unseen = (
        "Switch the cubes between their trays via the spare tray, then hit the button.",
        "Have each block end up where the other one started, using the empty tray, and press "
        "the button.",
    )
    aliasing_point = "after any move: two full trays and an empty one, like a fresh start"
    aliasing_stage = 2
    hidden_keys = ("empty_tray",)
    place_predicates = ("first_cube_tray", "second_cube_tray")
    # both arms home with two full trays and an empty one: after the last move against the
    # start (the headline), and after the first and the second move against the start of
    # the layout whose empty tray that is (roles: empty 2 -> the first cube in tray 1)
    aliasing_pairs = ((({"empty_tray": 2}, 3, 2), ({"empty_tray": 2}, 0, 1)),
                      (({"empty_tray": 2}, 1, 2), ({"empty_tray": 1}, 0, 1)),
                      (({"empty_tray": 2}, 2, 2), ({"empty_tray": 0}, 0, 1)))

    # The state observation: the trays (left to right), the button, and the two identical
    # cubes left to right (a fixed order would tell the first cube from the second).
    state_names = (*(n for k in range(3) for n in S.xy_names(f"tray{k}")),
                   *S.button_names("button"), *S.pose_names("cube_left", S.CUBE_SYMMETRY),
                   *S.pose_names("cube_right", S.CUBE_SYMMETRY))

    def __init__(self):
        super().__init__()
        self.trays = tuple(Tray(f"tray{k}") for k in range(3))
        self.cubes = (Cube("cube_first", size=0.03, rgba=CUBE_RGBA),
                      Cube("cube_second", size=0.03, rgba=CUBE_RGBA))
        self.button = Button("button")
        self.empty = 2
        self.is_stacked = False
        self.early_press = False
        self.swapped_at_press = False

    @property
    def pieces(self):
        return (*self.trays, self.button, *self.cubes)

    def initialize(self, rng: np.random.Generator) -> None:
        xc, y = ROW_X.draw(rng), ROW_Y.draw(rng)
        for k, tray in enumerate(self.trays):
            tray.move(self.model, (xc + (k - 1) * TRAY_SPACING, y))
        self.empty = self.choose("empty_tray", int(rng.integers(3)), range(3))
        for cube, tray in zip(self.cubes, roles(self.empty), strict=True):
            offset = CUBE_OFFSET.draw(rng, 2)
            cube.place(self.data, self.trays[tray].xy(self.model) + offset,
                       yaw=CUBE_YAW.draw(rng))
        self.button.move(self.model, (BUTTON_X.draw(rng), BUTTON_Y.draw(rng)))
        self.button.reset()
        self.is_stacked = self.early_press = self.swapped_at_press = False

    def plan(self) -> list[int]:
        return [0, 1, 2, 3]

    def environment_state(self) -> np.ndarray:
        m, d = self.model, self.data
        return S.assemble(self.state_names, [
            *(S.xy(t, m) for t in self.trays), S.button(self.button, m, d),
            *(S.pose(c, d, S.CUBE_SYMMETRY) for c in S.left_to_right(self.cubes, d))])

    def hidden_state(self) -> dict:
        first, second = roles(self.empty)
        return {"empty_tray": self.empty, "first_tray": first, "second_tray": second}

    def tray_of(self, cube: Cube) -> int | None:
        """The tray a cube rests in, released; None while carried or outside every tray."""
        if not self.released(cube):
            return None
        xy = cube.pos(self.data)[:2]
        return next((k for k, t in enumerate(self.trays) if t.contains(self.model, xy)), None)

    def swapped(self) -> bool:
        first, second = roles(self.empty)
        return (self.tray_of(self.cubes[0]), self.tray_of(self.cubes[1])) == (second, first)

    def on_substep(self) -> None:
        if self.button.update(self.data):
            if self.button.count == 1 and self.swapped():
                self.swapped_at_press = True
            else:
                self.early_press = True

    def evaluate(self) -> Evaluation:
        first, second = roles(self.empty)
        where = (self.tray_of(self.cubes[0]), self.tray_of(self.cubes[1]))
        self.is_stacked = self.is_stacked or self.stacked(self.cubes)
        presses = self.button.count
        preds = {"first_cube_tray": -1 if where[0] is None else where[0],
                 "second_cube_tray": -1 if where[1] is None else where[1],
                 "presses": presses, "stacked": self.is_stacked, "empty_tray": self.empty}
        reason = ""
        if self.is_stacked:
            reason = "the cubes were stacked"
        elif presses > 1:
            reason = "button pressed more than once"
        elif self.early_press:
            reason = "button pressed before the swap was complete"
        elif self.fell_off(self.cubes):
            reason = "a cube fell off the table"
        stage = 0
        for s, target in ((1, (self.empty, second)), (2, (self.empty, first)),
                          (3, (second, first))):
            if where == target and self._stage >= s - 1:
                stage = s
        if self.swapped_at_press:
            stage = 4
        stage, progress = self.advance(stage, stage / 4)
        return Evaluation(success=stage == 4 and not reason, failure=bool(reason),
                          progress=progress, stage=stage, failure_reason=reason,
                          predicates=preds)
