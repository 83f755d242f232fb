"""Where a policy declared its subtask ends against where the simulator counted them.

An M(n) policy that decomposes a task (Mem-0) says when each subtask is over; the simulator
counts the plan's steps as they are done. Both are in an evaluation's records
(``eval/events.py``): the task's ``subtask_step`` and the policy's ``subtask_ends`` (the number
of ends it has declared). The i-th declared end is matched with the i-th step the simulator
counted, and the pair classified:

- ``on_time``: declared at the step's last frame or up to ``LATE`` steps after it;
- ``early``: declared before the simulator counted the step (the next subtask starts on an
  unfinished one);
- ``late``: more than ``LATE`` steps after (the executor keeps working on a finished step);
- ``missed``: a step the simulator counted with no end declared by the episode's end (not
  the step whose count ended the episode: no policy acts after it);
- ``false``: an end declared beyond every step the simulator counted.

A step's last frame is the one whose action the simulator counted it after; the
demonstrations' end flags sit on that frame, and a classifier trained on them declares the
end while acting on it.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from rmbench.eval.events import capped

# steps (0.6 s): Mem-0's event classifier learns the 12 frames after each end and declares
# one after 8 of them in a row, so an end it detects on time is declared 8-12 frames after
LATE = 12
VERDICTS = ("on_time", "early", "late", "missed", "false")


def end_steps(events: list[list]) -> tuple[list[int], list[int]]:
    """(the frames the simulator counted a step after, the frames the policy declared an end
    on), both from one episode's events."""
    counted, declared = [], []
    last_step, last_ends = 0, 0
    for step, source, key, value in events:
        if step is None:
            continue
        if source == "task" and key == "subtask_step":
            # the event is seen after env step ``step``: the action of frame step - 1 did it
            counted += [step - 1] * max(0, int(value) - last_step)
            last_step = max(last_step, int(value))
        elif source == "policy" and key == "subtask_ends":
            # seen when the policy acted on frame ``step``
            declared += [step] * max(0, int(value) - last_ends)
            last_ends = max(last_ends, int(value))
    return counted, declared


def classify(counted: list[int], declared: list[int],
             last_frame: int | None = None) -> list[dict[str, Any]]:
    """One entry per plan step or declared end: its index, the two frames, the verdict. A
    step counted on ``last_frame`` (the episode's) with no declared end is left out."""
    out = []
    for i in range(max(len(counted), len(declared))):
        s = counted[i] if i < len(counted) else None
        d = declared[i] if i < len(declared) else None
        if d is None and s is not None and s == last_frame:
            continue
        if d is None:
            verdict = "missed"
        elif s is None:
            verdict = "false"
        elif d < s:
            verdict = "early"
        elif d - s > LATE:
            verdict = "late"
        else:
            verdict = "on_time"
        out.append({"step": i, "counted": s, "declared": d, "verdict": verdict,
                    "delay": None if s is None or d is None else d - s})
    return out


def boundary_counts(records: list[dict]) -> dict[str, Any] | None:
    """Counts of each verdict over an evaluation's records, the median delay of matched ends,
    and the episodes' first wrong verdict; None when no record has a policy's declared ends.
    An episode whose events passed ``events.LIMIT`` is left out (the ends between the limit
    and its last changes are not kept), counted in ``capped``."""
    if not any(e[1] == "policy" and e[2] == "subtask_ends" for r in records
               for e in r.get("events", [])):
        return None
    whole = [r for r in records if not capped(r)]
    left_out, records = len(records) - len(whole), whole
    counts: Counter = Counter()
    first_wrong: Counter = Counter()
    delays = []
    for r in records:
        last = r["steps"] - 1 if r.get("steps") else None
        entries = classify(*end_steps(r.get("events", [])), last_frame=last)
        counts.update(e["verdict"] for e in entries)
        delays += [e["delay"] for e in entries if e["delay"] is not None]
        wrong = next((e for e in entries if e["verdict"] != "on_time"), None)
        if wrong is not None:
            first_wrong[wrong["verdict"]] += 1
    return {"episodes": len(records), **{v: counts[v] for v in VERDICTS},
            "median_delay": float(np.median(delays)) if delays else None,
            "first_wrong": {v: first_wrong[v] for v in VERDICTS if first_wrong[v]},
            **({"capped": left_out} if left_out else {})}
