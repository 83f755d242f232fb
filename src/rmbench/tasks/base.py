"""The task framework: one subclass per task, the same hooks in the same order.

A task (1) builds its objects into the station's MjSpec, (2) binds ids after compilation,
(3) initialises an episode from the Generator handed to ``reset(seed)``, (4) is told after
every physics step (button counting, event latches), and (5) ``evaluate()``s named
predicates once per control step. The env starts an episode through ``start_episode``, which
does the base's bookkeeping before the task's ``initialize`` hook places the scene, so a task
cannot forget it. Reward, termination, ``info["is_success"]``, progress and
the ground-truth subtask all derive from those predicates in :mod:`rmbench.envs.env`.
"""

from __future__ import annotations

import json
from collections import deque
from dataclasses import dataclass, field
from typing import Any, ClassVar

import mujoco
import numpy as np

from rmbench.sim import robot
from rmbench.sim.station import HOME_ARM, TABLE_TOP

# Both arms are back home and settled once every arm joint, averaged over the last
# HOME_WINDOW control steps (0.5 s), lies within HOME_JOINT_TOL (rad) of its home angle. A
# test on the gripper's position alone passed while the arm that had just come back still
# turned its wrist, 0.1-0.2 rad from home, which told which arm had made the last move; the
# average over the window passes only once that arm has been home for most of it. Averaged,
# not read per step: the collection's executed action noise (white, 0.02 rad) keeps an arm
# at home 0.02-0.03 rad from it at any one step and moving at 0.3-0.6 rad/s, while its
# 0.5-s average stays within 0.003-0.007 (0.0002-0.0006 without the noise).
FELL_BELOW = 0.05  # m under the table top: a piece's centre there has left the table
HOME_WINDOW = 10
HOME_JOINT_TOL = 0.01


@dataclass(frozen=True)
class Evaluation:
    """What a task says about the current state, once per control step.

    success: the task is solved (episode terminates).
    failure: the task can no longer be solved, with ``failure_reason`` (episode terminates).
    progress: in [0, 1], the furthest stage reached so far (monotone within an episode).
    stage: index of the ground-truth current subtask in ``Task.plan``; len(plan) once done.
    predicates: every named boolean/number the above were derived from, for logs and tests.
    """

    success: bool
    failure: bool
    progress: float
    stage: int
    failure_reason: str = ""
    predicates: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        # A success with partial progress would publish a solved episode as a failure's
        # progress (a trial task solved off its plan did once: ``Task.advance(solved=)``).
        if self.success and self.progress != 1.0:
            raise ValueError(f"a solved task must report progress 1.0, not {self.progress}")
        if self.success and self.failure:
            raise ValueError("a task cannot report success and failure at once")


