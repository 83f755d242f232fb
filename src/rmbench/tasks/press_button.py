"""press_button — M(n).

Task: three buttons in a row (left, middle, confirm) and two number tiles behind the left
and middle buttons showing d1 and d2. Press the left button d1 times and the middle button
d2 times (left arm), then the confirm button once (right arm).

Randomization: d1 ~ U{1..9}, d2 ~ U{1..10-d1}; row y ~ U[-0.16, -0.12]; left button
x ~ U[-0.30, -0.24], middle U[0.13, 0.16] m to its right, confirm x ~ U[0.18, 0.26]; tiles
0.12 m behind the left and middle buttons.

Success: the confirm button pressed once, when the left count was exactly d1 and the middle
count exactly d2. A press counts once per push (travel past 6 mm, back above 3 mm).
Failure: more than d1 (d2) presses of the left (middle) button; a confirm with wrong counts;
any press after the confirm.

Memory: TMC M(n). Aliasing point: a released button looks the same after any number of
presses; only the past tells how many have been made (the count grows with the episode).
"""

from __future__ import annotations

import numpy as np

from rmbench.sim.fixtures import Button, NumberTile
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m), in the order drawn (after the digits)
ROW_Y = Uniform(-0.16, -0.12)
LEFT_X = Uniform(-0.30, -0.24)
MIDDLE_GAP = Uniform(0.13, 0.16)  # the middle button from the left one
CONFIRM_X = Uniform(0.18, 0.26)

TILE_OFFSET = 0.12


@register
class PressButton(Task):
    name = "press_button"
    gym_id = "rmbench/PressButton-v2"
    tmc = "M(n)"
    step_limit = 1500
    # One subtask per push, as the benchmark's reference annotates them: the plan repeats the
    # first two d1 and d2 times, and each push ends where the simulator counts it.
    subtasks = ("press the left button once", "press the middle button once",
                "press the confirm button")
    instructions_seen = (
        "Press the left button as many times as its number shows, the middle button as many "
        "times as its number shows, then press the confirm button.",
        "Push each of the two buttons the number of times written behind it, then confirm.",
        "Count out the left number on the left button and the middle number on the middle "
        "button, then hit confirm.",
        "Press the left and middle buttons the shown numbers of times and finish with the "
        "confirm button.",
    )
    instructions_unseen = (
        "Tap the left button to match its digit, tap the middle one to match its digit, and "
        "then press confirm.",
        "Enter the two displayed numbers by pressing their buttons, then press the confirm "
        "button once.",
    )
    aliasing_point = "between presses: a released button looks the same after any count"
    aliasing_stage = 1  # after the first press
    hidden_keys = ("d1", "d2")
    # the arm over a button between presses: the last left press against an earlier one (the
    # headline), the first against the second, and the last middle press against the first
    aliasing_pairs = ((({"d1": 3, "d2": 2}, 2, 1), ({"d1": 3, "d2": 2}, 3, 1)),
                      (({"d1": 3, "d2": 2}, 1, 1), ({"d1": 3, "d2": 2}, 2, 1)),
                      (({"d1": 3, "d2": 2}, 4, 1), ({"d1": 3, "d2": 2}, 5, 1)))

    # The state observation: the three buttons (left, middle, confirm) and the two tiles with
    # the digit each shows. Press counts are not in it: a released button shows none.
    state_names = (*S.button_names("button_left"), *S.button_names("button_middle"),
                   *S.button_names("button_confirm"), *S.xy_names("tile_left"), "tile_left_digit",
                   *S.xy_names("tile_middle"), "tile_middle_digit")

    def __init__(self):
        super().__init__()
        self.left = Button("button_left")
        self.middle = Button("button_middle")
        self.confirm = Button("button_confirm", cap_rgba=(0.15, 0.7, 0.2, 1.0))
        self.tiles = (NumberTile("tile_left"), NumberTile("tile_middle"))
        self.d1 = self.d2 = 1
        self.events: list[str] = []

    @property
    def buttons(self) -> dict[str, Button]:
        return {"left": self.left, "middle": self.middle, "confirm": self.confirm}

    @property
    def pieces(self):
        return (*self.buttons.values(), *self.tiles)

    def initialize(self, rng: np.random.Generator) -> None:
        d1 = int(rng.integers(1, 10))
        d2 = int(rng.integers(1, 11 - d1))
        self.d1 = self.choose("d1", d1, range(1, 10))
        self.d2 = self.choose("d2", min(d2, 10 - self.d1), range(1, 11 - self.d1))
        y = ROW_Y.draw(rng)
        xl = LEFT_X.draw(rng)
        xm = xl + MIDDLE_GAP.draw(rng)
        xc = CONFIRM_X.draw(rng)
        for button, x in ((self.left, xl), (self.middle, xm), (self.confirm, xc)):
            button.move(self.model, (x, y))
            button.reset()
        for tile, x, digit in ((self.tiles[0], xl, self.d1), (self.tiles[1], xm, self.d2)):
            tile.move(self.model, (x, y + TILE_OFFSET))
            tile.show(self.model, digit)
        self.events = []

    def plan(self) -> list[int]:
        return [0] * self.d1 + [1] * self.d2 + [2]

    def environment_state(self) -> np.ndarray:
        m, d = self.model, self.data
        return S.assemble(self.state_names, [
            *(S.button(b, m, d) for b in self.buttons.values()),
            *((S.xy(t, m), [t.digit]) for t in self.tiles)])

    def hidden_state(self) -> dict:
        return {"d1": self.d1, "d2": self.d2}

    def on_substep(self) -> None:
        for name, button in self.buttons.items():
            if button.update(self.data):
                self.events.append(name)

    def evaluate(self) -> Evaluation:
        counts = {n: b.count for n, b in self.buttons.items()}
        preds = {"left_presses": counts["left"], "middle_presses": counts["middle"],
                 "confirm_presses": counts["confirm"], "d1": self.d1, "d2": self.d2}
        reason = ""
        confirmed_at = self.events.index("confirm") if "confirm" in self.events else None
        if counts["left"] > self.d1:
            reason = f"left button pressed {counts['left']} times, needed {self.d1}"
        elif counts["middle"] > self.d2:
            reason = f"middle button pressed {counts['middle']} times, needed {self.d2}"
        elif confirmed_at is not None:
            before = self.events[:confirmed_at]
            if before.count("left") != self.d1 or before.count("middle") != self.d2:
                reason = (f"confirmed after {before.count('left')} left and "
                          f"{before.count('middle')} middle presses, needed {self.d1} and {self.d2}")
            elif len(self.events) > confirmed_at + 1:
                reason = "button pressed after the confirm"
        success = confirmed_at is not None and not reason
        stage = min(counts["left"], self.d1) + min(counts["middle"], self.d2) + \
            min(counts["confirm"], 1)
        total = self.d1 + self.d2 + 1
        if reason:
            stage = 0  # a failed episode keeps the progress it had, no more
        stage, progress = self.advance(stage, stage / total)
        return Evaluation(success=success, failure=bool(reason), progress=progress, stage=stage,
                          failure_reason=reason, predicates=preds)
