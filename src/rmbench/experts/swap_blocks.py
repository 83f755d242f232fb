"""Expert for swap_blocks: three moves through the empty tray, each by the arm nearer the
cube, then a press."""

from __future__ import annotations

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import OPEN, nearer_side
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks.swap_blocks import roles

TRAY_OPENING = 0.6  # fingers half open: a full opening would land on the tray walls
OPEN_SETTLE = 15  # steps for fingers reopened at home to come to rest


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

        def back_home():
            # home with the fingers open as at reset: a hand left half open (the tray
            # opening) would tell every later moment from the episode's first without memory
            moved = sorted(m.away)
            yield from m.retreat()
            for side in moved:
                yield from m.gripper(side, OPEN)
            if moved:
                yield from m.hold(OPEN_SETTLE)

        # Each retreat is labelled with the subtask it makes room for and is its own segment,
        # so every move starts with both arms at home, as at the start of an episode.
        moves = ((first_cube, task.empty), (second_cube, first), (first_cube, second))
        for k, (cube, tray) in enumerate(moves):
            yield from self.label(k, move(cube, tray))
            yield from self.label(k + 1, back_home())
        top = task.button.top(model)
        side = nearer_side(top)
        yield from self.label(3, m.press(side, top, count=lambda: task.button.count))
        yield from self.label(3, m.go_home(side))
