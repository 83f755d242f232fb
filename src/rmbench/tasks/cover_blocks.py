"""cover_blocks — M(n).

Task: three cubes — red, green and blue in a random order — stand in a row, with three
identical covers (upside-down cups) behind them. Cover the blocks left, middle, right; then
uncover them in the order red, green, blue, setting each cover down 0.13 m behind its block.

Randomization: row centre x ~ U[-0.02, 0.02], blocks 0.2 m apart at y ~ U[-0.17, -0.15]
(the benchmark's y = -0.18, a little nearer the arms' sweet spot); the colour order uniformly
of the six; covers 0.13 m behind their blocks; yaws ~ U[-0.2, 0.2].

Success: the covered/uncovered state of the blocks (left, middle, right; settled states
only, while no cover is held) runs exactly 000 -> 100 -> 110 -> 111 -> (red uncovered) ->
(green uncovered) -> (blue uncovered). A block is covered where a cover stands down on the
table around it (the cup is 7.6 cm across, the block 4 cm: up to 1.8 cm off centre a side).
Failure: any other settled state; a block or cover off the table; a cover knocked over, or a
block resting on an edge or against something (a block turned onto another face, all of one
colour, is as good as upright).
Progress per stage: 0, 0.05, 0.1, 0.15, 0.3, 0.6, 1.0.

Memory: TMC M(n). Aliasing point: with all three covered the colours are invisible; the robot
must remember which colour is under which cover (and, while uncovering, which it already
revealed).
"""

from __future__ import annotations

import itertools

import numpy as np

from rmbench.sim.objects import Cover, Cube
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m, rad), in the order drawn
ROW_X = Uniform(-0.02, 0.02)  # the middle block
ROW_Y = Uniform(-0.17, -0.15)
YAW = Uniform(-0.2, 0.2)  # each block and each cover

COLOURS = {"red": (0.85, 0.1, 0.1, 1.0), "green": (0.1, 0.7, 0.2, 1.0),
           "blue": (0.1, 0.25, 0.85, 1.0)}
ORDERS = tuple(itertools.permutations(COLOURS))
SPACING = 0.2
BEHIND = 0.13
PROGRESS = (0.0, 0.05, 0.1, 0.15, 0.3, 0.6, 1.0)
DOWN = 0.01  # a cover's bottom this close to the table stands on it
# A cover over a cube (the cube inside its cup's square), its rim lower than the cube's top,
# hides the cube from the head camera (its segmentation shows no cube pixel once the rim is
# 3 cm up).
HIDDEN_RIM = 0.04


