"""A table's data stage for one task, resumable and a no-op once done: the task's
demonstrations, with ``rendered_copies`` their rendered layout copies, and the frozen
backbones' features (so that the training jobs beside each other only read them); how far it
has come, for the progress display; and the check that data already in a table's folder is
the plan's. Its walls accumulate minute by minute in the task's ``timing.json``
(``suite.clock``): a call killed midway keeps its time up to the last minute."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rmbench.data import CollectConfig, collect
from rmbench.data.layout_shift import COPIES_SEED, layout_copies_cached, solve_layout_copies
from rmbench.data.reader import Dataset
from rmbench.envs.noise import NoiseSpec
from rmbench.files import read_json_or, write_json
from rmbench.identity import differences
from rmbench.suite.clock import DATA_WALLS, TIMING, timed
from rmbench.suite.plan import COLLECT_CAMERAS, Plan, trained_spec
from rmbench.suite.versions import made_on
from rmbench.tasks import get_task


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
        elif ds.num_episodes < plan.demos and any((out / task / "train").glob("*/config.json")):
            # a collection resumed to more would leave those cells, named alike, on fewer
            what = ", ".join(x for x in (what, f"{ds.num_episodes} demonstrations there and "
                                               f"cells trained on them, {plan.demos} asked") if x)
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


def copies_done(plan: Plan, out: Path, task: str) -> dict | None:
    """The rendered copies' summary once they are all written (of the plan's demonstrations),
    else None."""
    summary = read_json_or(plan.copies_record(out, task), None)
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

    made = read_json_or(plan.data_dir(out, task) / "meta" / "info.json", {})
    demos = min(1.0, made.get("total_episodes", 0) / plan.demos)
    if demos < 1:
        return "demos", demos
    data = plan.train_data_dir(out, task)
    episodes = read_json_or(data / "meta" / "info.json", {}).get("total_episodes", 0)
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
        write_json(plan.copies_record(out, task), summary.to_dict())
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
    ds, timing = Dataset(root), read_json_or(root.parent / TIMING, {})
    return {"path": str(root), "episodes": ds.num_episodes, "frames": ds.num_frames,
            "cameras": list(ds.cameras), "resolution": f"{asked.width}x{asked.height}",
            "environment_state": ds.state_names is not None,
            "noise": NoiseSpec(plan.noise_kind, plan.noise).to_dict() if plan.noise else None,
            "rendered_copies": copies_done(plan, out, task),
            **{k: timing.get(k) for k in DATA_WALLS}}
