"""put_back_block — M(1).

Task: four identical mats lie around a centre point; a red cube sits on one of them. Move
the cube to the centre, press the button with the left arm, then put the cube back on the
mat it came from.

Randomization: centre x ~ U[-0.02, 0.06], y ~ U[-0.115, -0.095]; mat offset from the centre
d ~ U[0.10, 0.13] (left, right, front, back); the cube's mat uniformly among the four, with
yaw ~ U[-0.4, 0.4]; button x ~ U[-0.38, -0.30], y ~ U[-0.22, -0.12].

Success: exactly one press, made while the cube was at the centre (within 4 cm); afterwards
the cube rests on its original mat (within 3 cm) and no finger touches it.
Failure: a second press; a press before the cube reached the centre; the cube released on a
wrong mat after the press; the cube off the table.

Memory: TMC M(1). Aliasing point: with the cube at the centre (before and after the press)
the four mats look the same; only the first frames tell which mat to return to.
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
CENTRE_X = Uniform(-0.02, 0.06)  # the point the four mats lie around
CENTRE_Y = Uniform(-0.115, -0.095)
MAT_OFFSET = Uniform(0.10, 0.13)  # each mat from the centre
BUTTON_X = Uniform(-0.38, -0.30)
BUTTON_Y = Uniform(-0.22, -0.12)
CUBE_YAW = Uniform(-0.4, 0.4)

MAT_NAMES = ("left", "right", "front", "back")
MAT_DIRECTIONS = {"left": (-1, 0), "right": (1, 0), "front": (0, -1), "back": (0, 1)}
CENTRE_TOL = 0.04
MAT_TOL = 0.03


@register
class PutBackBlock(Task):
    name = "put_back_block"
    gym_id = "rmbench/PutBackBlock-v1"
    tmc = "M(1)"
    step_limit = 500
    subtasks = ("move the block to the centre", "press the button",
                "put the block back on its original mat")
    instructions_seen = (
        "Move the red block to the centre, press the button, then put the block back where it was.",
        "Bring the block to the middle of the mats, press the button, and return the block to its mat.",
        "Place the cube at the centre, push the button once, then put the cube back on its original mat.",
        "Carry the red cube to the centre point, press the button, and return it to the mat it started on.",
    )
    instructions_unseen = (
        "Shift the cube into the middle, hit the button, then restore the cube to its starting mat.",
        "Take the block to the centre, press the button one time, and put it back on the mat it came from.",
    )
    aliasing_point = "cube at the centre, around the press: the four mats look identical"
    aliasing_stage = 2  # the press has happened; the cube still sits at the centre
    hidden_keys = ("original_mat",)
    aliasing_pairs = ((({"original_mat": "left"}, 2, 1), ({"original_mat": "front"}, 2, 1)),)

    # The state observation (docs/reference/observations.md): the four mats, the button, the cube.
    state_names = (*(n for m in MAT_NAMES for n in S.xy_names(f"mat_{m}")),
                   *S.button_names("button"), *S.pose_names("cube", S.CUBE_SYMMETRY))

    def __init__(self):
        super().__init__()
        self.cube = Cube("cube", size=0.04)
        self.mats = {n: Mat(f"mat_{n}") for n in MAT_NAMES}
        self.button = Button("button")
        self.centre = np.zeros(2)
        self.original = "left"
        self.pressed_at_centre = False
        self.press_without_centre = False

    @property
    def pieces(self):
        return (*self.mats.values(), self.button, self.cube)

    def initialize(self, rng: np.random.Generator) -> None:
        self.centre = np.array([CENTRE_X.draw(rng), CENTRE_Y.draw(rng)])
        d = MAT_OFFSET.draw(rng)
        for n, mat in self.mats.items():
            mat.move(self.model, self.centre + d * np.asarray(MAT_DIRECTIONS[n]))
        self.original = self.choose("original_mat", MAT_NAMES[int(rng.integers(4))], MAT_NAMES)
        self.button.move(self.model, (BUTTON_X.draw(rng), BUTTON_Y.draw(rng)))
        self.button.reset()
        self.cube.place(self.data, self.mats[self.original].xy(self.model),
                        yaw=CUBE_YAW.draw(rng))
        self.pressed_at_centre = False
        self.press_without_centre = False

    def plan(self) -> list[int]:
        return [0, 1, 2]

    def environment_state(self) -> np.ndarray:
        m, d = self.model, self.data
        return S.assemble(self.state_names, [*(S.xy(self.mats[n], m) for n in MAT_NAMES),
                                             S.button(self.button, m, d),
                                             S.pose(self.cube, d, S.CUBE_SYMMETRY)])

    def hidden_state(self) -> dict:
        return {"original_mat": self.original, "centre": self.centre.round(4).tolist()}

    def cube_at_centre(self) -> bool:
        return bool(np.linalg.norm(self.cube.pos(self.data)[:2] - self.centre) <= CENTRE_TOL)

    def on_substep(self) -> None:
        if self.button.update(self.data):
            if self.button.count == 1 and self.cube_at_centre():
                self.pressed_at_centre = True
            else:
                self.press_without_centre = True

    def mat_under_cube(self) -> str | None:
        xy = self.cube.pos(self.data)[:2]
        for n, mat in self.mats.items():
            if mat.contains(self.model, xy, MAT_TOL):
                return n
        return None

    def evaluate(self) -> Evaluation:
        settled = self.released(self.cube)
        at_centre = self.cube_at_centre()
        presses = self.button.count
        on_mat = self.mat_under_cube()
        back = presses == 1 and self.pressed_at_centre and on_mat == self.original and settled
        preds = {"cube_at_centre": at_centre, "cube_settled": settled, "presses": presses,
                 "pressed_at_centre": self.pressed_at_centre, "mat_under_cube": on_mat or "",
                 "original_mat": self.original}
        reason = ""
        if presses > 1:
            reason = "button pressed more than once"
        elif self.press_without_centre:
            reason = "button pressed before the block was at the centre"
        elif presses == 1 and settled and on_mat not in (None, self.original):
            reason = f"block put back on the wrong mat ({on_mat} instead of {self.original})"
        elif self.fell_off((self.cube,)):
            reason = "block fell off the table"
        stage = 0
        if at_centre and settled:
            stage = 1
        if self.pressed_at_centre:
            stage = 2
        if back:
            stage = 3
        stage, progress = self.advance(stage, stage / 3)
        return Evaluation(success=back and not reason, failure=bool(reason), progress=progress,
                          stage=stage, failure_reason=reason, predicates=preds)
