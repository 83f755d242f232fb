"""The episode jobs that evaluation workers run, with one policy and its envs kept per process.

Building an env and a policy costs more than a short episode, so a worker keeps them while
consecutive jobs ask for the same task, policy and instruction set. A job of several seeds
plays them side by side, up to ``batch`` at a time, when the policy has the batched form of
the interface (``policies/base.py``), one env per slot.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rmbench.envs.registration import make
from rmbench.eval.episode import batches, run_policy_episodes
from rmbench.eval.probe import MemoryReset
from rmbench.policies.registry import env_options, make_policy

_WORKER: dict[str, Any] = {}


def _setup(task: str, policy: str, instructions: str, envs: int = 1) -> tuple[list, Any]:
    """This worker's policy and at least ``envs`` envs of the task (the first is the one the
    policy was made with)."""
    key = (task, policy, instructions)
    if _WORKER.get("key") != key:
        close_worker()
        # the observation the policy reads (a state checkpoint: environment_state_agent_pos),
        # asked once: a remote policy's answer costs a connection to its server
        options = env_options(policy)
        env = make(task, instructions=instructions, **options)
        _WORKER.update(key=key, envs=[env], policy=make_policy(policy, env), options=options)
    while len(_WORKER["envs"]) < envs:
        _WORKER["envs"].append(make(task, instructions=instructions, **_WORKER["options"]))
    return _WORKER["envs"], _WORKER["policy"]


def policy_batches(task: str, policy: str, instructions: str) -> bool:
    """Does the policy take several episodes at once? (Asked of a worker, which keeps it.)"""
    return batches(_setup(task, policy, instructions)[1])


def episodes_job(task: str, policy: str, instructions: str, seeds: list[int],
                 videos: list[bool], memory_reset: str | None = None,
                 batch: int = 1, positions: list[int] | None = None,
                 on_record: Callable[[int, dict], None] | None = None) -> list[dict]:
    """The records of ``seeds``' episodes in seed order, up to ``batch`` side by side, seed k
    in slot ``positions[k]`` (its place among the task's seeds modulo ``batch``: the same in
    every job it could fall in). The policy is always asked for ``batch`` slots, however few
    seeds the job has (a resumed run's last ones), so what it computes does not depend on how
    the seeds were split. ``on_record``: ``run_policy_episodes``' (a job run in the caller's
    process)."""
    _, made = _setup(task, policy, instructions)
    batch = batch if batches(made) else 1
    most = getattr(made, "max_batch", None)
    if most is not None and batch > most:  # (before any episode: the run stops, nothing kept)
        raise ValueError(f"{policy} plays at most {most} episodes at once; evaluate it with "
                         f"--batch {most} or fewer")
    positions = [p % batch for p in positions] if positions is not None else [
        k % batch for k in range(len(seeds))]
    envs, made = _setup(task, policy, instructions, max(positions, default=0) + 1)
    probe = MemoryReset.parse(memory_reset) if memory_reset else None
    return run_policy_episodes(envs, made, seeds, videos, memory_reset=probe, slots=batch,
                               positions=positions, on_record=on_record)


def episode_job(task: str, policy: str, instructions: str, seed: int) -> dict:
    """One episode's record, without video (the seed search's job)."""
    return episodes_job(task, policy, instructions, [seed], [False])[0]


def close_worker() -> None:
    if "envs" in _WORKER:
        getattr(_WORKER["policy"], "close", lambda: None)()
        for env in _WORKER["envs"]:
            env.close()
    _WORKER.clear()
