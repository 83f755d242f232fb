"""battery_try — M(n).

Task: a holder with two slots stands at the centre, with an indicator lamp behind it; two
batteries lie to its left and right. Insert both batteries positive end first (pointing away
from the robot); while the lamp stays off, try the next orientation pair in the fixed order
[1,0], [1,1], [0,1] (0 = positive away, 1 = reversed; left, right), flipping only the battery
whose orientation changes. The lamp turns green when both sit in the slots the right way.

Randomization: holder centre x ~ U[-0.03, 0.03], y ~ U[-0.10, -0.06]; slots 7 cm apart (the
benchmark's 4 cm leaves no room for the fingers beside a neighbouring cell); batteries 0.17 m
left and right of the holder, y jitter U[-0.02, 0.02], lying along y with the positive end
either way and yaw noise U[-0.25, 0.25]; the correct pair uniformly of [1,0], [1,1], [0,1]
([0,0] is never correct).

Subtasks: each insertion and each flip ends with the cell set down and both arms back home
(as the benchmark's reference ends each with the arm back at its origin). Step limit 1200:
the benchmark's 1000 left the expert's longest episodes under 10% to spare once every try
ends with the way home.

Success: both batteries in their slots (within 1 cm, along the slot), in the correct
orientations, lamp on, neither touched by a finger.
Failure: a battery off the table.

Memory: TMC M(n). Aliasing point: the slots' contact plates hide the cells' ends from the
head camera, so after a failed try the holder looks like after any other failed try; only the
past tells which pairs were already tried. A try counts only with both arms home and settled
(every arm joint, averaged over the last ``HOME_WINDOW`` control steps, within
``HOME_JOINT_TOL`` of home, ``tasks/base.py``), so the view after the inserts is that view
too, arms included: nothing shows which arm moved last. Averaged, so that the count holds
under the collection's executed action noise too (v3 read each step: under that noise no try
was ever counted, and its datasets held one subtask). Without memory, flipping either cell at
random finds the pair within the step limit 75% of the time (``eval/chance.py``).
"""

from __future__ import annotations

import numpy as np

from rmbench.sim.fixtures import BatteryHolder, Lamp
from rmbench.sim.objects import Battery
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m, rad), in the order drawn
HOLDER_X = Uniform(-0.03, 0.03)
HOLDER_Y = Uniform(-0.10, -0.06)
BATTERY_Y_OFFSET = Uniform(-0.02, 0.02)  # a battery from the holder's y
BATTERY_YAW_NOISE = Uniform(-0.25, 0.25)  # added to the battery's pointing along y

PAIRS = ((1, 0), (1, 1), (0, 1))  # candidates for the hidden pair, also the order of tries
TRIES = ((0, 0), *PAIRS)
SLOT_TOL = 0.01
SIDE_OFFSET = 0.17
ENDS_HIDDEN_DX = 0.02  # a cell this close (across the slot) lies between the slot's plates


def flips(correct: tuple[int, int]) -> list[int]:
    """Which battery (0 left, 1 right) each try after the first flips, until ``correct``."""
    out = []
    for before, after in zip(TRIES, TRIES[1:], strict=False):
        out.append(0 if before[0] != after[0] else 1)
        if after == correct:
            break
    return out