class Task:
    """Base class. Subclasses set the class attributes and implement the hooks."""

    name: ClassVar[str]
    gym_id: ClassVar[str]
    tmc: ClassVar[str]  # "M(1)" or "M(n)"
    step_limit: ClassVar[int]  # policy steps at the control rate
    subtasks: ClassVar[tuple[str, ...]]  # distinct subtask texts; plan() indexes into these
    instructions_seen: ClassVar[tuple[str, ...]]
    instructions_unseen: ClassVar[tuple[str, ...]]
    aliasing_point: ClassVar[str]
    aliasing_stage: ClassVar[int]  # a stage (index into plan) at which the aliasing holds
    # The hidden variables (keys of ``hidden_state()``) that ``reset(options={"hidden": ...})``
    # may fix: the layout is drawn from the seed as usual, only these values are replaced.
    # Two episodes that differ only there are how the aliasing tests show a task needs memory.
    hidden_keys: ClassVar[tuple[str, ...]] = ()
    # Every pair of moments the expert's plan revisits: two moments that look alike while the
    # expert's next subtask, or its actions from there on, differ (the same next press with a
    # different count after it), each (hidden values, stage, n): the n-th expert segment start
    # after the env reached that stage, or with n = 0 the first frame at that stage
    # (rmbench.aliasing). The first pair is the task's headline (docs/tasks/<task>.png).
    aliasing_pairs: ClassVar[tuple[tuple[tuple[dict, int, int], tuple[dict, int, int]], ...]]
    # The state observation: names of ``environment_state()``'s entries, in order (see
    # rmbench.tasks.state for the shared encodings and docs/reference/observations.md).
    state_names: ClassVar[tuple[str, ...]] = ()
    # Predicates that hold where a piece is: the index of its place, or -1 while it is in none
    # (held, or between places); or where several pieces are together (a row's order), empty
    # while any is in none. Evaluation records carry them step by step, which is how a piece
    # taken from its place and set back in the same one is told from a move.
    place_predicates: ClassVar[tuple[str, ...]] = ()

    def __init__(self):
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self._stage = 0
        self._best_progress = 0.0
        self._home_gaps: deque[np.ndarray] = deque(maxlen=HOME_WINDOW)
        self.overrides: dict[str, Any] = {}
        self._reported: dict[str, Any] = {}  # hidden facts given that follow from the rest

    # -- the episode protocol -----------------------------------------------------------
    def start_episode(self, rng: np.random.Generator,
                      hidden: dict[str, Any] | None = None) -> None:
        """A new episode: the hidden variables in ``hidden`` fixed (the rest drawn), stage and
        progress back to the start, then the task's ``initialize`` draws from ``rng`` and
        places the scene."""
        self.set_overrides(hidden)
        self._stage = 0
        self._best_progress = 0.0
        self._home_gaps.clear()  # the arms' window starts with the episode
        self.initialize(rng)
        self._check_reported()

    # -- hooks ------------------------------------------------------------------------
    @property
    def pieces(self) -> tuple:
        """Every scene piece of the task (sim.objects); built and bound here in order."""
        raise NotImplementedError

    def build(self, spec: mujoco.MjSpec) -> None:
        for piece in self.pieces:
            piece.build(spec)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        self.model, self.data = model, data
        for piece in self.pieces:
            piece.bind(model)
        self._fingers = {model.geom(f"{side}/10_{f}_gripper_finger").id
                         for side in ("left", "right") for f in ("left", "right")}
        self._arm_qpos = np.array([model.joint(f"{side}/{joint}").qposadr[0]
                                   for side in robot.SIDES for joint in robot.ARM_JOINTS])
        self._home_qpos = np.concatenate([HOME_ARM[side] for side in robot.SIDES])

    def initialize(self, rng: np.random.Generator) -> None:
        """Sample the episode's layout and hidden variables; place everything. Called by
        ``start_episode``, never directly."""
        raise NotImplementedError

    def on_substep(self) -> None:
        """Called after every physics step."""

    def evaluate(self) -> Evaluation:
        """The episode's standing after a control step. Not a pure query: the env calls it
        once per control step (and once at reset), and tasks advance their own records in it
        (a try counted, a stage latched, a settling window filled), so a second call in one
        step would count that step twice: the step's info holds what it returned."""
        raise NotImplementedError

    def plan(self) -> list[int]:
        """The episode's subtask sequence as indices into ``subtasks`` (after initialize)."""
        raise NotImplementedError

    def hidden_state(self) -> dict[str, Any]:
        """The episode's hidden variables (what memory must recover), JSON-serialisable."""
        return {}

    def environment_state(self) -> np.ndarray:
        """What the head camera shows of the scene now, as a float64 vector in the order of
        ``state_names``: poses of objects and fixtures, visible fixture states (a button's
        depth, a lamp's colour, a tile's digit). Never a hidden variable, a counter, the
        subtask, or anything a screen, cover or holder hides at this moment."""
        raise NotImplementedError

    # -- shared helpers -----------------------------------------------------------------
    def set_overrides(self, hidden: dict[str, Any] | None) -> None:
        """Fix hidden variables for the next episode (``hidden_keys``). The other facts
        ``hidden_state`` reports (which follow from the seed and the fixed ones) may come too,
        so that an episode's ``info["hidden"]`` given back whole fixes that episode: each is
        checked against the episode once it is placed (``_check_reported``)."""
        if hidden is not None and not isinstance(hidden, dict):
            raise ValueError(f"hidden must be a map of {list(self.hidden_keys)} to values, got "
                             f"{type(hidden).__name__}")
        hidden = dict(hidden or {})
        self.overrides = {k: v for k, v in hidden.items() if k in self.hidden_keys}
        self._reported = {k: v for k, v in hidden.items() if k not in self.hidden_keys}

    def _check_reported(self) -> None:
        """Each reported fact given with the hidden variables is this episode's (as JSON says
        it), else a ValueError: it cannot be fixed, only follow."""
        if not self._reported:
            return
        actual = _as_json(self.hidden_state())
        for key, value in self._reported.items():
            if key not in actual:
                raise ValueError(f"{self.name} cannot fix hidden variable {key!r}; it fixes "
                                 f"{list(self.hidden_keys)} and reports {sorted(actual)}")
            if _tuples(_as_json(value)) != _tuples(actual[key]):
                raise ValueError(f"{self.name}: hidden {key}={value!r} is not this episode's "
                                 f"({actual[key]!r}): it follows from the seed and "
                                 f"{list(self.hidden_keys)}, it cannot be fixed")

    def choose(self, key: str, drawn, allowed=None):
        """``drawn`` (already taken from the episode's generator, so later draws do not
        shift), unless the caller fixed ``key``; a fixed value must be one of ``allowed``."""
        if key not in self.overrides:
            return drawn
        value = _tuples(self.overrides[key])  # (``hidden_state`` says them as JSON lists)
        if allowed is not None and value not in allowed:
            raise ValueError(f"{self.name}: hidden {key}={value!r} is not one of {list(allowed)}")
        return value

    def advance(self, stage: int, progress: float, solved: bool = False) -> tuple[int, float]:
        """Stages and progress only move forward within an episode. A solved task is done,
        whichever route it took: a trial task can be solved off its plan (a lucky guess, tries
        in another order), and its progress must not then read as a failure's."""
        if solved:
            stage, progress = len(self.plan()), 1.0
        self._stage = max(self._stage, stage)
        self._best_progress = max(self._best_progress, progress)
        return self._stage, self._best_progress

    def fell_off(self, pieces) -> bool:
        """Some piece's centre lies more than ``FELL_BELOW`` under the table top: it is off
        the table (a failure of every task)."""
        return min(p.pos(self.data)[2] for p in pieces) < TABLE_TOP - FELL_BELOW

    def released(self, piece) -> bool:
        """The piece rests on the table, still, and no finger touches it."""
        return piece.resting(self.data) and not self.touched_by_fingers(piece.body_id)

    def stacked(self, cubes) -> bool:
        """Some cube rests, released, on top of another (stacking is a failure where cubes
        must stay on the table)."""
        for upper in cubes:
            p = upper.pos(self.data)
            speed = np.linalg.norm(self.data.qvel[upper.qvel_adr: upper.qvel_adr + 3])
            if p[2] - upper.size / 2 < TABLE_TOP + 0.6 * upper.size or speed > 0.05:
                continue
            if self.touched_by_fingers(upper.body_id):
                continue
            if any(np.linalg.norm(p[:2] - c.pos(self.data)[:2]) < c.size for c in cubes
                   if c is not upper):
                return True
        return False

    def hands_home(self) -> bool:
        """Both arms back home and settled: every arm joint, averaged over this and the
        previous ``HOME_WINDOW - 1`` control steps, within ``HOME_JOINT_TOL`` of its home
        angle. Reads the window it keeps, so a task calls it once per control step (from
        ``evaluate``). battery_try counts a try only then, as the benchmark's reference ends
        each try with the arm back at its origin: the frame the next try is chosen at must
        show neither which arm made the last move nor that one is still on its way back."""
        self._home_gaps.append(self.data.qpos[self._arm_qpos] - self._home_qpos)
        if len(self._home_gaps) < HOME_WINDOW:
            return False
        return bool(np.abs(np.mean(self._home_gaps, axis=0)).max() <= HOME_JOINT_TOL)

    def touched_by_fingers(self, body_id: int) -> bool:
        """Whether any gripper finger is in contact with ``body_id``."""
        fingers = self._fingers
        d, m = self.data, self.model
        for i in range(d.ncon):
            g1, g2 = d.contact[i].geom1, d.contact[i].geom2
            if (g1 in fingers and m.geom_bodyid[g2] == body_id) or (
                    g2 in fingers and m.geom_bodyid[g1] == body_id):
                return True
        return False


def _as_json(value):
    """``value`` as JSON gives it back (numpy values as plain numbers and lists)."""
    return json.loads(json.dumps(value, default=lambda o: o.tolist() if hasattr(o, "tolist")
                                 else str(o)))


def _tuples(value):
    """``value`` with its lists (nested too) as tuples, the form a task's choices take."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list | tuple) else value
