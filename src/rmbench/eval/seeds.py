"""Expert-verified evaluation seeds: an episode counts only if the scripted expert solves it.

Candidates run from ``100000 * (1 + seed)`` upward, physics only. The verified list is cached
per task, gym id (its version) and evaluation seed, so re-runs skip the search; a longer list
extends the cached one.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.rollout import run_episode
from rmbench.seeds import EVAL_SEED_STRIDE, eval_seed_start
from rmbench.tasks import get_task
from rmbench.video import write_atomic

log = logging.getLogger(__name__)


def cache_dir() -> Path:
    return Path(os.environ.get("RMBENCH_CACHE", Path.home() / ".cache" / "rmbench")) / "seeds"


def verified_seeds(task: str, seed: int, episodes: int, cache: Path | None = None) -> list[int]:
    """The first ``episodes`` seeds from evaluation seed ``seed`` that the expert solves."""
    cls = get_task(task)
    path = (cache or cache_dir()) / f"{cls.gym_id.replace('/', '_')}-seed{seed}.json"
    state = {"task": cls.name, "gym_id": cls.gym_id, "seed": seed, "verified": [], "rejected": []}
    if path.exists():
        try:
            state = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            log.warning("ignoring unreadable seed cache %s", path)
    if len(state["verified"]) >= episodes:
        return state["verified"][:episodes]
    tried = state["verified"] + [r["seed"] for r in state["rejected"]]
    candidate = max(tried) + 1 if tried else eval_seed_start(seed)
    env = make(cls.name, render=False)
    expert = make_expert(env)
    try:
        while len(state["verified"]) < episodes:
            if candidate >= eval_seed_start(seed) + EVAL_SEED_STRIDE:
                raise RuntimeError(f"{cls.name}: fewer than {episodes} expert-solved seeds "
                                   f"from {eval_seed_start(seed)}")
            result = run_episode(env, expert, candidate)
            if result.success:
                state["verified"].append(candidate)
            else:
                log.info("%s: evaluation seed %d rejected (%s)", cls.name, candidate, result.reason)
                state["rejected"].append({"seed": candidate, "reason": result.reason})
            candidate += 1
    finally:
        env.close()
        write_atomic(path, (json.dumps(state, indent=1) + "\n").encode())
    return state["verified"][:episodes]
