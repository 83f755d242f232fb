"""Evaluation episodes of a policy: each until success, task failure or the step limit.

Whatever the policy does wrong (raises, returns NaN or a wrong shape) ends the episode as
``policy_error`` with the message; it never stops the evaluation. The record keeps the
episode's events (``eval/events.py``): when the task's subtask and discrete facts changed,
and the policy's own status where it reports one (``status()``: a Mem-0's subtask). With a
memory probe (``eval/probe.py``) the policy is reset mid-episode and the record lists the
steps at which it was (``memory_resets``).

``run_policy_episodes`` runs several episodes side by side, one env each, and asks a policy
with the batched form of the interface (``policies/base.py``) once per step for all of them:
a slot whose episode ended takes the next seed. A policy without it plays its episodes one
after another. ``run_policy_episode`` is the one-episode case; both keep each episode's
bookkeeping in ``_Episode``, so a record does not depend on how it was run.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rmbench.eval.events import Events
from rmbench.eval.probe import MemoryReset
from rmbench.policies.base import PolicyUnavailable
from rmbench.sim.simulator import ACTION_DIM
from rmbench.video import PREVIEW_CODEC, Mp4Encoder

ENDINGS = ("success", "task_failure", "timeout", "policy_error", "sim_error")


def as_chunk(out) -> np.ndarray:
    """A policy's answer as a (k, 14) float64 chunk, or ValueError saying what is wrong."""
    a = np.asarray(out)
    if a.dtype.kind not in "biuf":  # (a complex or text answer would be cast, not refused)
        raise ValueError(f"action must hold real numbers, got dtype {a.dtype}")
    a = a.astype(np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != ACTION_DIM or len(a) == 0:
        raise ValueError(f"action must have shape ({ACTION_DIM},) or (k, {ACTION_DIM}), got "
                         f"{np.shape(out)}")
    if not np.isfinite(a).all():
        raise ValueError("action has NaN/inf values")
    return a


def batches(policy) -> bool:
    """Does ``policy`` take several episodes at once (``act_batch``, policies/base.py)?"""
    return callable(getattr(policy, "act_batch", None))


class OneAtATime:
    """The batched form over a policy without it: one slot, the policy's own methods."""

    def __init__(self, policy):
        self.policy = policy
        self._status = getattr(policy, "status", dict)

    def reset_batch(self, slot: int, instruction: str, task_info: dict[str, Any], env) -> None:
        self.policy.reset(instruction, task_info)

    def act_batch(self, observations: list) -> list:
        (observation,) = observations
        return [None if observation is None else self.policy.act(observation)]

    def status_batch(self, slot: int) -> dict[str, Any]:
        return self._status()


class _Episode:
    """One episode's bookkeeping: its env, the chunk being executed, events, progress,
    ending, video and memory-probe resets; ``record()`` when it has ended."""

    def __init__(self, env, seed: int, video: bool, memory_reset: MemoryReset | None):
        self.t0 = time.perf_counter()
        self.env, self.seed = env, seed
        self.obs, info = env.reset(seed=seed)
        u = self.u = env.unwrapped
        self.task_info = {**u.spec_info, "seed": seed, "instruction": info["instruction"]}
        self.encoder = Mp4Encoder(u.metadata["render_fps"], PREVIEW_CODEC) if video else None
        if self.encoder:
            self.encoder.add(env.render())
        self.best, self.steps, self.success = float(info["progress"]), 0, False
        self.reason, self.message = "timeout", ""
        self.queue: list[np.ndarray] = []
        self.events = Events()
        self.events.update(0, "task", {"subtask": info["subtask"],
                                       "subtask_step": info["subtask_step"], **info["predicates"]})
        self.probe = memory_reset
        self.trigger = memory_reset.trigger(type(u.task).aliasing_stage) if memory_reset else None
        self.resets: list[int] = []
        self.ended = False

    def fail(self, message: str) -> None:
        self.reason, self.message, self.ended = "policy_error", message, True

    def reset_policy(self, policy, slot: int) -> None:
        try:
            policy.reset_batch(slot, self.task_info["instruction"], self.task_info, self.env)
        except PolicyUnavailable:
            raise  # (nothing about this episode: it is played again when the run resumes)
        except Exception as err:
            self.fail(f"reset: {type(err).__name__}: {err}")

    def answer(self, out, status: Callable[[], dict]) -> None:
        """The policy's answer to this episode's observation: the chunk to execute next."""
        try:
            self.queue = list(as_chunk(out))
            self.events.update(self.steps, "policy", status())
        except Exception as err:
            self.fail(f"{type(err).__name__}: {err}")

    def step(self, policy, slot: int, on_step: Callable[[int, dict], None] | None) -> None:
        """Execute the chunk's next action; a memory probe's reset where it is due."""
        self.obs, _, terminated, truncated, info = self.env.step(self.queue.pop(0))
        self.steps += 1
        if on_step:
            on_step(self.steps, info)
        self.events.update(self.steps, "task", {"subtask": info.get("subtask", ""),
                                                "subtask_step": info.get("subtask_step", 0),
                                                **info.get("predicates", {})})
        self.best = max(self.best, float(info["progress"]))
        if self.encoder:
            self.encoder.add(self.env.render())
        if terminated or truncated:
            self.ended, self.success = True, bool(info["is_success"])
            if self.success:
                self.reason = "success"
            elif info.get("sim_error"):
                self.reason, self.message = "sim_error", info["sim_error"]
            elif terminated:
                self.reason, self.message = "task_failure", info.get("failure_reason") or ""
            return
        if self.trigger is not None and self.trigger.due(self.steps, info):
            self.resets.append(self.steps)
            self.queue = []  # a chunk asked for before the reset is memory too
            self.reset_policy(policy, slot)

    def record(self) -> dict[str, Any]:
        u = self.u
        record = {"task": type(u.task).name, "seed": self.seed, "success": self.success,
                  "progress": round(self.best, 6), "steps": self.steps,
                  "step_limit": u.step_limit, "reason": self.reason, "message": self.message,
                  "instruction": self.task_info["instruction"],
                  "wall_s": round(time.perf_counter() - self.t0, 3),
                  "events": self.events.to_list(),
                  "video": self.encoder.finish() if self.encoder else None}
        if self.probe is not None:  # (absent otherwise: records without the probe stay as they were)
            record["memory_resets"] = self.resets
        return record


def run_policy_episodes(envs: Sequence, policy, seeds: Sequence[int],
                        videos: Sequence[bool] | None = None,
                        on_step: Callable[[int, int, dict], None] | None = None,
                        memory_reset: MemoryReset | None = None,
                        slots: int | None = None,
                        positions: Sequence[int] | None = None,
                        on_record: Callable[[int, dict], None] | None = None
                        ) -> list[dict[str, Any]]:
    """The records of ``seeds``' episodes, in seed order. A policy with ``act_batch`` plays
    them side by side in ``slots`` slots (default ``len(envs)``), ``seeds[k]`` in slot
    ``positions[k]`` (default k modulo the envs), after the earlier seeds of that slot, in
    ``envs[positions[k]]``; it is asked once per step for every episode whose chunk is used
    up, as a list of ``slots`` observations, None for a slot with nothing to ask, so it sees
    one batch size however many seeds there are. A float kernel may treat a row by its
    place in the batch (a matrix's last rows in another tile), so a seed's slot is given
    rather than whichever fell free first: a seed keeps its place however the seeds are split
    into jobs, and with it its record. A policy without it plays them one after another in
    ``envs[0]`` (the env it was made with, for a policy that reads the simulator).
    ``videos[k]``: keep ``seeds[k]``'s video (MP4 bytes in ``record["video"]``).
    ``on_step(seed, step, info)`` after every env step; ``memory_reset`` resets the policy's
    slot where the probe says, dropping what is left of its last chunk. An exception from
    ``act_batch`` ends the episodes it was asked for. ``on_record(k, record)`` as
    ``seeds[k]``'s episode ends (a caller in this process keeps each as it comes)."""
    if not envs:
        raise ValueError("no env to run episodes in")
    if not batches(policy):
        policy, slots, positions = OneAtATime(policy), 1, [0] * len(seeds)
    slots = slots or len(envs)
    used = min(slots, len(envs))
    positions = list(positions) if positions is not None else [k % used for k in
                                                                range(len(seeds))]
    if positions and not (0 <= min(positions) and max(positions) < used):
        raise ValueError(f"slots {sorted(set(positions))} for {slots} slots and {len(envs)} envs")
    videos = list(videos) if videos is not None else [False] * len(seeds)
    status = getattr(policy, "status_batch", lambda slot: {})
    todo = [deque((k, seeds[k]) for k in range(len(seeds)) if positions[k] == slot)
            for slot in range(slots)]
    records: dict[int, dict[str, Any]] = {}
    running: list[tuple[int, _Episode] | None] = [None] * slots

    def start(slot: int) -> None:
        """The slot's next seed (None when none is left); a failed reset ends it."""
        while todo[slot]:
            k, seed = todo[slot].popleft()
            ep = _Episode(envs[slot], seed, videos[k], memory_reset)
            ep.reset_policy(policy, slot)
            if not ep.ended:
                running[slot] = (k, ep)
                return
            ended(k, ep)
        running[slot] = None

    def ended(k: int, ep: _Episode) -> None:
        records[k] = ep.record()
        if on_record is not None:
            on_record(k, records[k])

    for slot in range(slots):
        start(slot)
    while any(running):
        ask = [s[1].obs if s is not None and not s[1].queue else None for s in running]
        if any(o is not None for o in ask):
            try:
                answers = list(policy.act_batch(ask))
                if len(answers) != len(ask):
                    raise ValueError(f"act_batch answered {len(answers)} of {len(ask)} slots")
            except PolicyUnavailable:
                raise
            except Exception as err:
                answers = [err] * len(ask)
            for slot, (obs, out) in enumerate(zip(ask, answers, strict=True)):
                if obs is None:
                    continue
                ep = running[slot][1]
                if isinstance(out, Exception):
                    ep.fail(f"{type(out).__name__}: {out}")
                else:
                    ep.answer(out, lambda slot=slot: status(slot))
        for slot, s in enumerate(running):
            if s is None:
                continue
            k, ep = s
            if not ep.ended:
                seed = ep.seed
                ep.step(policy, slot, on_step and (lambda step, info, seed=seed:
                                                   on_step(seed, step, info)))
            if ep.ended:
                ended(k, ep)
                start(slot)
    return [records[k] for k in range(len(seeds))]


def run_policy_episode(env, policy, seed: int, video: bool = False,
                       on_step: Callable[[int, dict], None] | None = None,
                       memory_reset: MemoryReset | None = None) -> dict[str, Any]:
    """Returns the episode's record; ``record["video"]`` holds MP4 bytes when ``video``.
    ``on_step(step, info)`` after every env step lets an analysis watch the scene of the very
    episode the evaluation runs (``scripts/swap_placements.py``). ``memory_reset`` resets the
    policy where the probe says, dropping what is left of its last chunk. A policy with the
    batched form plays it as a batch of one."""
    watch = on_step and (lambda _seed, step, info: on_step(step, info))
    return run_policy_episodes([env], policy, [seed], [video], watch, memory_reset)[0]
