"""A table cell's three stages, each resumable and each a no-op once done: collect the task's
training data (its demonstrations; with ``rendered_copies`` their rendered layout copies; the
frozen backbones' features, so that the training jobs beside each other only read them), train
the cell's checkpoint, evaluate it. Wall times accumulate in each folder's ``timing.json``
(``suite.clock``) with the machines they ran on: a data stage's and an evaluation's minute by
minute as it runs (a call killed midway keeps its time up to the last minute); a training's is
the one its saved state counts (``training.state.Kept``), every piece up to its last save."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from rmbench.data import CollectConfig, collect
from rmbench.data.layout_shift import COPIES_SEED, layout_copies_cached, solve_layout_copies
from rmbench.data.reader import Dataset
from rmbench.envs.noise import NoiseSpec
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.harness import read_records
from rmbench.eval.intervals import wilson
from rmbench.files import write_json
from rmbench.identity import differences
from rmbench.suite.clock import DATA_WALLS, TIMING, read_json, timed
from rmbench.suite.plan import (
    COLLECT_CAMERAS,
    Plan,
    executor_spec,
    memory_of,
    parse_policy,
    split_seed,
    trained_spec,
)
from rmbench.tasks import get_task
from rmbench.tasks.registry import recorded_gym_id
from rmbench.training.curve import CURVE_CSV
from rmbench.training.loop import TrainConfig
from rmbench.training.state import STATE


# ------------------------------------------------------------------------------ done yet?
def collect_config(plan: Plan, out: Path, task: str, workers: int = 1,
                   progress: bool = False) -> CollectConfig:
    """The collection of ``task``'s demonstrations the plan asks for."""
    cameras, (width, height) = COLLECT_CAMERAS[plan.obs]
    return CollectConfig(task, plan.data_dir(out, task), episodes=plan.demos, seed=0,
                         cameras=cameras, width=width, height=height, workers=workers,
                         noise=NoiseSpec(plan.noise_kind, plan.noise), progress=progress)


def check_data(plan: Plan, out: Path) -> None:
    """Each task's demonstrations already in ``out`` are the plan's: collected with its
    cameras, resolution and action noise, and no more of them than it asks, since its
    policies train on every episode the folder holds. A table's folders are named by its
    training recipe alone, so a table asking other data of the same ``OUT`` would otherwise
    train on, or report, the other table's. ValueError in one line where they are not."""
    for task in plan.tasks:
        root = plan.data_dir(out, task)
        # (a dataset of another task version is not this table's either way: a run moves it
        # aside, a report shows none of its cells)
        if not (root / "meta" / "info.json").exists() or made_on(root, task) != get_task(task).gym_id:
            continue
        ds = Dataset(root)
        what = differences(ds.rmbench.get("collection") or {},
                           collect_config(plan, out, task).identity())
        if ds.num_episodes > plan.demos:
            what = ", ".join(x for x in (what, f"{ds.num_episodes} demonstrations there, "
                                               f"{plan.demos} asked") if x)
        if what:
            raise ValueError(f"{root} holds demonstrations of another table ({what}); "
                             f"use another --out")


def demos_collected(plan: Plan, out: Path, task: str) -> bool:
    root = plan.data_dir(out, task)
    return (root / "meta" / "info.json").exists() and Dataset(root).num_episodes >= plan.demos


def collected(plan: Plan, out: Path, task: str) -> bool:
    """Whether the task's training data is complete: demonstrations, rendered copies, features,
    and the state's layout copies solved."""
    if not demos_collected(plan, out, task):
        return False
    if plan.rendered_copies and copies_done(plan, out, task) is None:
        return False
    if any(cache.missing(*wanted) for cache, wanted in feature_caches(plan, out, task)):
        return False
    data = plan.train_data_dir(out, task)
    return all(layout_copies_cached(data, n, reach, COPIES_SEED)
               for n, reach in layout_copy_sets(plan, task))


def layout_copy_sets(plan: Plan, task: str) -> list[tuple[int, float]]:
    """The (copies, reach) of each set of layout copies the plan's policies train with on
    ``task`` (``--set layout_copies``): solved once per dataset, by its collection."""
    sets = set()
    for spec in {trained_spec(s) for s in plan.policies}:
        c = plan.config(task, spec)
        if c.layout_copies and c.layout_shift:
            sets.add((c.layout_copies, c.layout_shift))
    return sorted(sets)


