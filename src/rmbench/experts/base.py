"""Scripted experts: the policy interface over a plan of labelled motion primitives."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np

from rmbench.experts.ik import ArmIK
from rmbench.experts.motion import Actions, GaveUp, Handle, Motion
from rmbench.tasks.base import Task

EXPERTS: dict[str, type[ScriptedExpert]] = {}


def register_expert(cls):
    if cls.task in EXPERTS:
        raise ValueError(f"an expert for {cls.task!r} is already registered")
    EXPERTS[cls.task] = cls
    return cls


class ScriptedExpert:
    """Solves one task from privileged state. ``act`` returns the next 14-d action and sets
    ``subtask_index`` / ``subtask`` to the subtask that action belongs to."""

    task: ClassVar[str]

    def __init__(self, env):
        self.env = env.unwrapped
        self.ik = ArmIK()
        self._plan: Iterator[tuple[np.ndarray, int, bool]] | None = None
        self._last: np.ndarray | None = None
        self.subtask_index = 0
        self.subtask = ""
        self.segment_start = False  # this action begins a new labelled segment of the plan
        self.finished = False
        self.gave_up = ""  # why the expert stopped before the task was done, if it did

    def reset(self, instruction: str = "", task_info: dict[str, Any] | None = None) -> None:
        sim = self.env.sim
        self.motion = Motion(self.ik, sim.config.substeps, sim.servo_gain,
                             1.0 / sim.config.control_hz)
        self._plan = self.plan(self.env.task)
        self._last = self.motion.cmd.copy()
        self.finished = False
        self.gave_up = ""

    def act(self, observation=None) -> np.ndarray:
        """The next action. Given the observation, the expert closes the loop on its joints:
        ``motion.observe`` compares them with what it commanded, and the action corrects
        for the offset the arms hold (servo sag, a drifting perturbation)."""
        if self._plan is None:
            raise RuntimeError("call reset() before act()")
        if observation is not None and "agent_pos" in observation:
            self.motion.observe(np.asarray(observation["agent_pos"], float))
        try:
            action, self.subtask_index, self.segment_start = next(self._plan)
            self._last = action
        except StopIteration:
            self.finished = True  # plan done: hold still while the task registers the end
            self.segment_start = False
        except GaveUp as reason:
            self.finished = True  # hold still; the caller ends the episode with the reason
            self.segment_start = False
            self.gave_up = str(reason)
        self.subtask = type(self.env.task).subtasks[self.subtask_index]
        return self.motion.compensate(self._last)

    def plan(self, task: Task) -> Iterator[tuple[np.ndarray, int, bool]]:
        """(action, subtask index, starts a segment) triples; build it from ``label``."""
        raise NotImplementedError

    def handle(self, piece, height: float, **how) -> Handle:
        """A handle on ``piece`` by its body origin, located live (see ``Motion.carry``)."""
        data = self.env.task.data
        return Handle(lambda: (piece.pos(data), piece.yaw(data)), height, **how)

    @staticmethod
    def label(subtask: int, actions: Actions) -> Iterator[tuple[np.ndarray, int, bool]]:
        """Tag a segment of the plan with its subtask. Segment starts are the expert's quiet
        moments between moves (the aliasing tests compare frames there)."""
        for k, a in enumerate(actions):
            yield a, subtask, k == 0


def make_expert(env) -> ScriptedExpert:
    name = type(env.unwrapped.task).name
    if name not in EXPERTS:
        raise KeyError(f"no scripted expert for task {name!r}; experts exist for {sorted(EXPERTS)}")
    return EXPERTS[name](env)
