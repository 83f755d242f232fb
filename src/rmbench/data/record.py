"""Recording one expert demonstration: the seed search pass and the recorded pass.

``search`` mode runs the expert without rendering, keeps the seed only if it succeeds, then
replays the same actions with the cameras on. The replay must reproduce the searched episode's
states bit for bit; a mismatch is an error, never a silently different demonstration.
``direct`` mode records while the expert runs and drops the recording if it fails: faster when
the expert almost never fails, wasteful when it often does.

Actions are rounded to float32 before they are applied, so the stored actions replayed from
the stored seed give back the recorded episode exactly.

With action noise (DART, Laskey et al. 2017) the env executes the expert's action plus the
noise, and the dataset stores the expert's action: what it wanted done in the state the noise
led to, which is how a policy learns to come back to the demonstrated path. The noise is drawn
from the episode seed, so a replay re-draws the same executed actions.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rmbench.data.layout import Spec
from rmbench.envs.noise import NoiseSpec, perturber
from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.video import Mp4Encoder

SEARCH_MODES = ("search", "direct")


class ReplayMismatch(RuntimeError):
    """The recorded replay diverged from the searched episode (non-deterministic physics)."""


@dataclass
class Trajectory:
    """The low-dimensional content of one episode, one row per frame (observation, action)."""

    instruction: str
    hidden: dict[str, Any]
    state: list[np.ndarray] = field(default_factory=list)
    ee_pose: list[np.ndarray] = field(default_factory=list)
    environment_state: list[np.ndarray] = field(default_factory=list)  # Task.environment_state
    action: list[np.ndarray] = field(default_factory=list)
    executed: list[np.ndarray] = field(default_factory=list)  # action + noise, as applied
    # The plan step each frame works on (the simulator's count of finished steps) and that
    # step's subtask: the task's ground truth, so an end falls where the step is done.
    step: list[int] = field(default_factory=list)
    subtask: list[int] = field(default_factory=list)
    progress: list[float] = field(default_factory=list)
    success: bool = False
    reason: str = "timeout"

    def __len__(self) -> int:
        return len(self.action)


@dataclass
class EpisodeRecord:
    """What a worker hands to the dataset writer for one seed."""

    task: str
    seed: int
    success: bool
    reason: str
    instruction: str = ""
    hidden: dict[str, Any] = field(default_factory=dict)
    state: np.ndarray | None = None  # (T, 14) float32
    ee_pose: np.ndarray | None = None  # (T, 14) float32
    action: np.ndarray | None = None  # (T, 14) float32
    subtask_index: np.ndarray | None = None  # (T,) int64
    progress: np.ndarray | None = None  # (T,) float32
    videos: dict[str, bytes] = field(default_factory=dict)  # camera -> mp4
    image_stats: dict[str, dict] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    environment_state: np.ndarray | None = None  # (T, len(Task.state_names)) float32
    subtask_step: np.ndarray | None = None  # (T,) int64, the plan step (layout.SUBTASK_STEP)

    @property
    def length(self) -> int:
        return 0 if self.action is None else len(self.action)


def _jsonable(value):
    """Hidden variables as plain JSON values (numpy scalars and arrays included)."""
    return json.loads(json.dumps(value, default=lambda v: v.tolist() if hasattr(v, "tolist")
                                 else str(v)))


class ImageStats:
    """Per-channel statistics of a camera's frames in [0, 1], from every ``stride``-th frame
    (the layout LeRobot uses: arrays of shape (3, 1, 1))."""

    def __init__(self, stride: int = 5):
        self.stride, self.n = stride, 0
        self.samples: list[np.ndarray] = []

    def add(self, frame: np.ndarray) -> None:
        if self.n % self.stride == 0:
            self.samples.append(frame[::4, ::4].reshape(-1, 3))
        self.n += 1

    def result(self) -> dict:
        px = np.concatenate(self.samples).astype(np.float64) / 255.0
        shape = (3, 1, 1)
        return {"min": px.min(0).reshape(shape), "max": px.max(0).reshape(shape),
                "mean": px.mean(0).reshape(shape), "std": px.std(0).reshape(shape),
                "count": np.array([len(self.samples)])}


class Recorder:
    """Records demonstrations of one task in one process; envs are built once and reused."""

    def __init__(self, task: str, spec: Spec, mode: str = "search",
                 noise: NoiseSpec | None = None):
        if mode not in SEARCH_MODES:
            raise ValueError(f"search mode must be one of {SEARCH_MODES}, got {mode!r}")
        self.task, self.spec, self.mode = task, spec, mode
        self.noise = noise if noise is not None and noise.active else None
        self._envs: dict[bool, tuple] = {}  # rendering? -> (env, expert)

    def _env(self, render: bool):
        if render not in self._envs:
            env = (make(self.task, render=True, cameras=self.spec.cameras, width=self.spec.width,
                        height=self.spec.height) if render else make(self.task, render=False))
            self._envs[render] = (env, make_expert(env))
        return self._envs[render]

    def close(self) -> None:
        for env, _ in self._envs.values():
            env.close()
        self._envs.clear()

    # ---------------------------------------------------------------------------------------
    def record(self, seed: int) -> EpisodeRecord:
        t0 = time.perf_counter()
        if self.mode == "search":
            traj = run_expert(*self._env(render=False), seed, noise=self.noise)
            t1 = time.perf_counter()
            if not traj.success:
                return EpisodeRecord(self.task, seed, False, traj.reason,
                                     timings={"search_s": t1 - t0})
            encoders, stats = self._replay(seed, traj)
            timings = {"search_s": t1 - t0, "record_s": time.perf_counter() - t1}
        else:
            encoders = {c: Mp4Encoder(self.spec.fps, self.spec.codec) for c in self.spec.cameras}
            stats = {c: ImageStats() for c in self.spec.cameras}
            traj = run_expert(*self._env(render=True), seed, encoders, stats, self.noise)
            if not traj.success:
                return EpisodeRecord(self.task, seed, False, traj.reason,
                                     timings={"record_s": time.perf_counter() - t0})
            timings = {"record_s": time.perf_counter() - t0}
        t2 = time.perf_counter()
        videos = {c: e.finish() for c, e in encoders.items()}
        timings["encode_flush_s"] = time.perf_counter() - t2
        return EpisodeRecord(
            self.task, seed, True, "success", traj.instruction, _jsonable(traj.hidden),
            np.asarray(traj.state, np.float32), np.asarray(traj.ee_pose, np.float32),
            np.asarray(traj.action, np.float32), np.asarray(traj.subtask, np.int64),
            np.asarray(traj.progress, np.float32), videos,
            {c: s.result() for c, s in stats.items()}, timings,
            environment_state=np.asarray(traj.environment_state, np.float32),
            subtask_step=np.asarray(traj.step, np.int64))

    def _replay(self, seed: int, traj: Trajectory):
        env, _ = self._env(render=True)
        encoders = {c: Mp4Encoder(self.spec.fps, self.spec.codec) for c in self.spec.cameras}
        stats = {c: ImageStats() for c in self.spec.cameras}
        for obs in replay(env, seed, traj.executed, traj.state, traj.environment_state,
                          f"{self.task} seed {seed}"):
            for cam in self.spec.cameras:
                encoders[cam].add(obs["pixels"][cam])
                stats[cam].add(obs["pixels"][cam])
        return encoders, stats


def executed_action(action: np.ndarray, perturb) -> np.ndarray:
    """What the env executes for ``action`` (float64): the action, or with noise the action
    plus the noise rounded to float32, as a replay from the stored actions re-draws it."""
    return action if perturb is None else np.asarray(perturb(action), np.float32).astype(np.float64)


def replay(env, seed: int, executed, state, environment_state, label: str):
    """Step ``env`` from ``seed`` through the ``executed`` actions, yielding each frame's
    observation once it is checked against the recorded ``state`` and ``environment_state``
    rows (compared at their own precision); a ``ReplayMismatch`` where they differ or where
    the episode does not end in success."""
    obs, info = env.reset(seed=seed)
    task = env.unwrapped.task
    # The env clips agent_pos to the joint limits (RMBenchEnv._observation); a dataset
    # collected without the clip holds the physics' readings (an open gripper up to 0.003
    # past its limit), so each row is compared clipped, as the env observes it
    space = env.unwrapped.observation_space["agent_pos"]
    for t, action in enumerate(executed):
        want, want_env = np.asarray(state[t]), np.asarray(environment_state[t])
        want = np.clip(want, space.low, space.high).astype(want.dtype)
        if not (np.array_equal(np.asarray(obs["agent_pos"], want.dtype), want) and np.array_equal(
                np.asarray(task.environment_state(), want_env.dtype), want_env)):
            raise ReplayMismatch(f"{label}: the replay differs from the recorded state at "
                                 f"frame {t}")
        yield obs
        obs, _, _, _, info = env.step(action)
    if not info.get("is_success"):
        raise ReplayMismatch(f"{label}: the replay did not succeed")


def run_expert(env, expert, seed: int, encoders: dict[str, Mp4Encoder] | None = None,
               stats: dict[str, ImageStats] | None = None,
               noise: NoiseSpec | None = None) -> Trajectory:
    """One expert episode; frames go to ``encoders`` when the env renders. With ``noise`` the
    env executes the expert's action plus the noise; the expert's own action is recorded."""
    sim = env.unwrapped.sim
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    perturb = perturber(noise, seed, env)
    traj = Trajectory(info["instruction"], info["hidden"])
    progress = info["progress"]
    plan, step = info["plan"], info["subtask_step"]
    while True:
        try:
            action = np.asarray(expert.act(obs), np.float32).astype(np.float64)
        except Exception as err:  # an expert that cannot plan is a skipped seed, not a crash
            traj.reason = f"expert error: {err}"
            return traj
        if expert.gave_up:
            traj.reason = f"expert gave up: {expert.gave_up}"
            return traj
        executed = executed_action(action, perturb)
        traj.state.append(obs["agent_pos"])
        traj.ee_pose.append(sim.ee_pose())
        traj.environment_state.append(env.unwrapped.task.environment_state())
        traj.action.append(action)
        traj.executed.append(executed)
        traj.step.append(min(step, len(plan) - 1))
        traj.subtask.append(plan[traj.step[-1]])
        traj.progress.append(progress)
        if encoders is not None:
            for cam, enc in encoders.items():
                enc.add(obs["pixels"][cam])
                stats[cam].add(obs["pixels"][cam])
        obs, _, terminated, truncated, info = env.step(executed)
        progress = info.get("progress", progress)
        step = info.get("subtask_step", step)
        if terminated or truncated:
            traj.success = bool(info.get("is_success"))
            traj.reason = ("success" if traj.success else info.get("failure_reason")
                           or ("timeout" if truncated else "failed"))
            return traj
