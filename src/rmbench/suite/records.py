"""A cell as the committed results keep it (``benchmarks/results/*.json``): the row of
``table.json`` without its local folders, plus what the evaluation's records and the
checkpoint say about the policy's subtask ends (``rmbench boundaries``) and its planner.
A cell pooled over training seeds keeps each seed's record under ``seeds``. An ``rmbench
eval`` folder of one checkpoint gives such rows too (``evaluation_rows``).

A record's ``conditions`` say what its walls were measured under, as fields: per stage
(``train``, ``eval``) a list of pieces, one per machine or run a training went through, in
step order. A piece: ``machine`` (a key of the results' ``machines``), ``steps`` ([from, to]
of a training run in pieces), ``wall_s`` (the piece's own wall, where kept), ``threads``
(torch threads) or ``workers`` (evaluation workers), ``jobs_beside`` (other jobs sharing the
machine, 0 alone) and ``beside`` (what they were), ``includes`` (other work the wall holds)
and a ``note``; null where the record does not say, and the results' ``wall_defaults`` hold
then."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

from rmbench.eval.boundaries import boundary_counts
from rmbench.eval.endings import failures_by_stage
from rmbench.eval.intervals import ci95
from rmbench.eval.records import read_records
from rmbench.eval.report import Rate
from rmbench.machine import describe
from rmbench.policies.config import argument_ablations, split_policy
from rmbench.suite.cell_rows import result_row
from rmbench.suite.clock import TIMING
from rmbench.suite.plan import TABLE_EPISODES, split_seed
from rmbench.tasks import get_task
from rmbench.tasks.registry import recorded_gym_id

KEEP = ("successes", "episodes", "success_rate", "success_ci95", "mean_progress", "endings",
        "failure_reasons", "train_wall_s", "train_wall_from_step", "eval_wall_s", "machines",
        "memory", "gym_id", "planner_refit")


TRAIN_CONDITIONS = ("machine", "steps", "wall_s", "threads", "jobs_beside", "beside", "includes",
                    "note")
EVAL_CONDITIONS = ("machine", "workers", "jobs_beside", "beside", "includes", "note")


def unstated_conditions(spec: str) -> dict[str, list[dict[str, None]]]:
    """The ``conditions`` of a record that states none: one piece per stage, every field null
    (no training piece for ``gt_classifier``, which evaluates Mem-0's checkpoint)."""
    train = [] if spec.startswith("mem0:gt_classifier") else [dict.fromkeys(TRAIN_CONDITIONS)]
    return {"train": train, "eval": [dict.fromkeys(EVAL_CONDITIONS)]}


def stated_conditions(spec: str, stages: dict[str, dict[str, Any]] | None = None,
                      train_pieces: list[dict[str, Any]] | None = None,
                      **fields: Any) -> dict[str, list[dict[str, Any]]]:
    """``unstated_conditions(spec)`` with ``fields`` (``machine``, ``jobs_beside``,
    ``beside``, ``note``, ``threads`` for a training, ``workers`` for an evaluation) written
    into each stage's one piece where the stage has that field, then ``stages``' fields into
    the named stage's alone (``{"train": {"note": ...}}``: what only the training needs
    said); a field given as None stays unstated. ``train_pieces``: a training that ran in
    pieces (on a GPU, then resumed on a CPU), one dict of training fields each, in step
    order; they replace the training's one piece, and ``fields`` fill only what a piece
    leaves unsaid. An unknown field or stage is a ValueError."""
    stages = stages or {}
    known = set(TRAIN_CONDITIONS) | set(EVAL_CONDITIONS)
    unknown = sorted(set(fields).union(*stages.values()) - known)
    if unknown:
        raise ValueError(f"no condition field {', '.join(unknown)}; fields: {', '.join(sorted(known))}")
    out = unstated_conditions(spec)
    if set(stages) - set(out):
        raise ValueError(f"no stage {', '.join(sorted(set(stages) - set(out)))}; stages: "
                         f"{', '.join(out)}")
    for stage, pieces in out.items():
        for piece in pieces:
            for said in (fields, stages.get(stage, {})):
                piece.update({k: v for k, v in said.items() if k in piece and v is not None})
    if train_pieces:
        if not out["train"]:
            raise ValueError(f"{spec} trains nothing of its own: it has no training pieces")
        said = {**fields, **{k: v for k, v in stages.get("train", {}).items() if v is not None}}
        out["train"] = [_training_piece(p, said, i) for i, p in enumerate(train_pieces)]
        ends = [p["steps"] for p in out["train"]]
        if any(a[1] != b[0] for a, b in itertools.pairwise(ends)):
            raise ValueError(f"training pieces' steps {ends} do not follow one another")
    return out


def _training_piece(piece: dict[str, Any], said: dict[str, Any], i: int) -> dict[str, Any]:
    """One piece of a training run in pieces: its own fields, then ``said`` where it is silent;
    ``steps`` [from, to] required."""
    unknown = sorted(set(piece) - set(TRAIN_CONDITIONS))
    if unknown:
        raise ValueError(f"training piece {i}: no field {', '.join(unknown)}; fields: "
                         f"{', '.join(TRAIN_CONDITIONS)}")
    steps = piece.get("steps")
    whole = isinstance(steps, list) and len(steps) == 2 and all(
        isinstance(n, int) and not isinstance(n, bool) for n in steps)
    if not (whole and 0 <= steps[0] < steps[1]):
        raise ValueError(f"training piece {i}: steps must be [from, to] with from < to, got "
                         f"{steps!r}")
    out = dict.fromkeys(TRAIN_CONDITIONS)
    out.update({k: v for k, v in said.items() if k in out and v is not None})
    out.update({k: v for k, v in piece.items() if v is not None})
    return out


def seed_records(cell: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """A cell's record per training seed (``{"0": ..., "1": ...}``): its ``seeds``, or the
    cell itself as seed 0 when it has one."""
    return cell.get("seeds") or {"0": cell}


def cell_record(row: dict[str, Any], task: str) -> dict[str, Any]:
    """``row`` (a cell of ``table.json``) as a results file keeps it. Reads the cell's
    evaluation records and checkpoint folder, so it runs where the table ran."""
    out = {k: row.get(k) for k in KEEP if k in row}
    if "seeds" in row:
        out["seeds"] = {seed: cell_record(r, task) for seed, r in row["seeds"].items()}
        return out
    rate = Rate.of(row)  # a row written before rates carried their counts has the rate alone
    out["successes"] = rate.successes
    out["success_ci95"] = ci95(rate.successes, rate.episodes)
    records = read_records(Path(row["evaluation"]) / task / "episodes.jsonl")
    # declared subtask ends against the simulator's: an M(1) task runs one subtask, the goal
    out["boundaries"] = boundary_counts(records) if get_task(task).tmc == "M(n)" else None
    out["failed_at"] = failures_by_stage(records)
    out["planner"] = planner_report(Path(row["checkpoint"]))
    if row.get("executor_from"):  # a planner-only ablation: its executor is this run's
        out["executor_of"] = Path(row["executor_from"]).name
    return out


def planner_report(checkpoint: Path) -> dict[str, Any] | None:
    """A Mem-0 checkpoint's planner fit (decisions, steps, training accuracy, final loss):
    its training's report, or a planner refit's in its config; None for a checkpoint
    without a planner of its own (M(1), another policy)."""
    planner = checkpoint / "training" / "planner.json"  # M(n) checkpoints only
    if planner.exists():
        return json.loads(planner.read_text())
    config = checkpoint / "config.json"
    if config.exists():  # a planner refit keeps its report there
        return (json.loads(config.read_text()).get("planner_refit") or {}).get("report")
    return None


def evaluation_rows(folder: Path, spec: str) -> dict[str, Any]:
    """An ``rmbench eval`` folder of one checkpoint as a table of one column, ``spec``: its
    command and, per task, a row as ``cell_row`` gives one. Its training wall is the
    checkpoint's; for a planner refit (``benchmarks/planner_refit.py``) the executor's
    training's, with where the refit came from. Its evaluation wall adds up the episodes' (the
    folder keeps no clock of its own: a one-worker run's wall), its machine is the one this
    runs on (record where the evaluation ran). Paths are read as the evaluation wrote them,
    so this runs where it ran."""
    run, summary = (json.loads((folder / f).read_text()) for f in ("run.json", "summary.json"))
    if (run.get("split", "test") != "test" or run.get("seeds_of") or run.get("seed", 0) != 0
            or run.get("episodes") != TABLE_EPISODES or run.get("instructions", "seen") != "seen"):
        raise ValueError(f"{folder}: evaluated on other episodes than the table's (split "
                         f"{run.get('split', 'test')!r}, seed {run.get('seed', 0)}, "
                         f"{run.get('episodes')} episodes, {run.get('instructions', 'seen')} "
                         f"instructions"
                         f"{', seeds of ' + run['seeds_of'] if run.get('seeds_of') else ''}): "
                         f"a table reports its task's {TABLE_EPISODES} test episodes, seen "
                         f"instructions")
    ckpt = Path(split_policy(run["policy"])[1])
    if not (ckpt / "config.json").is_file():
        raise ValueError(f"{folder}: evaluates {run['policy']!r}, not a checkpoint found here")
    config = json.loads((ckpt / "config.json").read_text())
    evaluated = _evaluated_spec(run["policy"], config)
    if evaluated != split_seed(spec)[0]:
        raise ValueError(f"{folder}: evaluates {evaluated} ({run['policy']}), not {spec}")
    refit = config.get("planner_refit")
    trained = Path(refit["from"]) if refit else ckpt
    timing = json.loads((trained / TIMING).read_text()) if (trained / TIMING).exists() else {}
    cells = {}
    for task, result in summary["tasks"].items():
        records = read_records(folder / task / "episodes.jsonl")
        clock = {"eval_wall_s": round(sum(r.get("wall_s", 0.0) for r in records), 1),
                 "machines": [describe()]}
        cells[task] = {spec: {
            **result_row(result, task, ckpt, folder, timing, clock),
            **({"planner_refit": {"from": str(refit["from"]), "set": refit["set"]}}
               if refit else {})}}
    tasks = " ".join(f"--task {t}" for t in cells)
    return {"command": f"rmbench eval {tasks} --policy {run['policy']} --episodes "
                       f"{run['episodes']} --seed {run['seed']} --out {folder}",
            "plan": None, "cells": cells}


def _evaluated_spec(policy: str, config: dict[str, Any]) -> str:
    """The table column an evaluated policy is: its name with the ablations its checkpoint
    was trained with and those its argument adds (``mem0:no_key``, ``mem0:gt_classifier``)."""
    name, _, arg = policy.partition(":")
    ablations = [*(config.get("config", {}).get("ablations") or ()), *argument_ablations(arg)]
    return name + (":" + "+".join(dict.fromkeys(ablations)) if ablations else "")


def measured_on(task: str, column: str, cell: dict[str, Any]) -> tuple:
    """What a cell was measured on: its dataset format (where the cell depends on it), task
    version and the recipe's items for its task alone (``task_items``). Cells of one such
    triple are one recipe's measurements; others do not replace, pool with or stand beside
    them in a difference."""
    fmt = cell.get("dataset") if reads_subtask_cut(task, column) else None
    return fmt, recorded_gym_id(task, cell), task_items(cell)


def task_items(cell: dict[str, Any]) -> tuple[str, ...]:
    """The recipe's items for the cell's task alone that it trained with (``task_sets`` in
    suite.recipes, those meant for its policy), as its record keeps them: none where the
    record names none (a cell recorded before they were kept, of a task that had none)."""
    if "task_items" in cell:
        return tuple(cell["task_items"])
    kept = {tuple(r.get("task_items", ())) for r in (cell.get("seeds") or {}).values()}
    return kept.pop() if len(kept) == 1 else ()


def reads_subtask_cut(task: str, column: str) -> bool:
    """Whether a cell depends on the dataset format (how a plan's steps are cut into
    subtasks): Mem-0's columns on an M(n) row. M(1) Mem-0 runs one subtask (the goal), and DP
    and ACT read no subtask, so the format changes nothing they learn."""
    return column.startswith("mem0") and get_task(task).tmc == "M(n)"
