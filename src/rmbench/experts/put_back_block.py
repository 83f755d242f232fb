"""Expert for put_back_block: cube to the centre, press, cube back to its own mat."""

from __future__ import annotations

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.sim.station import TABLE_TOP


@register_expert
class PutBackBlockExpert(ScriptedExpert):
    task = "put_back_block"

    def plan(self, task):
        m, model = self.motion, task.model
        side = "right" if task.original == "right" else "left"
        size = task.cube.size
        home_xy = task.mats[task.original].xy(model)

        def move_cube(dest_xy):
            yield from m.carry(side, self.handle(task.cube, size), (*dest_xy, TABLE_TOP))

        yield from self.label(0, move_cube(task.centre))
        yield from self.label(1, m.go_home(side) if side == "right" else iter(()))
        yield from self.label(1, m.press("left", task.button.top(model),
                                             count=lambda: task.button.count))
        yield from self.label(1, m.go_home("left"))
        yield from self.label(2, move_cube(home_xy))
        yield from self.label(2, m.hold(5))
