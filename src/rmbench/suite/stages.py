"""A table cell's two stages after its task's data (``data_stage.py``), each resumable and
each a no-op once done: train the cell's checkpoint, evaluate it; and how far a stage has
come. Wall times accumulate in each folder's ``timing.json`` (``suite.clock``) with the
machines they ran on: an evaluation's minute by minute as it runs (a call killed midway keeps
its time up to the last minute); a training's is the one its saved state counts
(``training.state.Kept``), every piece up to its last save."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rmbench.eval import EvalConfig, evaluate
from rmbench.files import read_json_or, write_json
from rmbench.suite.clock import TIMING, timed
from rmbench.suite.data_stage import data_progress
from rmbench.suite.plan import Plan, executor_spec, parse_policy, split_seed, trained_spec
from rmbench.suite.versions import made_on
from rmbench.tasks import get_task
from rmbench.training.curve import CURVE_CSV
from rmbench.training.loop import TrainConfig
from rmbench.training.state import STATE


def trained(plan: Plan, out: Path, task: str, spec: str) -> bool:
    """Whether the cell's training is done: its checkpoint of the plan's steps, and the
    stage's clock, which ``train_stage`` writes last (a training stopped between its
    checkpoint and its state, or before its bookkeeping, is finished by running it again)."""
    folder = plan.train_dir(out, task, spec)
    return (read_json_or(folder / "config.json", {}).get("step") == plan.steps
            and (folder / TIMING).exists())


def evaluated(plan: Plan, out: Path, task: str, spec: str) -> dict | None:
    """The cell's evaluation result (the harness's per-task summary) once complete, on the
    task's current version, else None: a report (``--report-only`` moves nothing aside) never
    shows a cell of an earlier version as this version's."""
    folder = plan.eval_dir(out, task, spec)
    result = read_json_or(folder / "summary.json", {}).get("tasks", {}).get(task)
    if result is None or result["episodes"] < plan.episodes:
        return None
    return result if made_on(folder, task) in (None, get_task(task).gym_id) else None


def fraction(plan: Plan, out: Path, kind: str, task: str, spec: str = "") -> float:
    """How far a stage has come (0-1), read from what it has written so far (a collection's:
    its part under way, ``data_progress``)."""
    if kind == "collect":
        return data_progress(plan, out, task)[1]
    if kind == "train":
        curve = plan.train_dir(out, task, spec) / CURVE_CSV
        try:
            with open(curve, "rb") as f:
                f.seek(max(0, f.seek(0, 2) - 200))
                last = f.read().decode(errors="replace").strip().splitlines()[-1]
            return min(1.0, int(last.split(",")[0]) / plan.steps)
        except (OSError, ValueError, IndexError):
            return 0.0
    records = plan.eval_dir(out, task, spec) / task / "episodes.jsonl"
    try:
        return min(1.0, sum(1 for _ in open(records)) / plan.episodes)
    except OSError:
        return 0.0


def train_stage(plan: Plan, out: Path, task: str, spec: str, progress: bool = False) -> Path:
    """The cell's checkpoint (its trained spec's: ``mem0:gt_classifier`` trains ``mem0``),
    resumed from its last saved state; a finished one is left alone. A planner-only ablation
    (``mem0:no_key``) takes the finished executor of its ``executor_spec`` (``mem0``)."""
    from rmbench.policies.trainable import trainable

    folder = plan.train_dir(out, task, spec)
    if not trained(plan, out, task, spec):
        spec = trained_spec(spec)
        cfg = plan.config(task, spec)
        train_cfg = TrainConfig(steps=plan.steps, batch_size=plan.batch, seed=split_seed(spec)[1],
                                save_every=min(500, plan.steps), device=plan.device)
        _, fit = trainable(parse_policy(spec)[0])
        source = executor_spec(spec)
        # (a folder holding a full run's state, started before no_key took Mem-0's executor,
        # resumes as that run)
        extra = ({} if source is None or (folder / STATE).exists()
                 else {"executor_from": plan.train_dir(out, task, source)})
        result = fit(plan.train_data_dir(out, task), folder, cfg, train_cfg, progress=progress,
                     **extra)
        timing = {k: result[k] for k in ("train_wall_s", "train_wall_from_step", "machines",
                                         "executor_from") if k in result}
        write_json(folder / TIMING, timing)
    elif executor_spec(trained_spec(spec)) is not None:
        from rmbench.policies.mem0.train import check_executor_source

        check_executor_source(folder)
    return folder


def eval_stage(plan: Plan, out: Path, task: str, spec: str, workers: int = 1,
               progress: bool = False) -> dict[str, Any]:
    """The cell's evaluation on ``plan.episodes`` expert-verified seeds (only the missing ones
    run); the harness's per-task result."""
    result = evaluated(plan, out, task, spec)
    if result is None:
        folder = plan.eval_dir(out, task, spec)
        # counted as it runs: an evaluation killed and resumed keeps the time of every piece
        with timed(folder, "eval_wall_s"):
            summary = evaluate(EvalConfig((task,), plan.eval_policy(out, task, spec), folder,
                                          episodes=plan.episodes, workers=workers,
                                          video=plan.video, progress=progress, split=plan.split))
        result = summary["tasks"][task]
    return result
