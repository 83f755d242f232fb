"""A table's folders made on another version of a task: which version a folder was made on,
and moving those of another aside so that the table makes them again on this one."""

from __future__ import annotations

from pathlib import Path

from rmbench.files import read_json_or
from rmbench.suite.clock import TIMING
from rmbench.suite.plan import Plan
from rmbench.tasks import get_task
from rmbench.tasks.registry import recorded_gym_id


def made_on(folder: Path, task: str) -> str | None:
    """The task version (gym id) a table folder was made on: a dataset's (its
    ``meta/rmbench.json``), a checkpoint's (its ``config.json``) or an evaluation's (its
    ``<task>/version.json``); None for a folder that holds none of them yet."""
    folder = Path(folder)
    for path in (folder / "meta" / "rmbench.json", folder / "config.json"):
        record = read_json_or(path, None)
        if isinstance(record, dict) and record:
            return recorded_gym_id(task, record)
    record = read_json_or(folder / task / "version.json", None)
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
            pieces.append(plan.copies_record(out, task))
        for path in pieces:
            if not path.exists():
                continue
            dest, n = path.with_name(f"{path.name}~{tag}"), 1
            while dest.exists():
                dest, n = path.with_name(f"{path.name}~{tag}-{n}"), n + 1
            path.rename(dest)
            moved.append((path, dest))
    return moved