def copies_record(plan: Plan, out: Path, task: str) -> Path:
    """Where a finished rendering of the copies leaves its summary (beside their dataset)."""
    data = plan.train_data_dir(out, task)
    return data.with_name(data.name + ".json")


def copies_done(plan: Plan, out: Path, task: str) -> dict | None:
    """The rendered copies' summary once they are all written (of the plan's demonstrations),
    else None."""
    summary = read_json(copies_record(plan, out, task), None)
    return summary if summary and summary.get("source_episodes") == plan.demos else None


def feature_caches(plan: Plan, out: Path, task: str) -> list[tuple[Any, tuple[list, list]]]:
    """Each frozen-backbone feature cache the plan's policies train from, with the (episodes,
    cameras) they read: one per (backbone, stride, image size), shared by the policies."""
    from rmbench.policies.feature_cache import FeatureCache

    root = plan.train_data_dir(out, task)
    cameras: dict[tuple, set[str]] = {}  # (backbone, stride, image size) -> cameras read
    for spec in {trained_spec(s) for s in plan.policies}:
        c = plan.config(task, spec)
        if c.reads_features:
            cameras.setdefault((c.backbone, c.backbone_stride, tuple(c.image_size)),
                               set()).update(c.cameras)
    if not cameras or not (root / "meta" / "info.json").exists():
        return []
    ds = Dataset(root)
    return [(FeatureCache(ds, *key), (list(range(ds.num_episodes)), sorted(cams)))
            for key, cams in cameras.items()]


def data_progress(plan: Plan, out: Path, task: str) -> tuple[str, float]:
    """The part of the task's data under way (``demos``, rendered ``copies``, ``features``)
    and how far it has come (0-1), read from what it has written so far: cheap enough for a
    progress display, which asks it every poll."""
    from rmbench.policies.feature_cache import cached_episodes, default_dir

    made = read_json(plan.data_dir(out, task) / "meta" / "info.json", {})
    demos = min(1.0, made.get("total_episodes", 0) / plan.demos)
    if demos < 1:
        return "demos", demos
    data = plan.train_data_dir(out, task)
    episodes = read_json(data / "meta" / "info.json", {}).get("total_episodes", 0)
    if plan.rendered_copies and copies_done(plan, out, task) is None:
        # (a copy out of the arms' reach is left out: this part may end short of 100%)
        return "copies", min(1.0, episodes / (plan.demos * (plan.rendered_copies + 1)))
    wanted = done = 0
    for spec in {trained_spec(s) for s in plan.policies}:
        c = plan.config(task, spec)
        if c.reads_features:
            folder = default_dir(data, c.backbone, c.backbone_stride, tuple(c.image_size))
            wanted += episodes * len(c.cameras)
            done += sum(min(episodes, cached_episodes(folder / cam)) for cam in c.cameras)
    return ("features", done / wanted) if wanted and done < wanted else ("data", demos)


def trained(plan: Plan, out: Path, task: str, spec: str) -> bool:
    """Whether the cell's training is done: its checkpoint of the plan's steps, and the
    stage's clock, which ``train_stage`` writes last (a training stopped between its
    checkpoint and its state, or before its bookkeeping, is finished by running it again)."""
    folder = plan.train_dir(out, task, spec)
    return (read_json(folder / "config.json", {}).get("step") == plan.steps
            and (folder / TIMING).exists())


def evaluated(plan: Plan, out: Path, task: str, spec: str) -> dict | None:
    """The cell's evaluation result (the harness's per-task summary) once complete, on the
    task's current version, else None: a report (``--report-only`` moves nothing aside) never
    shows a cell of an earlier version as this version's."""
    folder = plan.eval_dir(out, task, spec)
    result = read_json(folder / "summary.json", {}).get("tasks", {}).get(task)
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


# ------------------------------------------------------------------ another task version
def made_on(folder: Path, task: str) -> str | None:
    """The task version (gym id) a table folder was made on: a dataset's (its
    ``meta/rmbench.json``), a checkpoint's (its ``config.json``) or an evaluation's (its
    ``<task>/version.json``); None for a folder that holds none of them yet."""
    folder = Path(folder)
    for path in (folder / "meta" / "rmbench.json", folder / "config.json"):
        record = read_json(path, None)
        if isinstance(record, dict) and record:
            return recorded_gym_id(task, record)
    record = read_json(folder / task / "version.json", None)
    if isinstance(record, dict) and record.get("gym_id"):
        return record["gym_id"]
    if (folder / task / "episodes.jsonl").exists():  # (episodes from before versions were kept)
        return recorded_gym_id(task, {})
    return None


