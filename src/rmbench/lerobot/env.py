"""An rmbench task as LeRobot's evaluation expects a simulation env.

LeRobot's ``lerobot-eval`` makes ``gym.make(gym_id)`` envs in a vector env, seeds episode k
of a run with ``--seed`` + k, reads the observation in gym-aloha's layout (``pixels`` by
camera, ``agent_pos``, ``environment_state``: rmbench's own), the language instruction from
the env's ``task_description`` and the outcome from ``info["is_success"]``. Here seed k is
rmbench's k-th expert-verified evaluation seed (``eval/seeds.py``): ``--seed=0`` runs the
layouts ``rmbench eval --seed 0`` runs, in the same order, so the two commands' success rates
are measured on the same episodes.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from rmbench.envs.registration import make
from rmbench.eval.seeds import verified_seeds
from rmbench.tasks import TASKS, get_task

NAMESPACE = "rmbench_lerobot"


class LeRobotTaskEnv(gym.Env):
    """rmbench's env of ``task``, reset on verified seeds, with the instruction as the task."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, task: str, obs_type: str = "pixels_agent_pos",
                 cameras: tuple[str, ...] | str = ("head", "left_wrist", "right_wrist"),
                 width: int = 320, height: int = 240, eval_seed: int = 0,
                 instructions: str = "seen", render_mode: str | None = "rgb_array",
                 seed_cache: str | None = None):
        if isinstance(cameras, str):  # LeRobot's command line passes a comma-separated list
            cameras = tuple(c.strip() for c in cameras.split(",") if c.strip())
        self.task_name = get_task(task).name
        self.env = make(self.task_name, obs_type=obs_type, cameras=tuple(cameras), width=width,
                        height=height, instructions=instructions)
        self.eval_seed, self.seed_cache = eval_seed, seed_cache
        self.observation_space = self.env.observation_space
        self.action_space = self.env.action_space
        self.render_mode = render_mode
        # LeRobot's rollout reads the step limit here; rmbench truncates at the same step
        self._max_episode_steps = self.env.unwrapped.step_limit
        self.task = self.task_name  # LeRobot's suite envs name their task here
        self.task_description = ""  # the episode's instruction, set at reset
        self.rmbench_seed: int | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None and seed < 0:
            raise ValueError(f"an episode seed is an index into rmbench's verified seeds, got "
                             f"{seed}")
        super().reset(seed=seed)
        if seed is not None:
            seed = verified_seeds(self.task_name, self.eval_seed, seed + 1, self.seed_cache,
                                  progress=False)[seed]
        obs, info = self.env.reset(seed=seed, options=options)
        self.rmbench_seed = seed
        self.task_description = info["instruction"]
        return obs, {**info, "rmbench_seed": seed}

    def step(self, action):
        return self.env.step(action)

    def render(self):
        return self.env.render()

    def close(self):
        self.env.close()


def register() -> None:
    """``rmbench_lerobot/<task>`` for every task (LeRobot's ``gym_id``); idempotent."""
    for name in TASKS:
        gym_id = f"{NAMESPACE}/{name}"
        if gym_id not in gym.registry:
            # order_enforce off: LeRobot finds ``task_description`` with hasattr on the env
            # gym.make returns, which a wrapper would hide
            gym.register(id=gym_id, entry_point=LeRobotTaskEnv, kwargs={"task": name},
                         order_enforce=False, disable_env_checker=True)


register()