@register
class BatteryTry(Task):
    name = "battery_try"
    gym_id = "rmbench/BatteryTry-v4"
    tmc = "M(n)"
    step_limit = 1200
    subtasks = ("insert the left battery", "insert the right battery",
                "flip the left battery", "flip the right battery")
    instructions_seen = (
        "Put both batteries into the holder and flip them until the light turns on.",
        "Insert the two batteries, then try other orientations until the lamp lights up.",
        "Load the battery holder and keep flipping batteries until the indicator turns green.",
        "Place the batteries in the slots positive end first, then find the orientation that "
        "lights the lamp.",
    )
    instructions_unseen = (
        "Fit both cells into the holder and reverse them one at a time until the light comes "
        "on.",
        "Get the indicator to light by inserting the batteries and trying orientations.",
    )
    aliasing_point = "after a failed try: the holder hides the cells' ends and the lamp is off"
    aliasing_stage = 3
    hidden_keys = ("correct",)
    # at the frame each try is counted, where the planner chooses the next flip: the second
    # count of one hidden order against the third of another (the headline), then within one
    # episode the inserts' count against the first flip's, and against the second flip's
    # (both before a left flip: after it one goes on to the right battery, the other ends)
    aliasing_pairs = ((({"correct": (1, 1)}, 3, 0), ({"correct": (0, 1)}, 4, 0)),
                      (({"correct": (0, 1)}, 2, 0), ({"correct": (0, 1)}, 3, 0)),
                      (({"correct": (0, 1)}, 2, 0), ({"correct": (0, 1)}, 4, 0)))

    # The state observation: the holder, the lamp, and the two identical cells left to right.
    # A cell's axis shows as cos/sin(2 yaw) (no polarity); which way its positive end points
    # (cos/sin of yaw) only while the end can be seen, zero once the slot's plates hide it.
    state_names = (*S.xy_names("holder"), *S.lamp_names("lamp"),
                   *(n for p in ("left", "right") for n in (
                       *S.pose_names(f"battery_{p}", 2), f"battery_{p}_ends_visible",
                       f"battery_{p}_plus_cos_yaw", f"battery_{p}_plus_sin_yaw")))

    def __init__(self):
        super().__init__()
        self.holder = BatteryHolder("holder")
        self.lamp = Lamp("lamp")
        self.batteries = (Battery("battery_left"), Battery("battery_right"))
        self.correct: tuple[int, int] = PAIRS[0]
        self.cursor = 0

    @property
    def pieces(self):
        return (self.holder, self.lamp, *self.batteries)

    def initialize(self, rng: np.random.Generator) -> None:
        hx, hy = HOLDER_X.draw(rng), HOLDER_Y.draw(rng)
        self.holder.move(self.model, (hx, hy))
        self.lamp.move(self.model, (hx, hy + 0.08))
        self.lamp.set(self.model, "off")
        for k, battery in enumerate(self.batteries):
            x = hx + (2 * k - 1) * SIDE_OFFSET
            pointing = np.pi / 2 if rng.uniform() < 0.5 else -np.pi / 2
            battery.place(self.data, (x, hy + BATTERY_Y_OFFSET.draw(rng)),
                          yaw=pointing + BATTERY_YAW_NOISE.draw(rng))
        drawn = PAIRS[int(rng.integers(len(PAIRS)))]
        self.correct = tuple(self.choose("correct", drawn, PAIRS))
        self.cursor = 0

    def plan(self) -> list[int]:
        return [0, 1, *(2 + k for k in flips(self.correct))]

    def ends_hidden(self, battery: Battery) -> bool:
        """Whether the head camera cannot tell the cell's ends apart: it lies in a slot, below
        the top of the contact plates at its ends."""
        p, h = battery.pos(self.data), self.holder
        for k in (0, 1):
            dx, dy = np.abs(p[:2] - h.slot(self.model, k))
            if dx <= ENDS_HIDDEN_DX and dy <= h.slot_length / 2 and p[2] - TABLE_TOP < h.plate[2]:
                return True
        return False

    def environment_state(self) -> np.ndarray:
        d, parts = self.data, [S.xy(self.holder, self.model), S.lamp(self.lamp)]
        for b in S.left_to_right(self.batteries, d):
            visible = 0.0 if self.ends_hidden(b) else 1.0
            parts += [S.pose(b, d, 2), [visible], visible * S.heading(b.yaw(d), 1)]
        return S.assemble(self.state_names, parts)

    def hidden_state(self) -> dict:
        return {"correct": list(self.correct)}

    def orientation(self, k: int) -> int | None:
        """0/1 if battery ``k`` rests, released, in slot ``k`` along the slot; else None."""
        battery = self.batteries[k]
        if not self.released(battery):
            return None
        if np.linalg.norm(battery.pos(self.data)[:2] - self.holder.slot(self.model, k)) > SLOT_TOL:
            return None
        along = battery.axis(self.data)[1]
        if abs(along) < 0.95:
            return None
        return 0 if along > 0 else 1

    def evaluate(self) -> Evaluation:
        config = (self.orientation(0), self.orientation(1))
        lit = config == self.correct
        self.lamp.set(self.model, "green" if lit else "off")
        plan = self.plan()
        # Inserts end with the cell in its slot positive-away; each flip ends when the pair
        # shows the next try of the sequence. Either counts only once both arms are home and
        # settled: with an arm still at the holder (v1) or still turning its wrist back (v2),
        # the frame the next step is chosen at would show which arm made the last move, and
        # so which try comes next, without memory.
        home = self.hands_home()
        while home and self.cursor < len(plan):
            if self.cursor < 2:
                done = config[self.cursor] == 0
            else:
                done = config == TRIES[self.cursor - 1]
            if not done:
                break
            self.cursor += 1
        reason = ""
        if self.fell_off(self.batteries):
            reason = "a battery fell off the table"
        success = lit and not reason
        stage, progress = self.advance(self.cursor, self.cursor / len(plan), solved=success)
        preds = {"left_orientation": -1 if config[0] is None else config[0],
                 "right_orientation": -1 if config[1] is None else config[1],
                 "lamp": self.lamp.state, "correct": list(self.correct), "hands_home": home}
        return Evaluation(success=success, failure=bool(reason), progress=progress,
                          stage=stage, failure_reason=reason, predicates=preds)
