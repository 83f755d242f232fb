"""Expert for swap_T: each arm picks up the T on its side, turns it to a fixed carrying yaw
and holds it aside; the right arm then sets its T down in the left T's starting pose and
goes home, and the left arm sets its T down in the right T's starting pose."""

from __future__ import annotations

import numpy as np

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import FINE_SPEED, grasp_yaw
from rmbench.sim.geometry import wrap_angle
from rmbench.sim.station import TABLE_TOP

CARRY_YAW = 0.0  # every T is held at this yaw while lifted: the carried pose says nothing
WAIT = {"left": (-0.26, -0.12, TABLE_TOP + 0.20), "right": (0.26, -0.12, TABLE_TOP + 0.20)}


@register_expert
class SwapTExpert(ScriptedExpert):
    task = "swap_T"

    def plan(self, task):
        m, data = self.motion, task.data
        grips = {}

        def pick(side, block):
            pos, t_yaw = block.pos(data), block.yaw(data)
            grips[side] = grasp_yaw(side, pos[:2], t_yaw, symmetry=np.pi)
            yield from m.grasp(side, pos, grips[side], block.thickness)

        def carry(side, block):
            g = grips[side]
            turn = wrap_angle(CARRY_YAW - block.yaw(data))
            yield from m.twist(side, turn)
            grips[side] = g + turn  # gripper yaw while the T sits at CARRY_YAW
            yield from m.move_to(side, WAIT[side], grips[side])

        def put(side, block, pose):
            turn = wrap_angle(pose[2] - CARRY_YAW)
            yield from m.twist(side, turn)
            g = grips[side] + turn
            yield from m.place(side, (pose[0], pose[1], TABLE_TOP), g, block.thickness)
            yield from m.move_by(side, (0, 0, 0.05), g, FINE_SPEED)

        left, right = task.blocks
        # Carrying a lifted T aside serves the next subtask: the env counts a T as picked up
        # once it is off the table.
        yield from self.label(0, pick("left", left))
        yield from self.label(1, carry("left", left))
        yield from self.label(1, pick("right", right))
        yield from self.label(2, carry("right", right))
        yield from self.label(2, put("right", right, task.starts[0]))
        yield from self.label(3, m.go_home("right"))
        yield from self.label(3, put("left", left, task.starts[1]))
        yield from self.label(3, m.hold(3))
