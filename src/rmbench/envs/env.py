"""The Gymnasium environment: one task on the station.

Observation (gym-aloha / LeRobot layout): ``pixels`` (camera -> HxWx3 uint8) and
``agent_pos`` (14,) = 6 left joints, left gripper opening in [0, 1], 6 right joints, right
gripper. ``obs_type`` picks it (the names gym-pusht uses): ``pixels_agent_pos`` (the default),
``environment_state_agent_pos`` (``environment_state``: the task's vector of what the head
camera shows, ``Task.state_names``; no rendering) or ``pixels_environment_state_agent_pos``
(both). Action: the same 14-vector of absolute targets, applied at 20 Hz.

Reward: the increase of the task's progress this step, so an episode's return equals the
best progress reached (1.0 on success). Termination on success, task failure or a physics
error; truncation at the task's step limit.
"""

from __future__ import annotations

import logging
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np

from rmbench.sim.simulator import ACTION_DIM, Simulator
from rmbench.sim.station import SimulationError, StationConfig, base_spec
from rmbench.tasks import get_task
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.state import bounds as state_bounds

log = logging.getLogger(__name__)
SETTLE_STEPS = 50  # physics steps (0.1 s) after placing objects, before the first frame
RESET_OPTIONS = ("hidden",)  # what reset(options=...) takes
OBS_TYPES = ("pixels_agent_pos", "environment_state_agent_pos",
             "pixels_environment_state_agent_pos")


def _inwards(bound: np.ndarray, towards: float) -> np.ndarray:
    """``bound`` as float32, moved one float32 step ``towards`` where rounding put it past."""
    b = bound.astype(np.float32)
    past = b < bound if towards > 0 else b > bound
    return np.where(past, np.nextafter(b, np.float32(towards)), b)


class RMBenchEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, task: str | type[Task] = "put_back_block", *,
                 cameras: tuple[str, ...] | list[str] | None = None, width: int = 320,
                 height: int = 240, render: bool | None = None, instructions: str = "seen",
                 render_mode: str | None = "rgb_array", step_limit: int | None = None,
                 obs_type: str = "pixels_agent_pos"):
        task_cls = get_task(task) if isinstance(task, str) else task
        if obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {list(OBS_TYPES)}, got {obs_type!r}")
        if step_limit is not None and (isinstance(step_limit, bool) or not
                                       isinstance(step_limit, int | np.integer) or step_limit < 1):
            raise ValueError(f"step_limit must be a whole number >= 1 (None: the task's "
                             f"{task_cls.step_limit}), got {step_limit!r}")
        self.obs_type = obs_type
        self.with_state = "environment_state" in obs_type
        if render is None:  # cameras on exactly when the observation holds pixels
            render = obs_type.startswith("pixels")
        if instructions not in ("seen", "unseen"):
            raise ValueError(f"instructions must be 'seen' or 'unseen', got {instructions!r}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        if isinstance(cameras, str):  # ("head", not its letters)
            raise ValueError(f"cameras must be a list of names, got the string {cameras!r}: "
                             f"cameras=({cameras!r},)")
        if cameras is not None and not tuple(cameras) and render and obs_type.startswith("pixels"):
            raise ValueError("cameras=() renders no camera into a pixels observation: name "
                             "some, or make the env with render=False (physics only)")
        kwargs = {} if cameras is None else {"cameras": tuple(cameras)}
        self.config = StationConfig(width=width, height=height, render=render, **kwargs)
        self.task: Task = task_cls()
        spec = base_spec(self.config)
        self.task.build(spec)
        self.sim = Simulator(spec.compile(), self.config)
        self.task.bind(self.sim.model, self.sim.data)
        self.instructions = instructions
        self.render_mode = render_mode
        self.step_limit = step_limit or task_cls.step_limit

        # agent_pos: each joint within its range in the model, the gripper within [0, 1] (its
        # finger's range, mapped as agent_pos maps it); _observation clips to these.
        low, high = self.sim.agent_pos_limits()
        spaces: dict[str, gym.Space] = {
            "agent_pos": gym.spaces.Box(low, high, (ACTION_DIM,), np.float64)}
        if render and obs_type.startswith("pixels"):
            spaces["pixels"] = gym.spaces.Dict({
                cam: gym.spaces.Box(0, 255, (height, width, 3), np.uint8)
                for cam in self.config.cameras})
        if self.with_state:
            low, high = state_bounds(task_cls.state_names)
            spaces["environment_state"] = gym.spaces.Box(low, high, dtype=np.float64)
        self.observation_space = gym.spaces.Dict(spaces)
        # The joint limits rounded inwards to float32: every action the space holds lies within
        # them, so none of its actions is clipped (rounded to nearest, a bound would stand up
        # to 1e-7 rad outside a limit). Absolute joint targets in radians, the layout of the
        # datasets and of gym-aloha; Gymnasium's advice of a [-1, 1] action space does not fit.
        self.action_space = gym.spaces.Box(_inwards(self.sim.action_low, np.inf),
                                           _inwards(self.sim.action_high, -np.inf),
                                           dtype=np.float32)
        self._steps = 0
        self._done = True
        self._last: Evaluation | None = None
        self.instruction = ""

    # ------------------------------------------------------------------------ api
    @property
    def spec_info(self) -> dict[str, Any]:
        t = type(self.task)
        return {"task": t.name, "gym_id": t.gym_id, "tmc": t.tmc, "step_limit": self.step_limit,
                "subtasks": list(t.subtasks)}

    @property
    def subtask_stage(self) -> int:
        """How many of the task's subtasks are done (the ground truth behind subtask_end)."""
        return self._last.stage if self._last is not None else 0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        # until this reset has finished, no episode runs: a reset that fails (a hidden value
        # the task refuses) leaves no half-reset episode for step() to go on with
        self._done = True
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a map of {list(RESET_OPTIONS)}, got "
                             f"{type(options).__name__}")
        unknown = sorted(map(str, set(options or {}) - set(RESET_OPTIONS)))
        if unknown:
            raise ValueError(f"unknown reset option(s) {unknown}; options: {list(RESET_OPTIONS)}")
        super().reset(seed=seed)
        sim, task = self.sim, self.task
        mujoco.mj_resetData(sim.model, sim.data)
        sim.reset_robot()
        task.start_episode(self.np_random, (options or {}).get("hidden"))
        mujoco.mj_forward(sim.model, sim.data)
        for _ in range(SETTLE_STEPS):
            mujoco.mj_step(sim.model, sim.data)
        pool = (type(task).instructions_seen if self.instructions == "seen"
                else type(task).instructions_unseen)
        self.instruction = pool[int(self.np_random.integers(len(pool)))]
        self._steps = 0
        self._done = False
        self._last = task.evaluate()
        plan = task.plan()
        info = {**self.spec_info, "instruction": self.instruction, "plan": plan,
                "hidden": task.hidden_state(), "progress": self._last.progress,
                "predicates": self._last.predicates, **self._subtask_info(self._last, ended=False)}
        return self._observation(), info

    def step(self, action):
        if self._done:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        action = self._validate(action)
        clipped, n_clipped = self.sim.clip_action(action)
        stage_before = self._last.stage
        info: dict[str, Any] = {"clipped_targets": n_clipped}
        try:
            self.sim.step(clipped, on_substep=self.task.on_substep)
        except SimulationError as err:
            log.warning("physics error in %s: %s", type(self.task).name, err)
            self._done = True
            self._steps += 1
            # every key a step's info holds, the task's as of the last sound step
            info.update(sim_error=str(err), is_success=False, failure=False,
                        failure_reason=f"sim error: {err}", progress=self._last.progress,
                        predicates=self._last.predicates, step=self._steps,
                        **self._subtask_info(self._last, ended=False))
            # truncated, not terminated: the episode is cut off, not ended by the task
            return self._observation(safe=True), 0.0, False, True, info
        ev = self.task.evaluate()
        reward = ev.progress - self._last.progress
        self._last = ev
        self._steps += 1
        terminated = ev.success or ev.failure
        truncated = not terminated and self._steps >= self.step_limit
        self._done = terminated or truncated
        info.update(is_success=ev.success, failure=ev.failure, failure_reason=ev.failure_reason,
                    progress=ev.progress, predicates=ev.predicates, step=self._steps,
                    **self._subtask_info(ev, ended=ev.stage > stage_before))
        return self._observation(), float(reward), terminated, truncated, info

    def render(self):
        return self.sim.render(["third_person"], *self.config.video_size)["third_person"]

    def close(self):
        self.sim.close()

    # ------------------------------------------------------------------- helpers
    def _subtask_info(self, ev: Evaluation, ended: bool) -> dict[str, Any]:
        plan = self.task.plan()
        idx = plan[ev.stage] if ev.stage < len(plan) else -1
        return {"subtask": type(self.task).subtasks[idx] if idx >= 0 else "done",
                "subtask_index": idx, "subtask_step": ev.stage, "subtask_end": ended}

    def _validate(self, action) -> np.ndarray:
        raw = np.asarray(action)
        if raw.dtype.kind not in "biuf":  # (numpy would drop a complex part with a warning)
            raise ValueError(f"action must hold real numbers, got {raw.dtype} values")
        a = raw.astype(np.float64)
        if a.shape != (ACTION_DIM,):
            raise ValueError(f"action must have shape ({ACTION_DIM},), got {a.shape}")
        if not np.isfinite(a).all():
            bad = np.flatnonzero(~np.isfinite(a)).tolist()
            raise ValueError(f"action has NaN/inf at indices {bad}")
        return a

    def _observation(self, safe: bool = False) -> dict[str, Any]:
        """The observation, within ``observation_space``. Only the returned arrays are
        clipped, never the simulation's state: an episode is the same with or without it.

        agent_pos: MuJoCo's joint limits are soft constraints, so a joint can stand past its
        limit: a hair at rest (an open gripper reads 1 + 6e-7, its finger held against the
        stop) and by centimetres under a hard load (a light finger on an arm that arbitrary
        targets whip about at tens of rad/s reads beyond -2 and 2.5). The model bounds none
        of that, and a reading past a limit is no pose the arm can take, so it reads as at
        the limit rather than the space being widened by a guess.

        environment_state: nothing walls the room (an arm swung at arbitrary targets can
        throw a piece 10 m), so a position reads as at the edge of the declared 5 m around
        the table, further than any camera sees (a cap pushed past its stop, a soft limit
        too, likewise reads at 5 cm); headings, flags, one-hots and colours lie within their
        bounds by construction."""
        pos = self.sim.agent_pos()
        if safe:
            pos = np.nan_to_num(pos, nan=0.0, posinf=0.0, neginf=0.0)
        space = self.observation_space.spaces
        obs: dict[str, Any] = {"agent_pos": np.clip(pos, space["agent_pos"].low,
                                                    space["agent_pos"].high)}
        if self.with_state:
            state = self.task.environment_state()
            if safe:
                state = np.nan_to_num(state, nan=0.0, posinf=0.0, neginf=0.0)
            obs["environment_state"] = np.clip(state, space["environment_state"].low,
                                               space["environment_state"].high)
        if self.config.render and self.obs_type.startswith("pixels"):
            if safe:
                obs["pixels"] = {c: np.zeros((self.config.height, self.config.width, 3), np.uint8)
                                 for c in self.config.cameras}
            else:
                obs["pixels"] = self.sim.render()
        return obs
