"""Verify the benchmark's evaluation seeds once and ship the lists with the package, so that
an evaluation on a new machine starts at its first episode instead of first running the
scripted expert on every candidate seed (``eval/seeds.py``).

    .venv/bin/python scripts/ship_seed_lists.py --tasks all --splits test,validation --workers 2

Each list is written into ``src/rmbench/eval/verified_seeds/`` in the seed cache's own format
(saved after every candidate, so an interrupted run resumes), and the wall time of each
search into ``benchmarks/results/seed_verification.json``: what a new machine saves.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from rmbench.eval.seeds import SHIPPED, list_name, verified_seeds
from rmbench.eval.worker import close_worker
from rmbench.files import read_json_or, write_json
from rmbench.machine import describe
from rmbench.parallel import make_executor
from rmbench.tasks import TASKS
from rmbench.tasks.registry import ordered

RESULT = Path(__file__).resolve().parents[1] / "benchmarks" / "results" / "seed_verification.json"


def _complete(task: str, split: str, episodes: int) -> bool:
    cached = read_json_or(SHIPPED / list_name(task, 0, split), None) or {}
    return len(cached.get("verified", [])) >= episodes


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tasks", default="all", help="comma-separated task names, or all")
    p.add_argument("--splits", default="test,validation")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--workers", type=int, default=2)
    args = p.parse_args(argv)
    tasks = [t.name for t in ordered()] if args.tasks == "all" else args.tasks.split(",")
    unknown = [t for t in tasks if t not in TASKS]
    if unknown:
        raise SystemExit(f"unknown task(s) {unknown}; known: {', '.join(TASKS)}")
    # the lists complete before the run (copied from a seed cache, or made by an earlier run)
    complete = {f"{t}/{split}" for split in args.splits.split(",") for t in tasks
                if _complete(t, split, args.episodes)}
    doc = read_json_or(RESULT, None) or {"episodes": args.episodes, "seed": 0, "searches": {}}
    for split in args.splits.split(","):
        for task in tasks:
            executor = make_executor(args.workers, on_close=close_worker)
            start = time.perf_counter()
            try:
                seeds = verified_seeds(task, 0, args.episodes, SHIPPED, executor, progress=True,
                                       split=split)
            finally:
                executor.shutdown()
            key = f"{task}/{split}"
            wall = time.perf_counter() - start
            # a list complete before the run cost nothing here: keep the wall of the search
            # that made it, or say it was not kept
            found = key in complete
            if not found or key not in doc["searches"]:
                doc["searches"][key] = {
                    "wall_s": None if found else round(wall, 1), "workers": args.workers,
                    "first": seeds[0], "last": seeds[-1], "machine": describe(),
                    "note": "complete before this run: its search's wall was not kept"
                    if found else None}
                write_json(RESULT, doc)
            print(f"{key}: {len(seeds)} seeds, {wall:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
