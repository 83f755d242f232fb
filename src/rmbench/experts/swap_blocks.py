"""Expert for swap_blocks: three moves through the empty tray, each by the arm nearer the
cube, then a press."""

from __future__ import annotations

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import nearer_side
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks.swap_blocks import roles

TRAY_OPENING = 0.6  # fingers half open: a full opening would land on the tray walls


@register_expert
class SwapBlocksExpert(ScriptedExpert):
    task = "swap_blocks"

    def plan(self, task):
        m, data, model = self.motion, task.data, task.model
        first_cube, second_cube = task.cubes
        first, second = roles(task.empty)

        def move(cube, tray):
            side = nearer_side(cube.pos(data))
            yield from m.carry(side, self.handle(cube, cube.size, opening=TRAY_OPENING),
                               (*task.trays[tray].xy(model), TABLE_TOP))

        # Each retreat is labelled with the subtask it makes room for and is its own segment,
        # so every move starts with both arms at home, as at the start of an episode.
        moves = ((first_cube, task.empty), (second_cube, first), (first_cube, second))
        for k, (cube, tray) in enumerate(moves):
            yield from self.label(k, move(cube, tray))
            # home with the fingers open as at reset, not at the tray opening
            yield from self.label(k + 1, m.retreat_open())
        top = task.button.top(model)
        side = nearer_side(top)
        yield from self.label(3, m.press(side, top, count=lambda: task.button.count))
        yield from self.label(3, m.go_home(side))
