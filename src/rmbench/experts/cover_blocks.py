"""Expert for cover_blocks: covers on left, middle, right; off again red, green, blue, each
set down behind its block. Each cover is carried by its knob, by the arm nearer to it."""

from __future__ import annotations

import numpy as np

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import Handle, nearer_side
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks.cover_blocks import BEHIND, COLOURS


@register_expert
class CoverBlocksExpert(ScriptedExpert):
    task = "cover_blocks"

    def plan(self, task):
        m, data = self.motion, task.data
        cover_on = {}  # block index -> cover index

        def carry(cover, xy):
            side = nearer_side(cover.knob_centre(data))
            yield from m.clear_for(side)
            handle = Handle(lambda: (cover.knob_centre(data), cover.yaw(data)), cover.knob)
            yield from m.carry(side, handle, (*xy, TABLE_TOP + cover.knob_base))

        for k in range(3):
            cube = task.cubes[k]
            cover_on[k] = k
            yield from self.label(k, carry(task.covers[k], cube.pos(data)[:2]))
        for colour in COLOURS:
            k = task.colours.index(colour)
            behind = task.cubes[k].pos(data)[:2] + np.array([0.0, BEHIND])
            yield from self.label(3 + k, carry(task.covers[cover_on[k]], behind))
        yield from self.label(3 + k, m.retreat())
