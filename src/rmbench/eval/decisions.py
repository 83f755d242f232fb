"""The subtask a policy chose at each end it declared, against the one the task's plan has
next: where an M(n) policy's memory is read (Mem-0's planner decides only then).

Only the ends declared on time or late (``eval/boundaries.py``) are judged: there the step
was done when the policy chose, so a wrong choice is the planner's. An end declared early
makes its choice on an unfinished step, which is the end classifier's error, counted there.
The choice is the policy's ``subtask`` as of the frame it declared the end on; the plan's
next subtask is the task's ``subtask`` once it counted the step.
"""

from __future__ import annotations

from bisect import bisect_right
from collections import Counter, defaultdict
from typing import Any

from rmbench.eval.boundaries import classify, end_steps
from rmbench.eval.events import capped

JUDGED = ("on_time", "late")


def _subtask_timeline(events: list[list], source: str) -> tuple[list[int], list[Any]]:
    """``source``'s ``subtask`` changes, (the steps they were seen at, the values), in the
    order the record keeps them (step order)."""
    changes = [(step, value) for step, src, key, value in events
               if step is not None and src == source and key == "subtask"]
    return [s for s, _ in changes], [v for _, v in changes]


def _value_at(timeline: tuple[list[int], list[Any]], frame: int) -> Any:
    """The subtask in force once the events seen at ``frame`` are in (None before any)."""
    steps, values = timeline
    i = bisect_right(steps, frame)
    return values[i - 1] if i else None


def choices(record: dict[str, Any]) -> list[tuple[str, str]]:
    """One episode's judged choices, (the plan's next subtask, the policy's choice), in order."""
    events = record.get("events", [])
    task, policy = _subtask_timeline(events, "task"), _subtask_timeline(events, "policy")
    last = record["steps"] - 1 if record.get("steps") else None
    out = []
    for entry in classify(*end_steps(events), last_frame=last):
        if entry["verdict"] not in JUDGED:
            continue
        # the task's subtask event comes after the env step that counted the step
        wanted = _value_at(task, entry["counted"] + 1)
        chosen = _value_at(policy, entry["declared"])
        if wanted is not None and chosen is not None:
            out.append((wanted, chosen))
    return out


def decision_counts(records: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Over an evaluation's records: the judged choices, how many were right, and per next
    subtask of the plan how often it was chosen and what was chosen instead; None where no
    record holds a policy's subtask (a policy that reports none). An episode whose events
    passed ``events.LIMIT`` is left out, as ``boundary_counts`` leaves it."""
    if not any(e[1] == "policy" and e[2] == "subtask" for r in records
               for e in r.get("events", [])):
        return None
    by: dict[str, Counter] = defaultdict(Counter)
    for r in records:
        if capped(r):
            continue  # its events passed the limit: the ends after it are not kept
        for wanted, chosen in choices(r):
            by[wanted][chosen] += 1
    judged = sum(sum(c.values()) for c in by.values())
    right = sum(c[w] for w, c in by.items())
    return {"judged": judged, "right": right,
            "by_next": {w: {"right": c[w], "of": sum(c.values()),
                            "chose_instead": {k: n for k, n in c.most_common() if k != w}}
                        for w, c in sorted(by.items())}}
