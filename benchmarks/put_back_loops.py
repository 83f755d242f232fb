"""Put-back loops in an evaluation's records: how often a piece left its place and came back to
the same place, episode by episode, read from the predicates the task declares as places
(``Task.place_predicates``: the place's index, or -1 while the piece is in none; swap_blocks'
cube is in none while a finger touches it or it is off every tray; blocks_ranking_try's row is
its order, empty while a cube is held or off the slots). swap_blocks' and blocks_ranking_try's
cells mostly time out; this says whether they time out moving, or taking hold of a cube and
letting it go where it was, again and again, or stand still (no fact of the task changing in
the last quarter of the step limit). How long each put-back kept the piece out of place is set
beside how long each move did.

    .venv/bin/python benchmarks/put_back_loops.py --run LABEL=FOLDER [--run ...]
        [--loop 2] [--out benchmarks/results/put_back_loops.json]

FOLDER is an ``rmbench eval`` folder of one task (its records, ``TASK/episodes.jsonl``). An
episode loops where it holds at least ``--loop`` put-backs. A row per run, with Wilson 95%
intervals, is written atomically to the JSON (a task and label given again replace their row).
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from rmbench.eval.endings import ending, stage_at_end
from rmbench.eval.intervals import share
from rmbench.eval.records import read_records
from rmbench.eval.rows import put_row
from rmbench.tasks import get_task

OUT = Path(__file__).resolve().parent / "results" / "put_back_loops.json"
NONE = (-1, [])  # a place predicate's value while its piece (or a piece of its row) is in none


def in_place(value: Any) -> bool:
    return value not in NONE


def put_backs(record: dict[str, Any], places: tuple[str, ...]) -> tuple[Counter, list[int], list[int]]:
    """One episode's put-backs: {stage: count}, each time a piece's place predicate went from a
    place to none and then back to that same place (counted in the plan's stage it came back
    in); and the steps each put-back and each move (back in another place) was out of place."""
    last: dict[str, int] = {}
    left: dict[str, tuple[int, int]] = {}  # predicate -> (place it left, step it left)
    stage, out, back, moved = "", Counter(), [], []
    for step, source, key, value in record.get("events", []):
        if source != "task":
            continue
        if key == "subtask":
            stage = value
        if key not in places:
            continue
        before = last.get(key)
        if not in_place(value) and before is not None and in_place(before):
            left[key] = (before, step)
        elif in_place(value) and before is not None and not in_place(before) and key in left:
            place, since = left.pop(key)
            if place == value:
                out[stage] += 1
                back.append(step - since)
            else:
                moved.append(step - since)
        last[key] = value
    return out, back, moved


def still_at_end(record: dict[str, Any], limit: int) -> bool:
    """Whether no fact of the task changed in the episode's last quarter of ``limit`` steps:
    the robot stood still, or moved touching nothing that counts."""
    steps = [step for step, source, _, _ in record.get("events", []) if source == "task"]
    return record["steps"] - max(steps, default=0) >= limit / 4


def run_row(label: str, folder: Path, loop: int) -> dict:
    run = json.loads((folder / "run.json").read_text())
    (task,) = [p.name for p in folder.iterdir() if (p / "episodes.jsonl").exists()]
    records = read_records(folder / task / "episodes.jsonl")
    if not records:
        raise SystemExit(f"{folder}: no episode records")
    spec = get_task(task)
    places = spec.place_predicates
    if not places:
        raise SystemExit(f"{folder}: {task} declares no place predicates to read put-backs from")
    found = [(r, *put_backs(r, places)) for r in records]
    per = [(r, c) for r, c, _, _ in found]
    back = [n for _, _, b, _ in found for n in b]
    moved = [n for _, _, _, m in found for n in m]
    looped = [(r, c) for r, c in per if sum(c.values()) >= loop]
    endings = Counter("success" if r["success"] else ending(r) for r, _ in per)
    looped_endings = Counter("success" if r["success"] else ending(r) for r, _ in looped)
    failed_looping = [(r, c) for r, c in looped if not r["success"]]
    return {
        "label": label, "task": task, "policy": run["policy"], "seed": run["seed"],
        "split": run.get("split", "test"), "episodes": len(records), "places": list(places),
        "loop": loop, "endings": dict(endings.most_common()),
        "looped": share(len(looped), len(records)),
        "looped_by_ending": {k: share(looped_endings.get(k, 0), n) for k, n in endings.items()},
        # where the failed looping episodes ended, and where most of their put-backs were
        "failed_looping_ended_in": dict(Counter(stage_at_end(r) for r, _ in failed_looping)
                                        .most_common()),
        "failed_looping_mostly_in": dict(Counter(c.most_common(1)[0][0]
                                                 for _, c in failed_looping).most_common()),
        "put_backs_per_episode": [sum(c.values()) for _, c in per],
        # the other way to time out: nothing the task counts changes any more
        "timeouts_still": share(sum(still_at_end(r, spec.step_limit)
                                    for r, _ in per if ending(r) == "timeout"),
                                endings.get("timeout", 0)),
        # how long a piece was out of place: a put-back against a move to another place
        "put_back_steps_median": float(np.median(back)) if back else None,
        "put_backs_within_10_steps": share(sum(n <= 10 for n in back), len(back)),
        "move_steps_median": float(np.median(moved)) if moved else None,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--run", action="append", required=True, metavar="LABEL=FOLDER")
    p.add_argument("--loop", type=int, default=2)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    for item in args.run:
        label, sep, folder = item.rpartition("=")
        if not sep or not label:
            p.error(f"--run takes LABEL=FOLDER, got {item!r}")
        row = run_row(label, Path(folder), args.loop)
        put_row(args.out, row, key=("task", "label"))
        t = row["looped_by_ending"].get("timeout")
        print(f"{label}: {row['looped']['count']} of {row['episodes']} episodes loop"
              + (f"; {t['count']} of {t['of']} timeouts" if t else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
