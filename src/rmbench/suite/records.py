"""A cell as the committed results keep it (``benchmarks/results/*.json``): the row of
``table.json`` without its local folders, plus what the evaluation's records and the
checkpoint say about the policy's subtask ends (``rmbench boundaries``) and its planner.
A cell pooled over training seeds keeps each seed's record under ``seeds``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rmbench.eval.boundaries import summarize
from rmbench.eval.harness import read_records
from rmbench.eval.intervals import wilson
from rmbench.eval.report import Rate

KEEP = ("successes", "episodes", "success_rate", "success_ci95", "mean_progress", "endings",
        "failure_reasons", "train_wall_s", "train_wall_from_step", "eval_wall_s", "machines",
        "memory", "gym_id")


def cell_record(row: dict[str, Any], task: str) -> dict[str, Any]:
    """``row`` (a cell of ``table.json``) as a results file keeps it. Reads the cell's
    evaluation records and checkpoint folder, so it runs where the table ran."""
    out = {k: row.get(k) for k in KEEP if k in row}
    if "seeds" in row:
        out["seeds"] = {seed: cell_record(r, task) for seed, r in row["seeds"].items()}
        return out
    rate = Rate.of(row)  # a row written before rates carried their counts has the rate alone
    out["successes"] = rate.successes
    out["success_ci95"] = [round(v, 4) for v in wilson(rate.successes, rate.episodes)]
    out["boundaries"] = summarize(read_records(Path(row["evaluation"]) / task / "episodes.jsonl"))
    planner = Path(row["checkpoint"]) / "training" / "planner.json"  # M(n) checkpoints only
    out["planner"] = json.loads(planner.read_text()) if planner.exists() else None
    return out