@register
class CoverBlocks(Task):
    name = "cover_blocks"
    gym_id = "rmbench/CoverBlocks-v3"
    tmc = "M(n)"
    step_limit = 1500
    # Subtasks name the cover to move by where it stands, as a plan step is carried out: the
    # colour under each cover is what memory must recover, so it is the planner's to resolve
    # (from o_0 and the key memory), not hidden in the text the executor reads.
    subtasks = ("cover the left block", "cover the middle block", "cover the right block",
                "uncover the left block", "uncover the middle block", "uncover the right block")
    instructions_seen = (
        "Cover the three blocks from left to right, then uncover them in the order red, green, "
        "blue.",
        "Put a cover on each block, left first, and then lift the covers off the red, green and "
        "blue blocks in that order.",
        "Hide the blocks under the covers from left to right, then reveal red, then green, then "
        "blue.",
        "Cover every block starting from the left, and uncover them red first, green second, "
        "blue last.",
    )
    instructions_unseen = (
        "Place the cups over the blocks left to right and take them off again in red, green, "
        "blue order.",
        "After covering all blocks from the left, reveal them in the colour order red, green, "
        "blue.",
    )
    aliasing_point = "all three blocks covered: the colours are invisible"
    aliasing_stage = 3
    hidden_keys = ("colours",)
    # all three covered (the headline), and the left one uncovered with the other two still
    # covered, where green lies in the middle or on the right
    aliasing_pairs = ((({"colours": ("red", "green", "blue")}, 3, 1),
                       ({"colours": ("blue", "red", "green")}, 3, 1)),
                      (({"colours": ("red", "green", "blue")}, 4, 1),
                       ({"colours": ("red", "blue", "green")}, 4, 1)))

    # The state observation: the three cubes left to right, each with a visibility flag and,
    # while it can be seen, its pose and colour (zero under a cover); the three identical
    # covers left to right.
    state_names = (*(n for p in ("left", "middle", "right") for n in (
                       f"cube_{p}_visible", *S.pose_names(f"cube_{p}", S.CUBE_SYMMETRY),
                       *S.one_hot_names(f"cube_{p}", COLOURS))),
                   *(n for p in ("left", "middle", "right")
                     for n in S.pose_names(f"cover_{p}", S.COVER_SYMMETRY)))

    def __init__(self):
        super().__init__()
        self.cubes = tuple(Cube(f"cube{k}", size=0.04) for k in range(3))
        self.covers = tuple(Cover(f"cover{k}") for k in range(3))
        self.colours: tuple[str, ...] = ORDERS[0]
        self.sequence: list[str] = []
        self.state = "000"
        self.cursor = 0
        self.wrong_state = ""

    @property
    def pieces(self):
        return (*self.cubes, *self.covers)

    def initialize(self, rng: np.random.Generator) -> None:
        xc, y = ROW_X.draw(rng), ROW_Y.draw(rng)
        order = ORDERS[int(rng.integers(len(ORDERS)))]
        self.colours = tuple(self.choose("colours", order, ORDERS))
        yaws = YAW.draw(rng, 6)
        for k in range(3):
            x = xc + (k - 1) * SPACING
            self.cubes[k].paint(self.model, COLOURS[self.colours[k]])
            self.cubes[k].place(self.data, (x, y), yaw=yaws[k])
            self.covers[k].place(self.data, (x, y + BEHIND), yaw=yaws[3 + k])
        self.sequence = self.expected_states()
        self.state = "000"
        self.cursor = 0
        self.wrong_state = ""

    def expected_states(self) -> list[str]:
        states, bits = ["000"], [0, 0, 0]
        for k in range(3):
            bits[k] = 1
            states.append("".join(map(str, bits)))
        for colour in COLOURS:
            bits[self.colours.index(colour)] = 0
            states.append("".join(map(str, bits)))
        return states

    def plan(self) -> list[int]:
        return [0, 1, 2, *(3 + self.colours.index(colour) for colour in COLOURS)]

    def hidden_by_cover(self, cube: Cube) -> bool:
        """Whether a cover hides the cube from the head camera: one stands over it, its rim
        lower than the cube's top."""
        return self.cover_over(cube, HIDDEN_RIM)

    def cover_over(self, cube: Cube, below: float) -> bool:
        """Whether a cover stands around ``cube`` (the cube inside its cup's square) with its
        rim less than ``below`` over the table: hiding it (``HIDDEN_RIM``), or down on the
        table (``DOWN``), covering it."""
        centre, half = cube.pos(self.data), cube.size / 2
        return any(c.around(self.data, centre, half) and c.pos(self.data)[2] - TABLE_TOP < below
                   for c in self.covers)

    def environment_state(self) -> np.ndarray:
        d, parts = self.data, []
        for cube in S.left_to_right(self.cubes, d):
            visible = 0.0 if self.hidden_by_cover(cube) else 1.0
            colour = self.colours[self.cubes.index(cube)]
            parts += [[visible], visible * S.pose(cube, d, S.CUBE_SYMMETRY),
                      visible * S.one_hot(colour, list(COLOURS))]
        parts += [S.pose(c, d, S.COVER_SYMMETRY) for c in S.left_to_right(self.covers, d)]
        return S.assemble(self.state_names, parts)

    def hidden_state(self) -> dict:
        return {"colours": list(self.colours)}

    def settled_state(self) -> str | None:
        """Which blocks are covered, once no cover is held or moving; None in between."""
        for cover in self.covers:
            if cover.speed(self.data) > 0.02 or self.touched_by_fingers(cover.body_id):
                return None
        return "".join("1" if self.cover_over(cube, DOWN) else "0" for cube in self.cubes)

    def evaluate(self) -> Evaluation:
        state = self.settled_state()
        if state is not None and state != self.state and not self.wrong_state:
            if self.cursor + 1 < len(self.sequence) and state == self.sequence[self.cursor + 1]:
                self.cursor += 1
                self.state = state
            else:
                self.wrong_state = state
        stage = self.cursor  # the sequence revisits 000, so the index is kept, not looked up
        reason = ""
        if self.wrong_state:
            reason = (f"cover state went {self.state} -> {self.wrong_state}; expected "
                      f"{self.sequence[stage + 1] if stage + 1 < len(self.sequence) else 'none'}")
        elif any(not (p.on_a_face(self.data, 0.5) if isinstance(p, Cube) else
                      p.upright(self.data, 0.5))
                 for p in self.pieces if p.speed(self.data) < 0.02
                 and not self.touched_by_fingers(p.body_id)):
            reason = "a block or cover was knocked over"
        elif self.fell_off(self.pieces):
            reason = "a block or cover fell off the table"
        stage, progress = self.advance(stage, PROGRESS[stage])
        preds = {"cover_state": self.state, "settled_state": state or "",
                 "colours": list(self.colours), "expected_next":
                 self.sequence[stage + 1] if stage + 1 < len(self.sequence) else ""}
        return Evaluation(success=stage == 6 and not reason, failure=bool(reason),
                          progress=progress, stage=stage, failure_reason=reason,
                          predicates=preds)
