"""rearrange_blocks — M(1).

Task: two identical mats and three block slots lie on one row: slot 0 on the first mat, slot
1 between the mats, slot 2 on the second mat. Two identical red cubes: one in the middle
slot, the other on one of the mats. Move the middle block onto the empty mat, press the
button once with the left arm, then move the block that was on a mat from the start back to
the middle slot.

Randomization: row y ~ U[-0.15, -0.08]; slots at x0 + (0, 0.12, 0.24) with x0 ~ U[-0.06,
-0.02] (the benchmark's row at x = 0.02..0.26, shifted 6 cm towards the centre so both arms
reach every slot); the mat that starts loaded uniformly of the two; one yaw
~ U[-0.3, 0.3] for both cubes; button x ~ U[-0.32, -0.24], y ~ U[-0.22, -0.12].

Success: exactly one press, made while both blocks sat on the mats; afterwards the block that
started on a mat rests in the middle slot (within 3 cm), the other still on its mat, no
finger touching either.
Failure: a second press; a press before both blocks were on the mats; the wrong block moved
to the middle slot after the press; a block off the table.

Memory: TMC M(1). Aliasing point: right after the press both blocks sit on mats and look
alike; only the first frames tell which one started there. The press leaves no trace either:
with both arms home and both mats loaded, the moment before it and the moment after it look
alike (v2's expert reopens the pressing hand at home), so only memory tells whether it was made.
"""

from __future__ import annotations

import numpy as np

from rmbench.sim.fixtures import Button, Mat
from rmbench.sim.objects import Cube
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m, rad), in the order drawn
ROW_X0 = Uniform(-0.06, -0.02)  # slot 0; slots 1 and 2 follow SLOT_SPACING apart
ROW_Y = Uniform(-0.15, -0.08)
CUBE_YAW = Uniform(-0.3, 0.3)  # one yaw for both cubes
BUTTON_X = Uniform(-0.32, -0.24)
BUTTON_Y = Uniform(-0.22, -0.12)

SLOT_TOL = 0.03
SLOT_SPACING = 0.12
MAT_SIDES = ("left", "right")


