"""Expert for rearrange_blocks: middle block to the empty mat, press, the originally
mat-borne block to the middle; each block moved by the arm nearer to it."""

from __future__ import annotations

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import nearer_side
from rmbench.sim.station import TABLE_TOP


@register_expert
class RearrangeBlocksExpert(ScriptedExpert):
    task = "rearrange_blocks"

    def plan(self, task):
        m, data = self.motion, task.data
        returning, middle = task.cubes

        def move(cube, dest_xy):
            side = nearer_side(cube.pos(data))
            yield from m.clear_for(side)
            yield from m.carry(side, self.handle(cube, cube.size), (*dest_xy, TABLE_TOP))

        # Retreats belong to the subtask they make room for; each is its own segment, so the
        # next segment starts with the arms at home.
        yield from self.label(0, move(middle, task.mat_slot(task.empty)))
        yield from self.label(1, m.retreat())
        yield from self.label(1, m.press("left", task.button.top(task.model),
                                             count=lambda: task.button.count))
        # home with the fingers open, as before the press (v1 kept them closed: at home with
        # both mats loaded, the closed hand told that the press was made)
        yield from self.label(2, m.retreat_open())
        yield from self.label(2, move(returning, task.slots[1]))
        yield from self.label(2, m.hold(5))
