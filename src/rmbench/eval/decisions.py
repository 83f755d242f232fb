"""The subtask a policy chose at each end it declared, against the one the task's plan has
next: where an M(n) policy's memory is read (Mem-0's planner decides only then).

Only the ends declared on time or late (``eval/boundaries.py``) are judged: there the step
was done when the policy chose, so a wrong choice is the planner's. An end declared early
makes its choice on an unfinished step, which is the end classifier's error, counted there.
The choice is the policy's ``subtask`` as of the frame it declared the end on; the plan's
next subtask is the task's ``subtask`` once it counted the step.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from typing import Any

from rmbench.eval.boundaries import classify, end_steps

JUDGED = ("on_time", "late")


def _value_at(events: list[list], source: str, frame: int) -> Any:
    """``source``'s last ``subtask`` value in events seen at or before ``frame``."""
    value = None
    for step, src, key, v in events:
        if step is not None and step > frame:
            break
        if src == source and key == "subtask":
            value = v
    return value


def choices(record: dict[str, Any]) -> list[tuple[str, str]]:
    """One episode's judged choices, (the plan's next subtask, the policy's choice), in order."""
    events = sorted(record.get("events", []), key=lambda e: -1 if e[0] is None else e[0])
    last = record["steps"] - 1 if record.get("steps") else None
    out = []
    for entry in classify(*end_steps(events), last_frame=last):
        if entry["verdict"] not in JUDGED:
            continue
        # the task's subtask event comes after the env step that counted the step
        wanted = _value_at(events, "task", entry["counted"] + 1)
        chosen = _value_at(events, "policy", entry["declared"])
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
        if any(e[1:3] == ["events", "left_out"] for e in r.get("events", [])):
            continue  # its events passed the limit: the ends after it are not kept
        for wanted, chosen in choices(r):
            by[wanted][chosen] += 1
    judged = sum(sum(c.values()) for c in by.values())
    right = sum(c[w] for w, c in by.items())
    return {"judged": judged, "right": right,
            "by_next": {w: {"right": c[w], "of": sum(c.values()),
                            "chose_instead": {k: n for k, n in c.most_common() if k != w}}
                        for w, c in sorted(by.items())}}
