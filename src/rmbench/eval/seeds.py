"""Expert-verified evaluation seeds: an episode counts only if the scripted expert solves it.

Candidates run from the first seed of the evaluation seed's split upward (``rmbench.seeds``:
test from ``100000 * (1 + seed)``, validation 50000 further), physics only, through the same episode
job as the evaluation (so on the evaluation's workers). Results are taken in candidate order,
so the list is the first N solved seeds whatever the worker count. The list is cached per
task, gym id (its version), evaluation seed and split and saved after every candidate, so re-runs and
interrupted searches skip what is known; a longer list extends the cached one.

rmbench ships the benchmark's lists (evaluation seed 0, both splits: ``SHIPPED``, made by
``scripts/ship_seed_lists.py``), so the default cache starts from them and a new machine
evaluates at once. A cache folder given explicitly starts empty: it verifies every seed on
the machine it runs on.
"""

from __future__ import annotations

import logging
import os
from collections import deque
from pathlib import Path

from tqdm import tqdm

from rmbench.eval.worker import close_worker, episode_job
from rmbench.files import lock, read_json_or, write_json
from rmbench.parallel import Inline
from rmbench.seeds import SPLIT_STRIDE, eval_seed_start
from rmbench.tasks import get_task

log = logging.getLogger(__name__)


SHIPPED = Path(__file__).with_name("verified_seeds")  # lists verified once, in the cache's format


def cache_dir() -> Path:
    return Path(os.environ.get("RMBENCH_CACHE", Path.home() / ".cache" / "rmbench")) / "seeds"


def list_name(task: str, seed: int, split: str = "test") -> str:
    """The file a task version's seed list is kept in, in a cache and in ``SHIPPED``."""
    # (the test split's file keeps the name it had before there were splits)
    suffix = "" if split == "test" else f"-{split}"
    return f"{get_task(task).gym_id.replace('/', '_')}-seed{seed}{suffix}.json"


def verified_seeds(task: str, seed: int, episodes: int, cache: Path | None = None,
                   executor=None, progress: bool = False, split: str = "test") -> list[int]:
    """The first ``episodes`` seeds of evaluation seed ``seed``'s ``split`` that the expert
    solves."""
    cls = get_task(task)
    start = eval_seed_start(seed, split)
    path = Path(cache or cache_dir()) / list_name(task, seed, split)
    shipped = cache is None
    state = _cached(path, cls, seed, shipped)
    if len(state["verified"]) >= episodes:
        return state["verified"][:episodes]
    # one search at a time (a table starts a task's evaluations together); the one that
    # waited reads what the other found
    with lock(path.with_name(path.name + ".lock"), wait=True):
        return _search(cls, _cached(path, cls, seed, shipped), path, start, episodes, executor, progress)


def _cached(path: Path, cls, seed: int, shipped: bool = False) -> dict:
    """The seed cache at ``path``, or (with ``shipped``, where there is none yet) the list
    rmbench ships under its name, or an empty one (where neither is a cache)."""
    cached = read_json_or(path, None)
    if cached is None and shipped:
        cached = read_json_or(SHIPPED / path.name, None)
    if cached is not None and isinstance(cached.get("verified"), list) and isinstance(
            cached.get("rejected"), list):
        return cached
    if path.exists():
        log.warning("ignoring unreadable seed cache %s", path)
    return {"task": cls.name, "gym_id": cls.gym_id, "seed": seed, "verified": [], "rejected": []}


def _search(cls, state: dict, path: Path, start: int, episodes: int, executor,
            progress: bool) -> list[int]:
    """``state``'s verified seeds extended to ``episodes``, saved after every candidate."""
    verified = state["verified"]
    if len(verified) >= episodes:
        return verified[:episodes]
    tried = verified + [r["seed"] for r in state["rejected"]]
    candidate = max(tried) + 1 if tried else start
    end = start + SPLIT_STRIDE
    own = executor is None
    executor = executor or Inline(on_close=close_worker)
    pending: deque = deque()
    bar = tqdm(total=episodes, initial=len(verified), unit="seed", disable=not progress,
               desc=f"{cls.name} verifying seeds", dynamic_ncols=True)
    try:
        while len(verified) < episodes:
            # never more in flight than could still be needed: the list stays the first N
            while (len(pending) < executor.window and candidate < end
                   and len(verified) + len(pending) < episodes):
                pending.append((candidate, executor.submit(
                    episode_job, cls.name, "expert", "seen", candidate)))
                candidate += 1
            if not pending:
                raise RuntimeError(f"{cls.name}: fewer than {episodes} expert-solved seeds "
                                   f"in [{start}, {end})")
            c, job = pending.popleft()
            record = job.result()
            if record["success"]:
                verified.append(c)
                bar.update(1)
            else:
                log.info("%s: evaluation seed %d rejected (%s)", cls.name, c, record["reason"])
                state["rejected"].append({"seed": c, "reason": record["reason"]})
            write_json(path, state)
    finally:
        bar.close()
        if own:
            executor.shutdown()
    return verified[:episodes]
