"""Gymnasium ids ``rmbench/<TaskName>-v<N>`` for every registered task, and ``rmbench.make``.

N goes up whenever a task's behaviour changes (v1: debounced buttons, rubber finger pads,
servos that follow a jumpy target with a lag, experts that close the loop)."""

from __future__ import annotations

import gymnasium as gym

from rmbench.tasks import TASKS, get_task


def register_envs() -> None:
    """Register one gym id per task; a second registration of an id raises."""
    for name, cls in TASKS.items():
        if cls.gym_id in gym.registry:
            if gym.registry[cls.gym_id].kwargs.get("task") == name:
                continue  # this module was imported twice (e.g. reload): same entry
            raise ValueError(f"gym id {cls.gym_id} is already registered by someone else")
        gym.register(id=cls.gym_id, entry_point="rmbench.envs.env:RMBenchEnv",
                     kwargs={"task": name}, disable_env_checker=False)


def make(name: str, **config):
    """Make an env by task name or gym id; ``config`` goes to :class:`RMBenchEnv`."""
    from rmbench.envs.env import RMBenchEnv

    return RMBenchEnv(get_task(name), **config)
