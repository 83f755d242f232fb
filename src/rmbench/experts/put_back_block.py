"""Expert for put_back_block: cube to the centre, press, cube back to its own mat."""

from __future__ import annotations

import numpy as np

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import grasp_yaw
from rmbench.sim.station import TABLE_TOP


@register_expert
class PutBackBlockExpert(ScriptedExpert):
    task = "put_back_block"

    def plan(self, task):
        m, data, model = self.motion, task.data, task.model
        side = "right" if task.original == "right" else "left"
        size = task.cube.size
        home_xy = task.mats[task.original].xy(model)

        def move_cube(dest_xy):
            pos = task.cube.pos(data)
            yaw = grasp_yaw(side, pos[:2], task.cube.yaw(data))
            yield from m.grasp(side, pos, yaw, size)
            yield from m.place(side, np.array([*dest_xy, TABLE_TOP]), yaw, size)

        yield from self.label(0, move_cube(task.centre))
        yield from self.label(1, m.go_home(side) if side == "right" else iter(()))
        yield from self.label(1, m.press("left", task.button.top(model)))
        yield from self.label(1, m.go_home("left"))
        yield from self.label(2, move_cube(home_xy))
        yield from self.label(2, m.hold(5))
