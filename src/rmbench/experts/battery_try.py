"""Expert for battery_try: both batteries in positive-away, then flip through the fixed try
order while the lamp stays off. It learns the answer only from the lamp, as a policy would."""

from __future__ import annotations

from itertools import chain

import numpy as np

from rmbench.experts.base import ScriptedExpert, register_expert
from rmbench.experts.motion import Handle
from rmbench.sim.geometry import wrap_angle
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks.battery_try import PAIRS, SLOT_TOL, TRIES

OPENING = 0.5  # enough for a 24 mm cell, narrow beside the holder's plates
AWAY = np.pi / 2  # yaw of a positive end pointing away from the robot
SETTLE = 20  # steps an arm back home holds: its servos settle and the task counts the step
HOVER = 0.08  # halfway down (where a set-down is lined up) a held cell still clears the plates


@register_expert
class BatteryTryExpert(ScriptedExpert):
    task = "battery_try"

    def plan(self, task):
        m, data, model = self.motion, task.data, task.model

        def move(k, target_yaw, side):
            battery = task.batteries[k]
            slot = task.holder.slot(model, k)

            def locate():
                # fingers close across the cell: grasp yaws are the axis + 90 deg, mod 180 deg
                return battery.pos(data), float(np.arctan2(*battery.axis(data)[1::-1])) + np.pi / 2

            def seated():  # in its slot, pointing the way the expert meant
                axis = battery.axis(data)
                return bool(np.linalg.norm(battery.pos(data)[:2] - slot) <= SLOT_TOL
                            and axis[1] * np.sin(target_yaw) > 0.95)

            yield from m.clear_for(side)
            # in_hand: a cell must end within 1 cm of its slot's centre, with 8 mm of play to
            # the plates; under a drifting arm only steering by the cell's offset in the hand
            # gets it there reliably (see Motion.place).
            handle = Handle(locate, 2 * battery.radius, np.pi, OPENING, HOVER, in_hand=True)
            yield from m.carry(side, handle, (*slot, TABLE_TOP),
                               turn_to=lambda grip: wrap_angle(target_yaw - (grip - np.pi / 2)),
                               placed=seated)

        def step(k, target_yaw, side):
            # every step ends with its arm back home, where the task counts it; the hold lets
            # the servos settle there, so the next step always starts from one pose
            return chain(move(k, target_yaw, side), m.go_home(side), m.hold(SETTLE))

        # Each arm inserts the battery on its side; the left arm then makes every flip.
        yield from self.label(0, step(0, AWAY, "left"))
        yield from self.label(1, step(1, AWAY, "right"))
        for before, after in zip(TRIES, PAIRS, strict=False):
            if task.lamp.state == "green":
                break
            k = 0 if before[0] != after[0] else 1
            yield from self.label(2 + k, step(k, AWAY if after[k] == 0 else -AWAY, "left"))
