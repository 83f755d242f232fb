"""A table cell's row, read from its finished evaluation and its folders' clocks, and one
column's row pooled over its training seeds."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from rmbench.eval.intervals import ci95
from rmbench.eval.records import read_records
from rmbench.files import read_json_or
from rmbench.suite.clock import TIMING
from rmbench.suite.plan import Plan, memory_of
from rmbench.suite.stages import evaluated
from rmbench.tasks import get_task


def failure_reasons(records: Path) -> dict[str, int]:
    """How the failed episodes ended, by the message the task or the harness gave, most
    frequent first ("timeout" for an episode that ran out of steps)."""
    counts = Counter(r["message"] or r["reason"] for r in read_records(records)
                     if not r["success"])
    return dict(counts.most_common())


def cell_row(plan: Plan, out: Path, task: str, spec: str) -> dict[str, Any] | None:
    """A finished cell's row (success rate with its Wilson 95% interval, progress, endings,
    failure reasons, wall times and the machines they were measured on, its memory in words,
    its folders), or None while it is not evaluated."""
    result = evaluated(plan, out, task, spec)
    if result is None:
        return None
    ckpt, evals = plan.train_dir(out, task, spec), plan.eval_dir(out, task, spec)
    cfg = plan.config(task, spec)
    return {**result_row(result, task, ckpt, evals, read_json_or(ckpt / TIMING, {}),
                         read_json_or(evals / TIMING, {})),
            "memory": memory_of(spec, get_task(task).tmc, cfg)}


def result_row(result: dict[str, Any], task: str, ckpt: Path, evals: Path,
               train_timing: dict[str, Any], eval_timing: dict[str, Any]) -> dict[str, Any]:
    """A cell's row from its task's evaluation summary (``result``), its checkpoint and
    evaluation folders and their clocks (``timing.json``'s fields)."""
    n = result["episodes"]
    k = result.get("successes", round(result["success_rate"] * n))  # (older summaries)
    return {"success_rate": result["success_rate"], "successes": k,
            "success_ci95": ci95(k, n),
            "mean_progress": result["mean_progress"],
            "episodes": n, "endings": result["endings"],
            "failure_reasons": failure_reasons(evals / task / "episodes.jsonl"),
            "train_wall_s": train_timing.get("train_wall_s"),
            "train_wall_from_step": train_timing.get("train_wall_from_step", 0),
            "eval_wall_s": eval_timing.get("eval_wall_s"),
            "machines": {"train": train_timing.get("machines", []),
                         "eval": eval_timing.get("machines", [])},
            "checkpoint": str(ckpt), "evaluation": str(evals),
            # a planner-only ablation's train wall is its planner's; its executor trained here
            **({"executor_from": train_timing["executor_from"]}
               if train_timing.get("executor_from") else {}),
            **({"gym_id": result["gym_id"]} if result.get("gym_id") else {})}  # (older summaries)


def pooled_row(rows: dict[int, dict[str, Any] | None]) -> dict[str, Any] | None:
    """One column's row over its training seeds (``{seed: cell_row}``): the single seed's row
    as it is; for several, their episodes pooled (so the success rate is the seeds' mean, each
    having run the same episodes) with the pooled Wilson interval, and every seed's row under
    ``seeds``. None until every seed is evaluated: a mean over the seeds done so far would
    change as the others arrive."""
    if any(r is None for r in rows.values()):
        return None
    if len(rows) == 1:
        return next(iter(rows.values()))
    seeds = [rows[s] for s in sorted(rows)]
    if len({r.get("gym_id") for r in seeds}) > 1:
        raise ValueError(f"the seeds of one cell ran on different task versions: "
                         f"{sorted({str(r.get('gym_id')) for r in seeds})}")
    n, k = sum(r["episodes"] for r in seeds), sum(r["successes"] for r in seeds)
    walls = {w: sum(r[w] or 0 for r in seeds) for w in ("train_wall_s", "eval_wall_s")}
    return {"success_rate": round(k / n, 4), "successes": k,
            "success_ci95": ci95(k, n),
            "mean_progress": round(sum(r["mean_progress"] * r["episodes"] for r in seeds) / n, 4),
            "episodes": n,
            "endings": dict(sum((Counter(r["endings"]) for r in seeds), Counter())),
            "failure_reasons": dict(sum((Counter(r["failure_reasons"]) for r in seeds),
                                        Counter()).most_common()),
            **walls, "train_wall_from_step": 0,
            "machines": {stage: [m for r in seeds for m in r["machines"][stage]]
                         for stage in ("train", "eval")},
            # a row of an eval folder (evaluation_rows) says nothing of memory; another may
            **next(({"memory": r["memory"]} for r in seeds if "memory" in r), {}),
            **({"gym_id": seeds[0]["gym_id"]} if "gym_id" in seeds[0] else {}),
            "seeds": {str(s): rows[s] for s in sorted(rows)}}
