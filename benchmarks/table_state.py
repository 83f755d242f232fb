"""Record cells of an ``rmbench table`` run in benchmarks/results/table_state.json, the state
table that every number the docs quote about the table comes from.

    python benchmarks/table_state.py --table runs/table_state \\
        --tasks press_button,cover_blocks --specs mem0,mem0:no_key,mem0:gt_classifier \\
        --dataset rmbench/2 --why "trained on format 1 datasets"

Each recorded cell replaces its task's and column's cell. A replaced cell trained on another
dataset format moves to ``superseded`` under ``--why``, so no measurement is dropped; one of
the same format is the same recipe measured before, or one of the seeds the new cell pools.
A recorded cell keeps the command that made it and the dataset format it trained on. The
file is written atomically.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rmbench.suite.records import cell_record
from rmbench.video import write_atomic

OUT = Path(__file__).resolve().parent / "results" / "table_state.json"


def record(doc: dict, run: dict, tasks: list[str], specs: list[str], dataset: str,
           why: str, table: str) -> dict:
    """``doc`` with ``run``'s cells of ``tasks`` x ``specs`` in place of its own."""
    replaced: dict[str, dict] = {}
    for task in tasks:
        for spec in specs:
            row = run["cells"].get(task, {}).get(spec)
            if row is None:
                raise SystemExit(f"{table}: {task} {spec} is not evaluated yet")
            old = doc["cells"].setdefault(task, {}).get(spec)
            # a cell of the same data is the same recipe measured before (or one of the
            # seeds the new cell pools): the new one stands for it
            if old is not None and old.get("dataset") != dataset:
                replaced.setdefault(task, {})[spec] = old
            doc["cells"][task][spec] = {**cell_record(row, task), "dataset": dataset,
                                        "command": run["command"]}
        doc["chance"][task] = run["chance"][task]
    if replaced:
        groups = [g for g in doc.get("superseded", []) if g["why"] != why]
        same = next((g for g in doc.get("superseded", []) if g["why"] == why), None)
        kept = same["cells"] if same else {}
        for task, cells in replaced.items():
            kept.setdefault(task, {}).update(cells)
        doc["superseded"] = groups + [{"why": why, "cells": kept}]
    return doc


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--table", required=True, help="an `rmbench table` folder (its table.json)")
    p.add_argument("--tasks", required=True)
    p.add_argument("--specs", required=True)
    p.add_argument("--dataset", required=True, help="the format the cells trained on (rmbench/N)")
    p.add_argument("--why", required=True, help="why the replaced cells no longer stand, in words")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    run = json.loads((Path(args.table) / "table.json").read_text())
    doc = record(json.loads(args.out.read_text()), run, args.tasks.split(","),
                 args.specs.split(","), args.dataset, args.why, args.table)
    write_atomic(args.out, (json.dumps(doc, indent=1) + "\n").encode())
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
