"""Record cells of an ``rmbench table`` run in benchmarks/results/table_state.json (the state
table) or, with ``--obs pixels``, table_pixels.json (the camera table): the files every number
the docs quote about the tables comes from.

    python benchmarks/table_state.py --table runs/table_state \\
        --tasks press_button,cover_blocks --specs mem0,mem0:no_key,mem0:gt_classifier \\
        --dataset rmbench/2 --why "trained on format 1 datasets"
    python benchmarks/table_state.py --evaluation EVAL --tasks press_button --specs mem0 \\
        --dataset rmbench/2 --why "..."

``--evaluation`` records an ``rmbench eval`` folder of one checkpoint as one column (a
checkpoint made outside the table, such as a planner refit, which records where it came
from). Each recorded cell replaces its task's and column's cell. A replaced cell trained on
another dataset format or run on another task version moves to ``superseded`` under
``--why``, so no measurement is dropped; otherwise it was the same recipe measured before, or
one of the seeds the new cell pools. ``--recipe-changed`` says the new cells were made with
another recipe: the cells they replace move to ``superseded`` under ``--why`` even on the same
data and task version.

``--seed N`` records the source's cells as training seed N of the cells already recorded
(a recorded cell of one seed is seed 0), and the recorded cell becomes the pool of its seeds
(``suite.cell_rows.pooled_row``): so a seed evaluated in one folder joins one evaluated in
another (a planner refit's seed 0, a table's seed 1). Recording seed N again replaces it. A
pooled cell is replaced only seed by seed, never by a cell of one seed.

    python benchmarks/table_state.py --table runs/table_state --tasks press_button \\
        --specs mem0 --seed 1 --dataset rmbench/2

``--withdraw`` moves recorded cells run on an earlier version of their task to
``superseded`` under ``--why`` and leaves them empty, where re-running them is still to do;
a cell of the current version is refused.

    python benchmarks/table_state.py --withdraw --tasks cover_blocks --specs act \\
        --why "run on cover_blocks-v1; not re-run on the current version yet"

``--rerun`` records the source's cells as the recorded seed (``--seed``, else 0) trained
again, on another machine or software: kept under ``reruns`` beside the cell, neither
replacing nor pooling into it. Training is bit for bit on one machine, not across CPUs
(torch's float kernels for AVX-512 and AVX2 round differently), so a re-run elsewhere
measures how far the machine alone moves a cell. Recording one again (the same task, column, seed and command)
replaces it.

    python benchmarks/table_state.py --table runs/rerun --tasks cover_blocks --specs mem0 \
        --rerun --dataset rmbench/2 --machine cpu --threads 1 --workers 1

The camera table's file is made by its first record: the table's command, the run's plan
and chance levels, and no cells yet.

A recorded cell keeps the command that made it, the dataset format it trained on and its
walls' ``conditions`` (``suite/records.py``): what ``--machine``, ``--jobs-beside``,
``--beside``, ``--threads``, ``--workers`` and ``--note`` say (``--train-note``,
``--train-beside``, ``--eval-note`` and ``--eval-beside`` for one stage's wall alone), every
other field null; a training run in pieces on several machines (a GPU, then a
CPU) states each with ``--train-piece``, one cell at a time. The file is written atomically.

    python benchmarks/table_state.py --table runs/table_state --tasks battery_try \
        --specs mem0 --seed 1 --dataset rmbench/2 --machine cpu --threads 1 --workers 1 \
        --jobs-beside 1 --beside "another state-table training"
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

from rmbench.eval.chance import chance
from rmbench.files import write_json
from rmbench.suite.cell_rows import pooled_row
from rmbench.suite.plan import meant_for, parse_policy, split_seed, with_seed
from rmbench.suite.records import (
    cell_record,
    evaluation_rows,
    measured_on,
    seed_records,
    stated_conditions,
)
from rmbench.tasks.registry import get_task, on_current_version, recorded_gym_id

RESULTS = Path(__file__).resolve().parent / "results"
OUT = RESULTS / "table_state.json"
# the camera table's command, what its results page opens with
PIXELS_COMMAND = "rmbench table --obs pixels --tasks all --out runs/table_pixels --jobs 2"


def new_table(run: dict) -> dict:
    """A results file with no cells, for the table ``run`` (a table.json) belongs to."""
    return {"command": PIXELS_COMMAND, "plan": run.get("plan"), "cells": {}, "chance": {},
            "machines": {"cpu": {"label": "CPU", "cpu": "x86_64", "cores": 2, "gpu": None,
                                 "about": None}},
            "wall_defaults": {"jobs": 2, "train": {"machine": "cpu", "threads": 1,
                                                   "jobs_beside": 1},
                              "eval": {"machine": "cpu", "workers": 1}},
            "superseded": [],
            "source": "recorded from the cells' table.json by benchmarks/table_state.py"}


def _said(conditions: dict | None) -> tuple[dict, dict]:
    """The conditions stated for every stage, and what one stage's wall alone needs said
    (``train_note``, ``train_beside``, ``eval_note``, ``eval_beside``)."""
    said = dict(conditions or {})
    stages = {stage: {"note": said.pop(f"{stage}_note", None),
                      "beside": said.pop(f"{stage}_beside", None)} for stage in ("train", "eval")}
    return said, stages


def _same_measure(task: str, column: str, new: dict, old: dict, what: str) -> None:
    """A SystemExit unless ``new`` (``what``, in words) was measured on ``old``'s dataset
    format, task version and task items: only then do they pool or stand side by side."""
    ours, theirs = measured_on(task, column, new), measured_on(task, column, old)
    if ours != theirs:
        items = ours[2] != theirs[2]  # (named where they differ)
        said = ("{} ({})".format(*m[:2]) + (f", task items {m[2]}" if items else "")
                for m in (ours, theirs))
        raise SystemExit(f"{task} {column}: {what} trained on {next(said)}, the recorded "
                         f"cell on {next(said)}")


def items_of(run: dict, task: str, spec: str) -> dict:
    """``{"task_items": [...]}``: the recipe's items for ``task`` alone (its plan's
    ``task_sets``) that ``spec``'s policy trained with (``plan.meant_for``); ``{}`` where
    ``run`` has no plan to read them from (an evaluation's)."""
    plan = run.get("plan") or {}
    if "task_sets" not in plan:
        return {}
    return {"task_items": meant_for(parse_policy(spec)[0], plan["task_sets"].get(task, ()))}


def add_seed(old: dict | None, new: dict, seed: int, task: str, column: str) -> dict:
    """The recorded cell ``old`` with ``new`` as its training seed ``seed``: every seed's
    record under ``seeds``, the cell their pool. Each seed keeps its own command; seeds of
    other data or another task version do not pool."""
    if old is None:
        raise SystemExit(f"{task} {column}: no recorded cell to add seed {seed} to")
    if "seeds" in new:
        raise SystemExit(f"{task} {column}: the new cell pools seeds {sorted(new['seeds'])}; "
                         f"record one seed")
    _same_measure(task, column, new, old, f"seed {seed}")
    seeds = {int(s): r for s, r in seed_records(old).items()}
    seeds[seed] = new
    if len(seeds) == 1:  # seed 0 of a cell of one seed: the cell itself
        return new
    seeds = {s: {**r, "gym_id": recorded_gym_id(task, r)} for s, r in seeds.items()}
    commands = "; ".join(dict.fromkeys(seeds[s]["command"] for s in sorted(seeds)
                                       if seeds[s].get("command")))
    return {**pooled_row(seeds), "dataset": new["dataset"], "command": commands}


def record(doc: dict, run: dict, tasks: list[str], specs: list[str], dataset: str,
           why: str, table: str, seed: int | None = None,
           conditions: dict | None = None, recipe_changed: bool = False,
           train_pieces: list[dict] | None = None) -> dict:
    """``doc`` with ``run``'s cells of ``tasks`` x ``specs`` in place of its own (or, with
    ``seed``, added to its own as that training seed); ``conditions``: the fields
    ``stated_conditions`` writes into each new cell's walls' conditions (``train_note``,
    ``train_beside``, ``eval_note`` and ``eval_beside`` into its training's or its
    evaluation's alone, over ``note`` and ``beside``); ``recipe_changed``: the
    cells replaced were another recipe's, kept under ``superseded`` whatever their data and
    task version; ``train_pieces``: the training's pieces (``stated_conditions``), for a
    training run on several machines."""
    said, stages = _said(conditions)
    replaced: dict[str, dict] = {}
    for task in tasks:
        for spec in specs:
            row = run["cells"].get(task, {}).get(spec)
            if row is None:
                raise SystemExit(f"{table}: {task} {spec} is not evaluated yet")
            try:
                stated = stated_conditions(spec, stages, train_pieces, **said)
            except ValueError as err:
                raise SystemExit(str(err)) from None
            items = items_of(run, task, spec)

            def kept(r: dict, stated=stated, items=items) -> dict:
                return {"conditions": stated, **r, "dataset": dataset, "command": run["command"],
                        **items}

            new = kept(cell_record(row, task))
            if "seeds" in new:  # a column of several training seeds: each seed's record
                # keeps what one recorded with --seed keeps (each seed's stages ran apart)
                new["seeds"] = {s: kept(r) for s, r in new["seeds"].items()}
            ran = [s for s in (run.get("plan") or {}).get("policies", [])
                   if split_seed(s)[0] == spec]
            if seed is None and "policies" in (run.get("plan") or {}) and spec not in ran:
                raise SystemExit(f"{table}: its {spec} column is {ran}, without seed 0: "
                                 f"record a seed with --seed")
            if seed is not None:
                # a table's column is its seeds' pool: it must be this seed alone
                if run.get("plan") and ran != [with_seed(spec, seed)]:
                    raise SystemExit(f"{table}: its {spec} column is {ran}, not seed {seed} "
                                     f"alone")
                doc["cells"].setdefault(task, {})[spec] = add_seed(
                    doc["cells"].get(task, {}).get(spec), new, seed, task, spec)
                continue
            old = doc["cells"].setdefault(task, {}).get(spec)
            same = (old is not None and not recipe_changed
                    and measured_on(task, spec, old) == measured_on(task, spec, new))
            if same and "seeds" in old and "seeds" not in new:
                raise SystemExit(f"{task} {spec}: the recorded cell pools seeds "
                                 f"{sorted(old['seeds'])}; give --seed to replace one")
            # a cell of the same data and task version is the same recipe measured before
            # (or one of the seeds the new cell pools): the new one stands for it
            if old is not None and not same:
                replaced.setdefault(task, {})[spec] = old
            doc["cells"][task][spec] = new
        doc["chance"][task] = run["chance"][task] if "chance" in run else asdict(chance(task))
        walls = (run.get("wall_s") or {}).get("data", {}).get(task)
        if walls:  # the task's data stages, shared by its cells (a note written on them kept)
            kept = doc.setdefault("data_walls", {}).get(task, {})
            doc["data_walls"][task] = {**walls, **{k: v for k, v in kept.items() if k == "note"}}
    if replaced and not why:
        raise SystemExit("--why: say why the cells this replaces no longer stand (" + ", ".join(
            f"{task} {spec}" for task, cells in replaced.items() for spec in cells) + ")")
    if replaced:
        _supersede(doc, replaced, why)
    return doc


def _supersede(doc: dict, cells_by_task: dict[str, dict], why: str) -> None:
    """Keep ``cells_by_task`` in ``doc``'s ``superseded`` group of ``why``."""
    groups = [g for g in doc.get("superseded", []) if g["why"] != why]
    same = next((g for g in doc.get("superseded", []) if g["why"] == why), None)
    kept = same["cells"] if same else {}
    for task, cells in cells_by_task.items():
        for spec, cell in cells.items():
            # the cell a change replaced stays: recording the new recipe's cell again
            # (under the same why) replaces that one, not the measurement before the change
            kept.setdefault(task, {}).setdefault(spec, cell)
    doc["superseded"] = groups + [{"why": why, "cells": kept}]


def withdraw(doc: dict, tasks: list[str], specs: list[str], why: str) -> dict:
    """``doc`` with its cells of ``tasks`` x ``specs`` moved to ``superseded`` under ``why``,
    each left empty in the table: for a cell run on an earlier version of its task that is not
    re-run yet, so that no table or average mixes versions. A cell of the current version is
    refused (withdrawing a measurement of what the table reports would choose its numbers)."""
    if not why:
        raise SystemExit("--why: say why the withdrawn cells no longer stand")
    out: dict[str, dict] = {}
    for task in tasks:
        for spec in specs:
            cell = doc["cells"].get(task, {}).get(spec)
            if cell is None:
                raise SystemExit(f"{task} {spec}: no such cell in the table")
            if on_current_version(task, cell):
                raise SystemExit(f"{task} {spec}: ran on {get_task(task).gym_id}, the current "
                                 f"version; only a cell of an earlier version is withdrawn")
            out.setdefault(task, {})[spec] = doc["cells"][task].pop(spec)
    _supersede(doc, out, why)
    return doc


def add_rerun(doc: dict, run: dict, tasks: list[str], specs: list[str], dataset: str,
              table: str, seed: int, conditions: dict | None = None) -> dict:
    """``doc`` with ``run``'s cells of ``tasks`` x ``specs`` under ``reruns``, each as the
    recorded cell's training seed ``seed`` trained again; the recorded cells unchanged."""
    said, stages = _said(conditions)
    reruns = doc.setdefault("reruns", [])
    for task in tasks:
        for spec in specs:
            row = run["cells"].get(task, {}).get(spec)
            if row is None:
                raise SystemExit(f"{table}: {task} {spec} is not evaluated yet")
            if "seeds" in row:
                raise SystemExit(f"{table}: its {task} {spec} cell pools seeds "
                                 f"{sorted(row['seeds'])}; a re-run is one seed")
            old = doc["cells"].get(task, {}).get(spec)
            if old is None or str(seed) not in seed_records(old):
                raise SystemExit(f"{task} {spec}: no recorded seed {seed} to re-run")
            try:
                stated = stated_conditions(spec, stages, None, **said)
            except ValueError as err:
                raise SystemExit(str(err)) from None
            new = {"task": task, "column": spec, "seed": seed, "conditions": stated,
                   **cell_record(row, task), "dataset": dataset, "command": run["command"],
                   **items_of(run, task, spec)}
            _same_measure(task, spec, new, old, "the re-run")
            reruns[:] = [r for r in reruns if (r["task"], r["column"], r["seed"], r["command"])
                         != (task, spec, seed, new["command"])] + [new]
    return doc


def _train_piece(text: str) -> dict:
    """``--train-piece``'s value: a JSON object (its fields are checked when it is recorded)."""
    try:
        piece = json.loads(text)
    except json.JSONDecodeError as err:
        raise argparse.ArgumentTypeError(f"not JSON ({err}): {text}") from None
    if not isinstance(piece, dict):
        raise argparse.ArgumentTypeError(f"not a JSON object of training fields: {text}")
    return piece


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--table", help="an `rmbench table` folder (its table.json)")
    source.add_argument("--evaluation", help="an `rmbench eval` folder of one checkpoint")
    source.add_argument("--withdraw", action="store_true",
                        help="move the recorded cells of --tasks x --specs, each run on an "
                             "earlier version of its task, to superseded under --why, leaving "
                             "them empty until re-run")
    p.add_argument("--tasks", required=True)
    p.add_argument("--specs", required=True)
    p.add_argument("--dataset", help="the format the cells trained on (rmbench/N; needed "
                                     "with --table or --evaluation)")
    p.add_argument("--why", help="why the replaced cells no longer stand, in words (a cell of "
                                  "other data or another task version moves to superseded)")
    p.add_argument("--recipe-changed", action="store_true",
                   help="the cells were made with another recipe than those they replace: "
                        "those move to superseded under --why")
    p.add_argument("--seed", type=int, help="the cells are this training seed of the recorded "
                                             "ones: pool them")
    p.add_argument("--rerun", action="store_true",
                   help="the cells are the recorded seed (--seed, else 0) trained again, on "
                        "another machine: kept under reruns, the recorded cells unchanged")
    p.add_argument("--obs", choices=("state", "pixels"), default="state",
                   help="the table the cells belong to (default state)")
    p.add_argument("--out", type=Path, help="the results file (default "
                                            "benchmarks/results/table_<obs>.json)")
    said = p.add_argument_group("the walls' conditions (suite/records.py; unstated when left out)")
    said.add_argument("--machine", help="a key of the results' machines (cpu, h100, ...)")
    said.add_argument("--jobs-beside", type=int, metavar="N",
                      help="other jobs that shared the machine with each stage")
    said.add_argument("--beside", metavar="TEXT", help="what those jobs were, in words")
    said.add_argument("--train-beside", metavar="TEXT",
                      help="what ran beside the training alone (over --beside)")
    said.add_argument("--eval-beside", metavar="TEXT",
                      help="what ran beside the evaluation alone (over --beside)")
    said.add_argument("--threads", type=int, help="the training's torch threads")
    said.add_argument("--workers", type=int, help="the evaluation's workers")
    said.add_argument("--note", metavar="TEXT", help="anything else the walls need said")
    said.add_argument("--train-note", metavar="TEXT",
                      help="what the training's wall alone needs said (it ran in pieces, ...)")
    said.add_argument("--eval-note", metavar="TEXT",
                      help="what the evaluation's wall alone needs said (it was resumed, ...)")
    said.add_argument("--data-note", metavar="TEXT",
                      help="what the tasks' data walls need said (their copies were rendered "
                           "in pieces, beside other jobs, ...): kept beside those walls")
    said.add_argument("--train-piece", metavar="JSON", action="append", type=_train_piece,
                      help="a training run in pieces, one per machine or run, in step order: "
                           "'{\"machine\": \"h200\", \"steps\": [0, 17500], \"wall_s\": 442, "
                           "\"jobs_beside\": 1}' (repeatable; the options above fill what a "
                           "piece leaves unsaid)")
    args = p.parse_args(argv)
    args.out = args.out or RESULTS / f"table_{args.obs}.json"
    if args.seed is not None and args.seed < 0:
        raise SystemExit(f"--seed {args.seed}: a training seed is 0 or more")
    if args.rerun and (args.why or args.recipe_changed or args.train_piece or args.data_note):
        raise SystemExit("--rerun replaces nothing and keeps no data walls: without "
                         "--why, --recipe-changed, --train-piece and --data-note")
    if args.withdraw:
        if not args.out.exists():
            raise SystemExit(f"{args.out}: no such results file")
        doc = withdraw(json.loads(args.out.read_text()), args.tasks.split(","),
                       args.specs.split(","), args.why)
        write_json(args.out, doc)
        print(f"wrote {args.out}")
        return 0
    if not args.dataset:
        raise SystemExit("--dataset: say the format the cells trained on (rmbench/N)")
    if args.evaluation and "," in args.specs:
        raise SystemExit("--evaluation records one column: give one --specs")
    try:
        run = (json.loads((Path(args.table) / "table.json").read_text()) if args.table
               else evaluation_rows(Path(args.evaluation), args.specs))
    except ValueError as err:
        raise SystemExit(str(err)) from None
    ran = (run.get("plan") or {}).get("obs")
    if ran and ran != args.obs:
        raise SystemExit(f"{args.table}: a table of the {ran} observation, not {args.obs} "
                         f"(--obs)")
    split = (run.get("plan") or {}).get("split", "test")
    if split != "test":
        raise SystemExit(f"{args.table}: a table on the {split} episodes; the results report "
                         f"each task's test episodes")
    if not args.out.exists() and args.obs == "state":
        raise SystemExit(f"{args.out}: no such results file")
    doc = json.loads(args.out.read_text()) if args.out.exists() else new_table(run)
    known = doc.get("machines", {})

    def check_machine(name: str | None, flag: str) -> None:
        if name is not None and name not in known:
            raise SystemExit(f"{flag}: machine {name!r} is not one of {args.out.name}'s "
                             f"machines ({', '.join(known)})")

    check_machine(args.machine, "--machine")
    if args.train_piece and len(args.tasks.split(",")) * len(args.specs.split(",")) > 1:
        raise SystemExit("--train-piece states one training's pieces: record one task and "
                         "one spec at a time")
    for piece in args.train_piece or []:
        check_machine(piece.get("machine"), "--train-piece")
    said_now = {k: getattr(args, k) for k in (
        "machine", "jobs_beside", "beside", "threads", "workers", "note",
        "train_note", "eval_note", "train_beside", "eval_beside")}
    if args.rerun:
        doc = add_rerun(doc, run, args.tasks.split(","), args.specs.split(","), args.dataset,
                        args.table or args.evaluation, args.seed or 0, said_now)
        write_json(args.out, doc)
        print(f"wrote {args.out}")
        return 0
    doc = record(doc, run, args.tasks.split(","),
                 args.specs.split(","), args.dataset, args.why, args.table or args.evaluation,
                 args.seed, said_now, args.recipe_changed, args.train_piece)
    if args.data_note:
        for task in args.tasks.split(","):
            if task not in doc.get("data_walls", {}):
                raise SystemExit(f"--data-note: {task} has no data walls in {args.table or args.evaluation}")
            doc["data_walls"][task]["note"] = args.data_note
    write_json(args.out, doc)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
