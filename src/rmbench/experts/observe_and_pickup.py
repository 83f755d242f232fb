"""Expert for observe_and_pickup: keep still until the screen is up, then pick up the
matching object with the arm on its side and lift it 0.1 m."""

from __future__ import annotations

import numpy as np

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import grasp_yaw
from rmbench.tasks.observe_and_pickup import OBSERVE_SECONDS

WAIT_STEPS = int(OBSERVE_SECONDS * 20) + 2  # a margin past the screen's rise


@register_expert
class ObserveAndPickupExpert(ScriptedExpert):
    task = "observe_and_pickup"

    def plan(self, task):
        m, data = self.motion, task.data
        yield from self.label(0, m.hold(WAIT_STEPS))

        def pick():
            obj = task.objects[task.target]
            pos = obj.pos(data)
            side = "left" if pos[0] < 0 else "right"
            yaw = grasp_yaw(side, pos[:2], obj.yaw(data), np.pi)
            yield from m.grasp(side, pos, yaw, obj.height)
            yield from m.hold(3)

        yield from self.label(1, pick())
