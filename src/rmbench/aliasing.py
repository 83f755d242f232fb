"""Aliasing points, measured: why each task needs memory.

Every task names two moments (``Task.aliasing_pair``): each is a set of fixed hidden
variables, a stage of the plan, and which expert segment start after reaching that stage.
Run from the same seed, the two moments should look alike to the head camera while the
expert's next subtask (or, where the text is the same, its next actions) differ. The pixel
distance is compared with the same moment in an unrelated seed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.tasks import get_task


@dataclass
class Moment:
    frame: np.ndarray  # head camera, HxWx3 uint8
    step: int
    next_subtask: str
    actions: np.ndarray  # the expert's actions from the moment to the end of the episode


@dataclass
class AliasingResult:
    task: str
    seed: int
    unrelated_seed: int
    pixel_distance: float  # mean |difference| (0-255) between the two moments
    unrelated_distance: float  # the first moment vs the same moment in the unrelated seed
    ratio: float
    next_subtasks: tuple[str, str]
    action_divergence: float  # max |difference| of the expert's actions from there on (rad)
    steps: tuple[int, int]

    def to_dict(self) -> dict:
        return asdict(self)


def capture(task: str, seed: int, hidden: dict, stage: int, segment: int,
            width: int = 320, height: int = 240) -> Moment:
    """Roll the expert from ``seed`` with ``hidden`` fixed until its ``segment``-th segment
    start after the env reached ``stage``; return the head frame there and what follows."""
    env = make(task, render=False)
    try:
        expert = make_expert(env)
        obs, info = env.reset(seed=seed, options={"hidden": hidden})
        expert.reset(info["instruction"], info)
        plan = info["plan"]
        reached, seen, frame, step = info["subtask_step"] >= stage, 0, None, 0
        actions: list[np.ndarray] = []
        for t in range(env.unwrapped.step_limit):
            action = expert.act(obs)
            if frame is None and reached and expert.segment_start:
                seen += 1
                if seen == segment:
                    frame = env.unwrapped.sim.render(["head"], width, height)["head"]
                    step = t
            if frame is not None:
                actions.append(action)
            obs, _, terminated, truncated, info = env.step(action)
            reached = reached or info["subtask_step"] >= stage
            if terminated or truncated:
                break
        if frame is None:
            raise RuntimeError(f"{task} seed {seed}: the expert never reached stage {stage} "
                               f"segment {segment} with {hidden}")
        subtasks = get_task(task).subtasks
        return Moment(frame, step, subtasks[plan[stage]] if stage < len(plan) else "done",
                      np.array(actions))
    finally:
        env.close()


def pixel_distance(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a.astype(np.int16) - b.astype(np.int16)).mean())


def measure(task: str, seed: int = 100000, unrelated_seed: int | None = None) -> AliasingResult:
    cls = get_task(task)
    unrelated_seed = seed + 1 if unrelated_seed is None else unrelated_seed
    a, b = (capture(cls.name, seed, *m) for m in cls.aliasing_pair)
    other = capture(cls.name, unrelated_seed, *cls.aliasing_pair[0])
    d, d_other = pixel_distance(a.frame, b.frame), pixel_distance(a.frame, other.frame)
    n = max(len(a.actions), len(b.actions))  # a finished episode holds its last action
    pad = [np.concatenate([m.actions, np.repeat(m.actions[-1:], n - len(m.actions), 0)])
           for m in (a, b)]
    return AliasingResult(cls.name, seed, unrelated_seed, round(d, 3), round(d_other, 3),
                          round(d / max(d_other, 1e-9), 3), (a.next_subtask, b.next_subtask),
                          round(float(np.abs(pad[0] - pad[1]).max()), 3), (a.step, b.step))