def retire_other_versions(plan: Plan, out: Path, task: str) -> list[tuple[Path, Path]]:
    """Move aside every folder of ``task``'s cells made on another version of the task (its
    data, rendered copies, checkpoints, evaluations; and the data's clock, ``timing.json``),
    each to ``<name>~<its version>`` beside it, so that the table makes them again on this
    version and nothing measured on the other is lost or mixed in. The (old, new) paths."""
    current = get_task(task).gym_id
    folders = {plan.data_dir(out, task), plan.train_data_dir(out, task)}
    for t, spec in plan.cells():
        if t == task:
            folders |= {plan.train_dir(out, task, spec), plan.eval_dir(out, task, spec)}
    moved = []
    for folder in sorted(folders):
        version = made_on(folder, task)
        if version is None or version == current:
            continue
        tag = version.rsplit("/", 1)[-1]
        pieces = [folder]
        if folder == plan.data_dir(out, task):
            pieces.append(folder.parent / TIMING)  # the data's walls: of that version's data
        if folder == plan.train_data_dir(out, task) and plan.rendered_copies:
            pieces.append(copies_record(plan, out, task))
        for path in pieces:
            if not path.exists():
                continue
            dest, n = path.with_name(f"{path.name}~{tag}"), 1
            while dest.exists():
                dest, n = path.with_name(f"{path.name}~{tag}-{n}"), n + 1
            path.rename(dest)
            moved.append((path, dest))
    return moved


# ------------------------------------------------------------------------------- stages
def collect_stage(plan: Plan, out: Path, task: str, workers: int = 1,
                  progress: bool = False) -> dict[str, Any]:
    """The task's training data, each part continued where a previous call stopped: its
    demonstrations, their rendered copies, the frozen backbones' features; their summary."""
    from rmbench.data.layout_copies import copy_layouts

    root, asked = plan.data_dir(out, task), collect_config(plan, out, task, workers, progress)
    if not demos_collected(plan, out, task):
        with timed(root.parent, "collect_wall_s"):
            collect(asked)
    if plan.rendered_copies and copies_done(plan, out, task) is None:
        with timed(root.parent, "copies_wall_s"):
            summary = copy_layouts(root, plan.train_data_dir(out, task), plan.rendered_copies,
                                   plan.rendered_reach, seed=0, episodes=plan.demos,
                                   workers=workers, progress=progress)
        write_json(copies_record(plan, out, task), summary.to_dict())
    for cache, wanted in feature_caches(plan, out, task):
        todo = cache.missing(*wanted)  # (reads every file's header: once)
        if todo:
            with timed(root.parent, "features_wall_s"):
                cache.encode(todo, workers)
    data = plan.train_data_dir(out, task)
    for n, reach in layout_copy_sets(plan, task):
        if not layout_copies_cached(data, n, reach, COPIES_SEED):
            with timed(root.parent, "layout_copies_wall_s"):
                solve_layout_copies(data, n, reach, COPIES_SEED, workers)
    ds, timing = Dataset(root), read_json(root.parent / TIMING, {})
    return {"path": str(root), "episodes": ds.num_episodes, "frames": ds.num_frames,
            "cameras": list(ds.cameras), "resolution": f"{asked.width}x{asked.height}",
            "environment_state": ds.state_names is not None,
            "noise": NoiseSpec(plan.noise_kind, plan.noise).to_dict() if plan.noise else None,
            "rendered_copies": copies_done(plan, out, task),
            **{k: timing.get(k) for k in DATA_WALLS}}


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


# -------------------------------------------------------------------------------- results
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
    return {**result_row(result, task, ckpt, evals, read_json(ckpt / TIMING, {}),
                         read_json(evals / TIMING, {})),
            "memory": memory_of(spec, get_task(task).tmc, cfg)}


def result_row(result: dict[str, Any], task: str, ckpt: Path, evals: Path,
               train_timing: dict[str, Any], eval_timing: dict[str, Any]) -> dict[str, Any]:
    """A cell's row from its task's evaluation summary (``result``), its checkpoint and
    evaluation folders and their clocks (``timing.json``'s fields)."""
    n = result["episodes"]
    k = result.get("successes", round(result["success_rate"] * n))  # (older summaries)
    return {"success_rate": result["success_rate"], "successes": k,
            "success_ci95": [round(v, 4) for v in wilson(k, n)] if n else None,
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
            "success_ci95": [round(v, 4) for v in wilson(k, n)],
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
