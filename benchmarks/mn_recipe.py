"""Record one Mem-0 recipe candidate's M(n) cells in benchmarks/results/mn_recipe.json.

Each candidate is a named change to the state table's recipe (its data, training or
inference), measured on the rows it touches with the table's own command; this file keeps
what was tried beside the table's reference cells, each cell with its Wilson interval, its
endings and, for cells whose policy declares subtask ends, where it declared them against
the simulator (``rmbench boundaries``).

    python benchmarks/mn_recipe.py --table runs/table_state --name NAME --changes "..." \\
        --tasks press_button --specs mem0,mem0:gt_classifier

A candidate that changes only what a checkpoint's policy does can instead be measured with
``rmbench eval`` on that checkpoint (``--evaluation DIR``: its folder, recorded as the one
column ``--specs`` names, beside the candidate's other columns).

A candidate recorded again keeps its other tasks and columns and takes the new cells in place
of the ones they replace; the file is written atomically.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rmbench.files import write_json
from rmbench.suite.records import cell_record, evaluation_rows
from rmbench.suite.tables import differences

OUT = Path(__file__).resolve().parent / "results" / "mn_recipe.json"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--table", help="an `rmbench table` folder (its table.json)")
    source.add_argument("--evaluation", help="an `rmbench eval` folder of a mem0 checkpoint")
    p.add_argument("--name", required=True)
    p.add_argument("--changes", required=True, help="what the candidate changes, in words")
    p.add_argument("--tasks", required=True)
    p.add_argument("--specs", default="mem0")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    if args.evaluation and "," in args.specs:
        raise SystemExit("--evaluation records one column: give one --specs")
    res = (json.loads((Path(args.table) / "table.json").read_text()) if args.table
           else evaluation_rows(Path(args.evaluation), args.specs))
    cells = {}
    for task in args.tasks.split(","):
        for spec in args.specs.split(","):
            row = res["cells"].get(task, {}).get(spec)
            if row is None:
                raise SystemExit(f"{args.table}: {task} {spec} is not evaluated yet")
            cells.setdefault(task, {})[spec] = cell_record(row, task)
    doc = json.loads(args.out.read_text()) if args.out.exists() else {"candidates": []}
    command = res.get("command", "")
    # the candidate's other tasks and columns stay: a re-run replaces only what it recorded
    old = next((c for c in doc["candidates"] if c["name"] == args.name), None)
    if old is not None:
        for task, row in old["cells"].items():
            cells[task] = {**row, **cells.get(task, {})}
        command = "; ".join(dict.fromkeys(old["command"].split("; ") + [command]))
    entry = {"name": args.name, "changes": args.changes, "command": command,
             "plan": res.get("plan") or (old or {}).get("plan"), "cells": cells,
             # Mem-0 minus each other column, with Newcombe's 95% interval
             "differences": differences(cells)}
    doc["candidates"] = [c for c in doc["candidates"] if c["name"] != args.name] + [entry]
    write_json(args.out, doc)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
