"""Expert for blocks_ranking_try: check with the button; while the lamp is red, apply the
next swap of the fixed sequence through a parking spot in front of the row, and check again.

The expert knows the target only through the verdicts it reads off the task, exactly what a
policy sees: the lamp after each press.
"""

from __future__ import annotations

import numpy as np

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks.blocks_ranking_try import PARK_OFFSET, SWAP_SUBTASK, SWAPS


@register_expert
class BlocksRankingTryExpert(ScriptedExpert):
    task = "blocks_ranking_try"

    def plan(self, task):
        m, model = self.motion, task.model
        slot_of = {c: k for k, c in enumerate(task.initial)}  # colour -> slot, as moved

        # One arm does everything: the button is on the left, and a single arm never has to
        # wait for the other to clear the row.
        def move(colour, xy):
            cube = task.cubes[colour]
            yield from m.carry("left", self.handle(cube, cube.size), (*xy, TABLE_TOP))

        def check():
            yield from m.press("left", task.button.top(model), approach="left" not in m.away,
                               count=lambda: task.button.count)

        for pair in (None, *SWAPS):
            if pair is not None:
                a, b = pair
                ca = next(c for c, s in slot_of.items() if s == a)
                cb = next(c for c, s in slot_of.items() if s == b)
                park = task.slots[a] + np.array([0.0, -PARK_OFFSET])
                sub = SWAP_SUBTASK[pair]
                yield from self.label(sub, move(ca, park))
                yield from self.label(sub, move(cb, task.slots[a]))
                yield from self.label(sub, move(ca, task.slots[b]))
                slot_of[ca], slot_of[cb] = b, a
            yield from self.label(0, check())
            yield from self.label(0, m.hold(2))
            if task.lamp.state == "green":
                break
        yield from self.label(0, m.go_home("left"))
