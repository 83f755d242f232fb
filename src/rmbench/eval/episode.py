"""One evaluation episode of a policy: until success, task failure or the step limit.

Whatever the policy does wrong (raises, returns NaN or a wrong shape) ends the episode as
``policy_error`` with the message; it never stops the evaluation. The record keeps the
episode's events (``eval/events.py``): when the task's subtask and discrete facts changed,
and the policy's own status where it reports one (``status()``: a Mem-0's subtask).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from rmbench.eval.events import Events
from rmbench.sim.simulator import ACTION_DIM
from rmbench.video import PREVIEW_CODEC, Mp4Encoder

ENDINGS = ("success", "task_failure", "timeout", "policy_error", "sim_error")


def as_chunk(out) -> np.ndarray:
    """A policy's answer as a (k, 14) float64 chunk, or ValueError saying what is wrong."""
    a = np.asarray(out, dtype=np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != ACTION_DIM or len(a) == 0:
        raise ValueError(f"action must have shape ({ACTION_DIM},) or (k, {ACTION_DIM}), got "
                         f"{np.shape(out)}")
    if not np.isfinite(a).all():
        raise ValueError("action has NaN/inf values")
    return a


def run_policy_episode(env, policy, seed: int, video: bool = False,
                       on_step: Callable[[int, dict], None] | None = None) -> dict[str, Any]:
    """Returns the episode's record; ``record["video"]`` holds MP4 bytes when ``video``.
    ``on_step(step, info)`` after every env step lets an analysis watch the scene of the very
    episode the evaluation runs (``scripts/swap_placements.py``)."""
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    u = env.unwrapped
    task_info = {**u.spec_info, "seed": seed, "instruction": info["instruction"]}
    encoder = Mp4Encoder(u.metadata["render_fps"], PREVIEW_CODEC) if video else None
    if encoder:
        encoder.add(env.render())
    best, steps, reason, message, success = float(info["progress"]), 0, "timeout", "", False
    queue: list[np.ndarray] = []
    events = Events()
    events.update(0, "task", {"subtask": info["subtask"], "subtask_step": info["subtask_step"],
                              **info["predicates"]})
    status = getattr(policy, "status", dict)
    try:
        policy.reset(info["instruction"], task_info)
    except Exception as err:
        reason, message = "policy_error", f"reset: {type(err).__name__}: {err}"
        queue = None  # type: ignore[assignment]
    while queue is not None:
        if not queue:
            try:
                queue = list(as_chunk(policy.act(obs)))
                events.update(steps, "policy", status())
            except Exception as err:
                reason, message = "policy_error", f"{type(err).__name__}: {err}"
                break
        obs, _, terminated, truncated, info = env.step(queue.pop(0))
        steps += 1
        if on_step:
            on_step(steps, info)
        events.update(steps, "task", {"subtask": info.get("subtask", ""),
                                      "subtask_step": info.get("subtask_step", 0),
                                      **info.get("predicates", {})})
        best = max(best, float(info["progress"]))
        if encoder:
            encoder.add(env.render())
        if terminated or truncated:
            success = bool(info["is_success"])
            if success:
                reason = "success"
            elif info.get("sim_error"):
                reason, message = "sim_error", info["sim_error"]
            elif terminated:
                reason, message = "task_failure", info.get("failure_reason") or ""
            break
    return {"task": type(u.task).name, "seed": seed, "success": success,
            "progress": round(best, 6), "steps": steps, "step_limit": u.step_limit,
            "reason": reason, "message": message, "instruction": task_info["instruction"],
            "wall_s": round(time.perf_counter() - t0, 3), "events": events.to_list(),
            "video": encoder.finish() if encoder else None}
