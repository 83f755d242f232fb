"""The first thing a new user runs: the expert on every task, a video each, a summary."""

from __future__ import annotations

import time
from pathlib import Path

from rmbench.files import write_json
from rmbench.rollout import run_expert
from rmbench.tasks.registry import ordered


def quickstart(out: str | Path = "runs/quickstart", episodes: int = 3, seed: int = 100000,
               log=None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = []
    for cls in ordered():
        name = cls.name
        results = run_expert(name, range(seed, seed + episodes), video_dir=out, videos=1)
        ok = sum(r.success for r in results)
        row = {"task": name, "tmc": cls.tmc, "episodes": len(results), "successes": ok,
               "mean_steps": round(sum(r.steps for r in results) / len(results), 1),
               "step_limit": cls.step_limit, "video": results[0].video,
               "failures": [{"seed": r.seed, "reason": r.reason} for r in results
                            if not r.success]}
        rows.append(row)
        if log:
            log(f"{name:<18} {cls.tmc:<5} expert {ok}/{len(results)}  "
                f"mean steps {row['mean_steps']:>6}/{cls.step_limit}  video {row['video']}")
    summary = {"tasks": rows, "wall_s": round(time.perf_counter() - t0, 1),
               "all_succeeded": all(r["successes"] == r["episodes"] for r in rows)}
    write_json(out / "summary.json", summary, indent=2)
    if log:
        log(f"\n{len(rows)} tasks in {summary['wall_s']} s; summary: {out / 'summary.json'}")
    return summary
