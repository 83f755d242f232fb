"""The episode job that evaluation workers run, with one (env, policy) kept per process.

Building an env and a policy costs more than a short episode, so a worker keeps them while
consecutive jobs ask for the same task, policy and instruction set.
"""

from __future__ import annotations

from typing import Any

from rmbench.envs.registration import make
from rmbench.eval.episode import run_policy_episode
from rmbench.eval.probe import MemoryReset
from rmbench.policies.registry import env_options, make_policy

_WORKER: dict[str, Any] = {}


def episode_job(task: str, policy: str, instructions: str, seed: int, video: bool,
                memory_reset: str | None = None) -> dict:
    key = (task, policy, instructions)
    if _WORKER.get("key") != key:
        close_worker()
        # the observation the policy reads (a state checkpoint: environment_state_agent_pos)
        env = make(task, instructions=instructions, **env_options(policy))
        _WORKER.update(key=key, env=env, policy=make_policy(policy, env))
    probe = MemoryReset.parse(memory_reset) if memory_reset else None
    return run_policy_episode(_WORKER["env"], _WORKER["policy"], seed, video, memory_reset=probe)


def close_worker() -> None:
    if "env" in _WORKER:
        getattr(_WORKER["policy"], "close", lambda: None)()
        _WORKER["env"].close()
    _WORKER.clear()