@register
class RearrangeBlocks(Task):
    name = "rearrange_blocks"
    gym_id = "rmbench/RearrangeBlocks-v2"
    tmc = "M(1)"
    step_limit = 700
    subtasks = ("move the middle block onto the empty mat", "press the button",
                "move the block that started on a mat back to the middle")
    instructions_seen = (
        "Put the middle block on the empty mat, press the button, then bring the block that "
        "was on a mat at the start to the middle.",
        "Move the centre block onto the free mat, push the button once, and return the "
        "originally placed block to the middle slot.",
        "Fill the empty mat with the middle block, press the button, then move the block "
        "that started on a mat into the middle.",
        "Shift the middle cube to the empty mat, press the button, and put the cube that "
        "began on a mat in the centre slot.",
    )
    instructions_unseen = (
        "Place the central block on the unused mat, hit the button, then carry the block "
        "that was already on a mat to the middle.",
        "After moving the middle cube onto the open mat and pressing the button, put the "
        "first mat's cube in the middle.",
    )
    aliasing_point = "after the press: both blocks sit on identical mats"
    aliasing_stage = 2
    hidden_keys = ("loaded_mat",)
    # the mat the block started on (the headline), and the press: both arms home with both
    # mats loaded, before it and after it (a released button shows no press)
    aliasing_pairs = ((({"loaded_mat": "left"}, 2, 1), ({"loaded_mat": "right"}, 2, 1)),
                      (({"loaded_mat": "left"}, 1, 2), ({"loaded_mat": "left"}, 2, 2)))

    # The state observation: the mats, the button, and the two identical cubes left to right
    # (a fixed order would tell the cube that started on a mat from the other).
    state_names = (*S.xy_names("mat_left"), *S.xy_names("mat_right"), *S.button_names("button"),
                   *S.pose_names("cube_left", S.CUBE_SYMMETRY),
                   *S.pose_names("cube_right", S.CUBE_SYMMETRY))

    def __init__(self):
        super().__init__()
        self.mats = {s: Mat(f"mat_{s}") for s in MAT_SIDES}
        self.cubes = (Cube("cube_a", size=0.04), Cube("cube_b", size=0.04))
        self.button = Button("button")
        self.slots = np.zeros((3, 2))
        self.loaded = "left"
        self.pressed_on_mats = False
        self.early_press = False

    @property
    def pieces(self):
        return (*self.mats.values(), self.button, *self.cubes)

    def initialize(self, rng: np.random.Generator) -> None:
        x0, y = ROW_X0.draw(rng), ROW_Y.draw(rng)
        self.slots = np.array([[x0 + k * SLOT_SPACING, y] for k in range(3)])
        self.mats["left"].move(self.model, self.slots[0])
        self.mats["right"].move(self.model, self.slots[2])
        self.loaded = self.choose("loaded_mat", MAT_SIDES[int(rng.integers(2))], MAT_SIDES)
        yaw = CUBE_YAW.draw(rng)
        # cube_a starts on a mat (the one to bring back), cube_b in the middle slot.
        self.cubes[0].place(self.data, self.mat_slot(self.loaded), yaw=yaw)
        self.cubes[1].place(self.data, self.slots[1], yaw=yaw)
        self.button.move(self.model, (BUTTON_X.draw(rng), BUTTON_Y.draw(rng)))
        self.button.reset()
        self.pressed_on_mats = False
        self.early_press = False

    def mat_slot(self, side: str) -> np.ndarray:
        return self.slots[0 if side == "left" else 2]

    @property
    def empty(self) -> str:
        return "right" if self.loaded == "left" else "left"

    def plan(self) -> list[int]:
        return [0, 1, 2]

    def environment_state(self) -> np.ndarray:
        m, d = self.model, self.data
        cubes = S.left_to_right(self.cubes, d)
        return S.assemble(self.state_names, [
            S.xy(self.mats["left"], m), S.xy(self.mats["right"], m), S.button(self.button, m, d),
            *(S.pose(c, d, S.CUBE_SYMMETRY) for c in cubes)])

    def hidden_state(self) -> dict:
        return {"loaded_mat": self.loaded}

    def _near(self, cube: Cube, xy) -> bool:
        return bool(np.linalg.norm(cube.pos(self.data)[:2] - xy) <= SLOT_TOL)

    def blocks_on_mats(self) -> bool:
        a, b = self.cubes
        return (self._near(a, self.mat_slot(self.loaded)) and self.released(a)
                and self._near(b, self.mat_slot(self.empty)) and self.released(b))

    def on_substep(self) -> None:
        if self.button.update(self.data):
            if self.button.count == 1 and self.blocks_on_mats():
                self.pressed_on_mats = True
            else:
                self.early_press = True

    def evaluate(self) -> Evaluation:
        a, b = self.cubes
        presses = self.button.count
        on_mats = self.blocks_on_mats()
        a_middle = self._near(a, self.slots[1]) and self.released(a)
        b_middle = self._near(b, self.slots[1]) and self.released(b)
        b_stays = self._near(b, self.mat_slot(self.empty)) and self.released(b)
        done = self.pressed_on_mats and presses == 1 and a_middle and b_stays
        preds = {"blocks_on_mats": on_mats, "presses": presses,
                 "pressed_on_mats": self.pressed_on_mats, "returned_block_in_middle": a_middle,
                 "other_block_on_mat": b_stays, "loaded_mat": self.loaded}
        reason = ""
        if presses > 1:
            reason = "button pressed more than once"
        elif self.early_press:
            reason = "button pressed before both blocks were on the mats"
        elif self.pressed_on_mats and b_middle:
            reason = "moved the wrong block back to the middle"
        elif self.fell_off((a, b)):
            reason = "a block fell off the table"
        stage = 0
        if on_mats:
            stage = 1
        if self.pressed_on_mats:
            stage = 2
        if done:
            stage = 3
        stage, progress = self.advance(stage, stage / 3)
        return Evaluation(success=done and not reason, failure=bool(reason), progress=progress,
                          stage=stage, failure_reason=reason, predicates=preds)
