"""What an evaluation folder holds is one evaluation: its ``run.json`` (the arguments it was
made with) and each task folder's ``version.json`` (the task version its episodes ran on). A
folder of other arguments or another version is refused, never resumed into."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rmbench.eval.records import EvalError, read_records
from rmbench.files import read_json_object, write_json
from rmbench.identity import differences
from rmbench.tasks import get_task
from rmbench.tasks.registry import recorded_gym_id


def check_identity(out: Path, asked: dict[str, Any]) -> None:
    """``out`` holds the evaluation whose arguments are ``asked`` (``EvalConfig.identity``,
    kept as its ``run.json``), or none yet: a folder whose run.json says other arguments is
    refused while any episode is recorded under it, and taken over when none is (a run that
    stopped before its first episode, on a bad checkpoint say)."""
    path = out / "run.json"
    if not path.exists() and any((out / f).exists() for f in ("summary.json", "summary.md")):
        raise EvalError(f"{out} holds a summary but no run.json: not an rmbench evaluation "
                        f"folder, whose files this one would overwrite; use another --out")
    if path.exists():
        saved = read_json_object(path)
        what = differences({**saved, "policy": placed(saved.get("policy"))},
                           {**asked, "policy": placed(asked["policy"])})
        if not what:
            return
        if any(p.stat().st_size for p in out.glob("*/*.jsonl")):
            raise EvalError(f"{out} holds an evaluation with other arguments ({what}); use "
                            f"another --out")
    write_json(path, asked, indent=2)


def placed(policy: Any) -> Any:
    """A policy spec with the checkpoint folder it names resolved (``NAME:FOLDER[?QUERY]``,
    where the folder exists): one checkpoint spelled from here as a relative path, an
    absolute one or through a link is one policy, so that its evaluation resumes."""
    if not isinstance(policy, str):
        return policy
    name, colon, arg = policy.partition(":")
    folder, mark, query = arg.partition("?")
    if not (colon and folder) or not Path(folder).is_dir():
        return policy
    return f"{name}:{Path(folder).resolve()}{mark}{query}"


def check_version(folder: Path, task: str) -> None:
    """A task folder holds episodes of one task version: a folder written on another (its
    ``version.json``, or for episodes recorded before versions were kept, the version of that
    time) is refused, never resumed."""
    path, gym_id = folder / "version.json", get_task(task).gym_id
    if path.exists():
        try:
            saved = json.loads(path.read_text()).get("gym_id")
        except (OSError, json.JSONDecodeError, AttributeError) as err:
            raise EvalError(f"{path} is unreadable ({err}); use another --out") from None
    elif read_records(folder / "episodes.jsonl"):
        saved = recorded_gym_id(task, {})
    else:
        saved = gym_id
    if saved != gym_id:
        raise EvalError(f"{folder} holds episodes of {saved}, this rmbench's {task} is "
                        f"{gym_id} (CHANGELOG.md); use another --out")
    if not path.exists():
        write_json(path, {"gym_id": gym_id}, indent=None)
