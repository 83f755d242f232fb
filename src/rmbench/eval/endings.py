"""Where an evaluation's failed episodes end: the stage of the task's plan each one was in
(the task's last ``subtask`` event, its own words) and how it ended (``timeout``, or the
task's failure message), so a low success rate reads as "stuck putting the block back" or
"pressed too early" instead of a number alone."""

from __future__ import annotations

import re
from typing import Any

_PARTICULAR = re.compile(r" [\[(]")  # where a message's coordinates or names begin


def failure_kind(message: str) -> str:
    """A failure message without what is particular to its episode, cut before its first
    coordinates or parenthesis, so every episode (or expert) that failed so reads the same:
    "left arm cannot reach [0.1, -0.2, 0.9] (IK error 0.03 m)" -> "left arm cannot reach"."""
    return _PARTICULAR.split(message, maxsplit=1)[0]


def ending(record: dict[str, Any]) -> str:
    """How a failed episode ended, in words shared by every episode that ended so."""
    if record["reason"] != "task_failure" or not record.get("message"):
        return record["reason"]
    return failure_kind(record["message"])


def stage_at_end(record: dict[str, Any]) -> str:
    """The plan's stage the episode ended in: the task's last ``subtask`` event ('' where the
    record has none)."""
    stages = [e[3] for e in record.get("events", []) if e[1] == "task" and e[2] == "subtask"]
    return stages[-1] if stages else ""


def failures_by_stage(records: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    """{stage: {ending: episodes}} over the failed episodes, stages in the order the plan
    reaches them (first seen), endings most frequent first."""
    out: dict[str, dict[str, int]] = {}
    order: dict[str, int] = {}
    for r in records:
        for e in r.get("events", []):
            if e[1] == "task" and e[2] == "subtask":
                order.setdefault(e[3], len(order))
    for r in records:
        if r["success"]:
            continue
        row, how = out.setdefault(stage_at_end(r), {}), ending(r)
        row[how] = row.get(how, 0) + 1
    return {s: dict(sorted(out[s].items(), key=lambda kv: (-kv[1], kv[0])))
            for s in sorted(out, key=lambda s: order.get(s, len(order)))}
