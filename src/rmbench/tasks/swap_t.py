"""swap_T — M(1).

Task: a red and a blue T-shaped block lie on the table side by side, each turned by a random
yaw. Pick both up (one per arm), then put each one down where the other lay, in the other's
orientation.

Randomization: which colour lies left uniformly; yaws ~ U[-0.75, 0.75]; T centres (the middle
of the stem) at x = -0.09 and +0.09, each plus U[-0.01, 0.01], y ~ U[-0.15, -0.10].

Success: each T within 2.5 cm (xy) and 15 degrees of the other's starting pose, resting on
the table, neither touched by a finger, after the plan's lifts: the left T raised 5 cm off
the table, then the right one (a T never lifted, only pushed along the table into place,
does not count).
Failure: a T off the table or tipped over on the table.

Memory: TMC M(1). Aliasing point: once both are lifted (and held in a fixed carrying pose),
their starting poses are no longer visible.
"""

from __future__ import annotations

import numpy as np

from rmbench.sim.geometry import wrap_angle
from rmbench.sim.objects import TBlock
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

SIDE_X = 0.09  # m: the left T's centre lies near x = -SIDE_X, the right one's near +SIDE_X
# Randomization (m, rad), in the order drawn
YAW = Uniform(-0.75, 0.75)
CENTRE_X_OFFSET = Uniform(-0.01, 0.01)  # from -SIDE_X or +SIDE_X
CENTRE_Y = Uniform(-0.15, -0.10)

POS_TOL = 0.025
YAW_TOL = np.deg2rad(15)
LIFTED = 0.05
COLOURS = ((0.85, 0.1, 0.1, 1.0), (0.1, 0.25, 0.85, 1.0))


@register
class SwapT(Task):
    name = "swap_T"
    gym_id = "rmbench/SwapT-v1"
    tmc = "M(1)"
    step_limit = 600
    subtasks = ("pick up the left T block", "pick up the right T block",
                "put the right T where the left one was",
                "put the left T where the right one was")
    instructions_seen = (
        "Swap the two T-shaped blocks: each one goes where the other was, facing the same way.",
        "Pick up both T blocks and put each in the other's place and orientation.",
        "Exchange the red and the blue T, matching the position and angle of the other.",
        "Lift the two T blocks and set each one down at the other's starting pose.",
    )
    instructions_unseen = (
        "Make the T blocks trade places, each taking over the other's pose.",
        "Move each T-shaped piece to where the other one lay, turned the same way.",
    )
    aliasing_point = "both T blocks held up: their starting poses are no longer visible"
    aliasing_stage = 2
    hidden_keys = ("yaws",)
    # both Ts held (the headline), and the left T still held once the right one is down,
    # where only the right T's starting yaw differs
    aliasing_pairs = ((({"yaws": (0.5, -0.3)}, 2, 2), ({"yaws": (-0.6, 0.2)}, 2, 2)),
                      (({"yaws": (0.5, -0.3)}, 3, 2), ({"yaws": (0.5, 0.2)}, 3, 2)))

    # The state observation: the red T and the blue T (their colours tell them apart).
    state_names = (*S.pose_names("t_red", 1), *S.pose_names("t_blue", 1))

    def __init__(self):
        super().__init__()
        self.blocks = (TBlock("t_left"), TBlock("t_right"))
        self.starts = np.zeros((2, 3))  # x, y, yaw of the left and right T at the start

    @property
    def pieces(self):
        return self.blocks

    def initialize(self, rng: np.random.Generator) -> None:
        colours = COLOURS if rng.uniform() < 0.5 else COLOURS[::-1]
        yaws = tuple(float(y) for y in YAW.draw(rng, 2))
        yaws = self.choose("yaws", yaws)
        if len(yaws) != 2 or not all(float(y) in YAW for y in yaws):
            raise ValueError(f"{self.name}: yaws must be two angles in "
                             f"[{YAW.low}, {YAW.high}], got {yaws}")
        for k, block in enumerate(self.blocks):
            x = (2 * k - 1) * SIDE_X + CENTRE_X_OFFSET.draw(rng)
            y = CENTRE_Y.draw(rng)
            self.starts[k] = (x, y, float(yaws[k]))
            block.paint(self.model, colours[k])
            block.place(self.data, (x, y), yaw=float(yaws[k]))

    def plan(self) -> list[int]:
        return [0, 1, 2, 3]

    def environment_state(self) -> np.ndarray:
        red = max(self.blocks, key=lambda b: self.model.geom_rgba[b.geom_id][0])
        blue = self.blocks[1] if red is self.blocks[0] else self.blocks[0]
        return S.assemble(self.state_names, [S.pose(red, self.data, 1), S.pose(blue, self.data, 1)])

    def hidden_state(self) -> dict:
        # unrounded: the yaws given back fix this very episode
        return {"yaws": self.starts[:, 2].tolist(), "starts": self.starts.tolist()}

    def at_pose(self, block: TBlock, pose) -> bool:
        d = self.data
        return bool(np.linalg.norm(block.pos(d)[:2] - pose[:2]) <= POS_TOL
                    and abs(wrap_angle(block.yaw(d) - pose[2])) <= YAW_TOL
                    and self.released(block))

    def evaluate(self) -> Evaluation:
        d = self.data
        left, right = self.blocks
        lifted = [bool(b.pos(d)[2] > TABLE_TOP + b.rest_height + LIFTED) for b in self.blocks]
        right_done = self.at_pose(right, self.starts[0])
        left_done = self.at_pose(left, self.starts[1])
        stage = 0
        if lifted[0]:
            stage = 1
        if self._stage >= 1 and lifted[1]:
            stage = 2
        if self._stage >= 2 and right_done:
            stage = 3
        if self._stage >= 3 and right_done and left_done:
            stage = 4
        reason = ""
        if self.fell_off(self.blocks):
            reason = "a T block fell off the table"
        elif any(not b.upright(d, 0.5) and b.speed(d) < 0.02
                 and not self.touched_by_fingers(b.body_id) for b in self.blocks):
            reason = "a T block tipped over"
        stage, progress = self.advance(stage, stage / 4)
        preds = {"left_lifted": lifted[0], "right_lifted": lifted[1],
                 "right_at_left_start": right_done, "left_at_right_start": left_done}
        return Evaluation(success=stage == 4 and not reason, failure=bool(reason),
                          progress=progress, stage=stage, failure_reason=reason,
                          predicates=preds)
