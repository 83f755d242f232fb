"""The tables of README.md and docs/, rendered from the JSON under benchmarks/results/.

A doc holds a generated table between two markers:

    <!-- table:NAME -->
    ...
    <!-- /table -->

and this script rewrites what lies between them from ``TABLES[NAME]``; no number in such a
table is typed by hand. Success rates carry their Wilson 95% interval (``eval/intervals.py``).

    .venv/bin/python scripts/render_docs.py          # rewrite every table
    .venv/bin/python scripts/render_docs.py --check  # list the tables that differ; exit 1 if any

``tests/test_docs.py`` runs the check, so a committed doc cannot drift from its JSON.
"""

from __future__ import annotations

import argparse
import functools
import json
import re
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path

from rmbench.data.layout import FORMAT
from rmbench.eval import published as paper
from rmbench.eval.chance import chance
from rmbench.eval.endings import failure_kind
from rmbench.eval.intervals import difference, format_difference, format_rate
from rmbench.eval.report import PUBLISHED, Rate, published_source
from rmbench.files import write_atomic
from rmbench.policies.config import split_policy
from rmbench.suite.plan import COLUMNS, applies, executor_spec
from rmbench.suite.records import measured_on, reads_subtask_cut, seed_records, task_items
from rmbench.suite.tables import (
    ABLATION_TABLE,
    POLICY_TABLE,
    difference_table,
    differences,
)
from rmbench.tasks import get_task
from rmbench.tasks.registry import on_current_version, ordered

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
MARKER = re.compile(r"(<!-- table:([\w-]+) -->\n)(.*?)(<!-- /table -->)", re.S)

COLUMN = {"mem0": "Mem-0", "mem0:no_memory": "`no_memory`", "mem0:no_anchor": "`no_anchor`",
          "mem0:no_sliding": "`no_sliding`", "mem0:no_key": "`no_key`",
          "mem0:gt_classifier": "`gt_classifier`", "dp": "DP", "act": "ACT",
          "mem0:no_memory+no_key": "`no_memory+no_key`"}


def load(name: str) -> dict:
    res = json.loads((RESULTS / name).read_text())
    return _recipe_marked(res) if name.startswith("table_") else res


def _recipe_marked(res: dict) -> dict:
    """``res`` (a table's results) with each Mem-0 ablation cell that trained with other task
    items than its row's Mem-0 cell (``task_items``: a recipe change re-runs Mem-0 first)
    flagged ``recipe_before``, which ``_older`` marks '§'."""
    for row in res.get("cells", {}).values():
        base = row.get("mem0")
        for spec, cell in row.items():
            if base is not None and spec.startswith("mem0:") and cell is not None:
                cell["recipe_before"] = task_items(cell) != task_items(base)
    return res


def rate(cell: dict | None) -> str:
    """'85 [77, 91]': successes in percent with the Wilson 95% interval; '—' if not measured."""
    if cell is None:
        return "—"
    r = Rate.of(cell)
    return format_rate(r.successes, r.episodes)


def minutes(seconds: float | None) -> str:
    return "—" if seconds is None else f"{seconds / 60:.1f} min"


def markdown(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(v) for v in r) + " |" for r in rows]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------ the tasks
def tasks() -> str:
    """The nine tasks as the registry defines them, each with its chance level without memory."""
    rows = [[t.name, f"`{t.gym_id}`", t.tmc, t.step_limit, t.aliasing_point,
             f"{100 * chance(t.name).rate:.1f}%"] for t in ordered()]
    return markdown(["task", "gym id", "TMC", "step limit", "where only memory tells", "chance"], rows)


# ------------------------------------------------------------------ the state table
def _needs_no_memory(res: dict) -> list[str]:
    """The tasks whose chance level is 100%: a policy without memory can solve them, so their
    rows measure skill, not memory."""
    return [t.name for t in ordered() if t.name in res["chance"] and res["chance"][t.name]["rate"] >= 1]


def _state_rows(res: dict, specs: list[str], extra: Callable[[str], list] = lambda t: [],
                extra_avg: Callable[..., list] = lambda g, without=(): []) -> list[list[str]]:
    """One row per task (M(1), then M(n)) and the three averages: each measured cell as a rate
    with its interval, each average as the mean of its column's rates (empty where a column
    lacks a cell of the group). Where a task needs no memory (chance 100%), its group's
    average and the overall one come again without it, each right below."""
    skip = _needs_no_memory(res)
    cells, rows, groups = res["cells"], [], {}
    for task in ordered():
        row = cells.get(task.name, {})  # (a task not measured yet: its row and averages read —)
        groups.setdefault(task.tmc, []).append(task.name)
        rows.append([task.name, task.tmc]
                    + [(rate(row.get(s)) + _older(task.name, s, row.get(s)))
                       if applies(s, task.tmc) else "n/a" for s in specs]
                    + extra(task.name))
        if task.name == [t.name for t in ordered() if t.tmc == task.tmc][-1]:
            rows += _averages(res, specs, groups[task.tmc], f"average {task.tmc}", task.tmc,
                              skip, extra_avg)
    everything = [t for names in groups.values() for t in names]
    rows += _averages(res, specs, everything, "average (all)", "", skip, extra_avg)
    return rows


def _averages(res: dict, specs: list[str], tasks: list[str], name: str, group: str,
              skip: list[str], extra_avg: Callable[..., list]) -> list[list[str]]:
    """The average row over ``tasks``, and where some of ``skip`` is among them, the average
    without those."""
    rows = [_average(res, specs, tasks, name, group) + extra_avg(group)]
    without = tuple(t for t in skip if t in tasks)
    if without:
        rows.append(_average(res, specs, [t for t in tasks if t not in without],
                             f"{name} without {_and(list(without))}", group)
                    + extra_avg(group, without))
    return rows


def _without_line(res: dict) -> str:
    """The note under a table with averages without the tasks that need no memory."""
    skip = _needs_no_memory(res)
    if not skip:
        return ""
    rows = "that row" if len(skip) == 1 else "those rows"
    return (f"\nAverages without {_and(skip)}: the same means with {rows} left out, whose "
            "chance level is 100% (a policy without memory can solve it: it measures skill, "
            "not memory).\n")


def _withdrawn_line(res: dict, specs: list[str]) -> str:
    """The note for the cells of ``specs`` withdrawn from the table (``benchmarks/
    table_state.py --withdraw``): kept under ``superseded``, run on an earlier version of their
    task, and not re-run on the current one yet; '' where there are none."""
    gone: dict[str, list[str]] = {}
    for group in res.get("superseded", []):
        for task, cells in group["cells"].items():
            for spec, cell in cells.items():
                if (spec in specs and spec not in res["cells"].get(task, {})
                        and not on_current_version(task, cell)):
                    gone.setdefault(spec, []).append(task)
    if not gone:
        return ""
    said = "; ".join(f"{COLUMN[s]} on {_and(sorted(set(ts)))}" for s, ts in gone.items())
    return (f"\n— ({said}): measured on an earlier version of the task only, and withdrawn "
            "until run on the current version, so that no cell or average mixes "
            "versions (the earlier cells: docs/history.md; what each version changed: "
            "CHANGELOG.md).\n")


def _version_mark(task: type, cell: dict) -> str:
    """'‡' for a record (a cell, an expert run) made on an earlier version of ``task``, the
    gym id it records (``recorded_gym_id``)."""
    return "" if on_current_version(task.name, cell) else "‡"


def _older(task: str, spec: str, cell: dict | None) -> str:
    """The marks of a cell measured before the current task or data (CHANGELOG.md): ' †' for
    a Mem-0 cell of an M(n) row trained on datasets older than the current format (its
    planner and end classifier learnt another subtask layout; M(1) Mem-0 runs one subtask,
    the goal, and DP and ACT read no subtask: the format changes nothing they learn); ' ‡'
    for any cell run on an earlier version of its task (the gym id it records)."""
    if cell is None:
        return ""
    cls = get_task(task)
    marks = ""
    if reads_subtask_cut(task, spec) and cell.get("dataset") != FORMAT:
        marks += "†"
    marks += _version_mark(cls, cell)
    if cell.get("recipe_before"):
        marks += "§"
    return f" {marks}" if marks else ""


def _footnote(table: str, lead: str = "", marks: str | None = None) -> str:
    """The notes under a table for the marks it holds, or for ``marks`` with ``lead`` (how a
    table that leaves such cells out says so, instead of the marks: its ``{mark}`` the one a
    left-out cell carries)."""
    marks = "".join(m for m in "†‡§" if m in table) if marks is None else marks
    notes = []
    if "†" in marks:
        notes.append(f"{lead.format(mark='†') if lead else '†'} trained on datasets older than "
                     f"format `{FORMAT}`, where a subtask repeated back to back was one subtask "
                     "(CHANGELOG.md, 2026-11-27); not re-run on the current data yet.")
    if "‡" in marks:
        notes.append(f"{lead.format(mark='‡') + ' run' if lead else '‡'} on an earlier version of "
                     "the task than the one the README's tasks table names (what each version changed, "
                     "and why results before it are not mixed with those after: CHANGELOG.md); "
                     "not re-run on the current version yet.")
    if "§" in marks:
        notes.append(f"{lead.format(mark='§') if lead else '§'} trained without the items its "
                     "task's recipe now adds for Mem-0 and its ablations, which the row's Mem-0 "
                     "cell trained with (`task_sets` in `src/rmbench/suite/recipes.py`; "
                     "CHANGELOG.md); not re-run with them yet.")
    return "".join(f"\n{n}\n" for n in notes)


def _average(res: dict, specs: list[str], tasks: list[str], name: str, group: str) -> list[str]:
    out = [f"**{name}**", group]
    for s in specs:
        vals = [res["cells"].get(t, {}).get(s) for t in tasks]
        if any(v is None for v in vals):
            out.append("n/a" if not all(applies(s, g) for g in ({group} if group else {"M(1)", "M(n)"}))
                       else "—")
        else:
            older = "".join(sorted({m for t, v in zip(tasks, vals, strict=True)
                                    for m in _older(t, s, v).strip()}))
            out.append(f"{100 * sum(v['success_rate'] for v in vals) / len(vals):.1f}"
                       + (f" {older}" if older else ""))
    return out


def _chance(res: dict, task: str) -> list[str]:
    return [f"{100 * res['chance'][task]['rate']:.1f}"]


def _chance_avg(res: dict, group: str, without: tuple[str, ...] = ()) -> list[str]:
    tasks = [t.name for t in ordered() if t.name in res["chance"] and (not group or t.tmc == group)
             and t.name not in without]
    return [f"{100 * sum(res['chance'][t]['rate'] for t in tasks) / len(tasks):.1f}"]


def _published_average(table: str, column: str, group: str,
                       without: tuple[str, ...] = ()) -> float | None:
    """The paper's average of ``column`` over ``group`` (its stated one, else the mean of its
    tasks); ``without``: the mean of its tasks but those (the paper states no such average)."""
    if not without:
        return paper.average(table, column, group)
    rates = paper.columns(table)[column]
    tasks = [t for t, g in paper.data()["tasks"].items()
             if (not group or g == group) and t not in without]
    if any(t not in rates for t in tasks):
        return None
    return sum(rates[t] for t in tasks) / len(tasks)


def _published_avg(policy: str, group: str, without: tuple[str, ...] = ()) -> str:
    return f"{_published_average('main', policy, group, without):.1f}"


def readme_results() -> str:
    res, cams = load("table_state.json"), pixel_table()
    specs = list(POLICY_TABLE)
    header = ["task", "TMC", *(f"{COLUMN[s]} (state)" for s in specs),
              *(f"{COLUMN[s]} (cameras)" for s in PIXEL_MAIN), "chance",
              "Mem-0 (published, cameras)"]
    rows = _state_rows(res, specs,
                       lambda t: _cells(cams, t, PIXEL_MAIN) + _chance(res, t)
                       + [f"{PUBLISHED['Mem-0'][t]:g}"],
                       lambda g, w=(): _column_avgs(cams, PIXEL_MAIN, g, w)
                       + _chance_avg(res, g, w) + [_published_avg("Mem-0", g, w)])
    table = markdown(header, rows)
    return (table + _published_line() + _pixels_line(cams) + _without_line(res)
            + _withdrawn_line(res, specs) + _footnote(table))


# ------------------------------------------------------------------ the camera table
PIXEL_MAIN = ["mem0", "mem0:no_memory"]  # the camera columns the README shows


def pixel_table() -> dict:
    """benchmarks/results/table_pixels.json with a row for every task (empty where none of its
    cells is recorded yet) and every task's chance level."""
    path = RESULTS / "table_pixels.json"
    res = (_recipe_marked(json.loads(path.read_text())) if path.exists()
           else {"cells": {}, "chance": {}})
    cells = {t.name: res["cells"].get(t.name, {}) for t in ordered()}
    odds = {t.name: res["chance"].get(t.name) or {"rate": chance(t.name).rate} for t in ordered()}
    return {**res, "cells": cells, "chance": odds}


def _cells(res: dict, task: str, specs: list[str]) -> list[str]:
    row = res["cells"].get(task, {})
    return [rate(row.get(s)) + _older(task, s, row.get(s)) if applies(s, get_task(task).tmc)
            else "n/a" for s in specs]


def _column_avgs(res: dict, specs: list[str], group: str, without: tuple[str, ...] = ()) -> list[str]:
    tasks = [t.name for t in ordered() if (not group or t.tmc == group) and t.name not in without]
    return _average(res, specs, tasks, "", group)[2:]


def _pixels_line(cams: dict) -> str:
    done = sum(1 for t in ordered() if cams["cells"][t.name].get("mem0"))
    return (f"\nThe camera columns: [the camera table](docs/results/benchmark_pixels.md), "
            f"{done} of 9 rows measured so far (— where a cell is not yet).\n")


def _memory_gap(res: dict, task: str) -> list[str]:
    """Mem-0 minus ``no_memory`` in points with Newcombe's 95% interval, * where it excludes 0;
    — where either is missing or the two were measured on other data or task versions
    (``measured_on``: two cells marked alike may still stand on different versions)."""
    row = res["cells"].get(task, {})
    a, b = row.get("mem0"), row.get("mem0:no_memory")
    if a is None or b is None or (measured_on(task, "mem0", a)
                                  != measured_on(task, "mem0:no_memory", b)):
        return ["—"]
    ra, rb = Rate.of(a), Rate.of(b)
    d, low, high = difference(ra.successes, ra.episodes, rb.successes, rb.episodes)
    return [format_difference(d, low, high) + ("*" if low > 0 or high < 0 else "")]


def pixels_policies() -> str:
    res, state = pixel_table(), load("table_state.json")
    specs = list(POLICY_TABLE)
    header = ["task", "TMC", *(f"{COLUMN[s]} (cameras)" for s in specs),
              "Mem-0 − `no_memory` (points)", "Mem-0 (state)", "Mem-0 (published, cameras)",
              "chance"]
    rows = _state_rows(res, specs,
                       lambda t: _memory_gap(res, t) + _cells(state, t, ["mem0"])
                       + [f"{PUBLISHED['Mem-0'][t]:g}"] + _chance(res, t),
                       lambda g, w=(): [""] + _column_avgs(state, ["mem0"], g, w)
                       + [_published_avg("Mem-0", g, w)] + _chance_avg(res, g, w))
    table = markdown(header, rows)
    return (table + "\nMem-0 − `no_memory`: the difference in points with Newcombe's 95% "
            "interval, * where it excludes 0. The state column is the [state table]"
            "(benchmark_state.md)'s; the published one the paper's, read from cameras as these "
            "cells are.\n" + _without_line(res) + _footnote(table))


def validation_probes(obs: str = "state") -> str:
    """Recipe probes on the validation episodes of ``obs``'s table
    (benchmarks/validation_probes.py)."""
    path = RESULTS / "validation_probes.json"
    probes = [p for p in (json.loads(path.read_text())["probes"] if path.exists() else [])
              if p["obs"] == obs]
    rows = [[p["task"], f"`{Path(split_policy(p['policy'])[1]).name.split('-s')[0]}`", p["change"],
             rate(p), ", ".join(f"{k} {v}" for k, v in p["endings"].items() if v),
             _decisions_text(p.get("decisions"))]
            for p in probes]
    return markdown(["task", "checkpoint (training seed)", "probe", "success (validation)",
                     "endings", "planner's choices right at the ends declared on time or late"],
                    rows)


def _decisions_text(d: dict | None) -> str:
    """'104 of 108; swap the left and right blocks 0 of 3', the plan's next subtasks it chose
    wrong at least once after the total; '—' where not kept (or an M(1) task)."""
    if not d or not d["judged"]:
        return "—"
    wrong = [f"{w} {c['right']} of {c['of']}" for w, c in d["by_next"].items()
             if c["right"] < c["of"]]
    return f"{d['right']} of {d['judged']}" + ("; " + "; ".join(wrong) if wrong else "")


def planner_keys_pixels() -> str:
    """The camera planner's decisions on held-out press_button demonstrations, per planner
    setting (benchmarks/planner_keys.py)."""
    doc = json.loads((RESULTS / "planner_keys_press_button_pixels.json").read_text())
    rows = []
    for name, r in doc["checkpoints"].items():
        by = {d["delay"]: d for d in r["delays"]}
        rows.append([name] + [f"{by[k]['decisions_right']} of {by[k]['decisions']}; "
                              f"{by[k]['episodes_all_right']} of {by[k]['episodes']}"
                              for k in (0, 12)])
    return markdown(["planner fitted", "keys on the end frames: decisions right; episodes all right",
                     "keys 12 frames late"], rows)


def share_text(c: dict) -> str:
    """A stored share ({count, of, ...}, rmbench.eval.intervals.share): '43 [34, 53] (43 of
    100)', or '—' where there was nothing to count."""
    if not c["of"]:
        return "—"
    return format_rate(c["count"], c["of"]) + f" ({c['count']} of {c['of']})"


def observe_grasps() -> str:
    """Where observe_and_pickup's first grasp closes (benchmarks/observe_grasps.py)."""
    path = RESULTS / "observe_grasps.json"
    rows = []
    for r in (json.loads(path.read_text())["rows"] if path.exists() else []):
        shares = [share_text(r[k]) for k in ("success", "on_object", "on_target", "target_side_arm")]
        cm = [("—" if r.get(k) is None else f"{100 * r[k]:.1f}")
              for k in ("median_nearest_m", "median_target_m", "median_height_m")]
        rows.append([r["label"], *shares, *cm])
    return markdown(["policy", "success", "first grasp on an object", "on the target",
                     "with the target side's arm", "median cm to the nearest object",
                     "median cm to the target", "median cm over the table"], rows)


def render_size() -> str:
    """Copies' frames rendered smaller: cost and feature distance (benchmarks/render_size.py)."""
    path = RESULTS / "render_size.json"
    if not path.exists():
        return markdown(["rendered at"], [])
    res = json.loads(path.read_text())
    cams, rows = res["cameras"], []
    for size, r in res["sizes"].items():
        rows.append([size, f"{r['render_ms_per_image']:.1f}", f"{r['encode_ms_per_image']:.1f}",
                     f"{r['render_encode_speedup']:.2f}x",
                     *(f"{r['cameras'][c]['training_vs_closed_loop']:.3f}" for c in cams)])
    for key, label in ((f"{res['lag_steps']}_steps_later",
                        f"(the same view {res['lag_steps']} steps later)"),
                       ("other_layout", "(the same step of another layout)")):
        rows.append([label, "", "", "", *(f"{res['apart'][c][key]:.3f}" for c in cams)])
    return markdown(["rendered at", "render (CPU ms an image)", "encode (CPU ms an image)",
                     "speed-up", *(f"{c}: training features' distance" for c in cams)], rows)


def put_back_loops() -> str:
    """Put-back loops in evaluation records (benchmarks/put_back_loops.py)."""
    path = RESULTS / "put_back_loops.json"
    rows = []
    for r in (json.loads(path.read_text())["rows"] if path.exists() else []):
        by = r["looped_by_ending"]
        nothing = {"count": 0, "of": 0}  # no episode ended so: share_text's '—'
        rows.append([r["task"], r["label"], r["split"], share_text(r["looped"]),
                     share_text(by.get("timeout", nothing)), share_text(by.get("success", nothing)),
                     f"{r['put_back_steps_median']:.0f} against {r['move_steps_median']:.0f}",
                     "; ".join(f"{s} {n}" for s, n in r["failed_looping_mostly_in"].items()),
                     share_text(r["timeouts_still"]) if "timeouts_still" in r else "(not kept)"])
    return markdown(["task", "checkpoint", "episodes", "episodes that loop", "of the timeouts",
                     "of the successes", "steps out of place: put-back against move "
                     "(medians)", "failed loops, by the stage most of their put-backs were in",
                     "timeouts with no task fact changing in the last quarter of the step limit"],
                    rows)


def _most(cell: dict, stage: str, field: str) -> int:
    """The most threads (training) or workers (evaluation) any piece of a cell's stage states;
    one where none states any."""
    return max([p.get(field) or 1 for p in (cell.get("conditions") or {}).get(stage, [])] or [1])


def _core_seconds(cell: dict, stage: str, field: str, wall: float) -> float:
    """A cell's stage wall in core-seconds: each piece's wall (the whole ``wall`` for a stage
    of one piece) times the threads or workers it states, one where it states none."""
    pieces = (cell.get("conditions") or {}).get(stage, [])
    if len(pieces) > 1 and all(p.get("wall_s") is not None for p in pieces):
        return sum(p["wall_s"] * (p.get(field) or 1) for p in pieces)
    return wall * _most(cell, stage, field)


def _busy(cell: dict, stage: str, field: str, wall: float | None) -> str:
    """A stage's wall in minutes, with the workers or threads that shared it where more than
    one."""
    n = _most(cell, stage, field)
    return minutes(wall) + (f" ({n} {field})" if n > 1 else "")


def pixels_cost() -> str:
    """Each measured row's cost: its data stages (shared by its cells) and each cell's
    training and evaluation, in core-hours: each wall times the threads or workers its record
    states (one where it states none). The cells shown alone: superseded ones are not
    counted."""
    res = pixel_table()
    walls = res.get("data_walls", {})
    specs = COLUMNS["pixels"]
    rows, notes = [], []
    for task in ordered():
        cells = {s: c for s, c in res["cells"][task.name].items() if s in specs and c}
        if not cells:
            continue
        w = walls.get(task.name, {})
        data = [w.get(k) for k in ("collect_wall_s", "copies_wall_s", "features_wall_s")]
        # gt_classifier evaluates Mem-0's checkpoint: its record's training is Mem-0's
        trained = {s: c for s, c in cells.items()
                   if s != "mem0:gt_classifier" and c.get("train_wall_s") is not None}
        fits = "; ".join(f"{COLUMN[s]} {_busy(c, 'train', 'threads', c['train_wall_s'])}"
                         for s, c in trained.items())
        evals = "; ".join(f"{COLUMN[s]} {_busy(c, 'eval', 'workers', c.get('eval_wall_s'))}"
                          for s, c in cells.items())
        spent = [x for x in data if x is not None] + [
            _core_seconds(c, "train", "threads", c["train_wall_s"]) for c in trained.values()] + [
            _core_seconds(c, "eval", "workers", c.get("eval_wall_s") or 0)
            for c in cells.values()]
        rows.append([task.name, *(minutes(x) for x in data), fits, evals,
                     f"{sum(spent) / 3600:.1f}"])
        if w.get("note"):
            notes.append(f"{task.name}: {w['note']}")
        # what a cell's record says of its walls (a resumed evaluation, pieces, ...), once
        for s, c in cells.items():
            said = {what: [p["note"] for p in (c.get("conditions") or {}).get(stage, [])
                           if p.get("note")]
                    for stage, what in (("train", "training"), ("eval", "evaluation"))}
            if said["training"] and said["training"] == said["evaluation"]:
                said = {"walls": said["training"]}
            notes += [f"{task.name}, {COLUMN[s]}'s {what}: {n}"
                      for what, ns in said.items() for n in ns]
    table = markdown(["task", "demonstrations", "rendered copies", "cached features", "training",
                      "evaluation", "core-hours of these cells"], rows) if rows else "No row measured yet.\n"
    return table + "".join(f"\n{n}\n" for n in notes)


def pixels_ablations() -> str:
    res = pixel_table()
    specs = ["mem0", "mem0:no_key", "mem0:gt_classifier", "mem0:no_memory+no_key"]
    header = ["task", "TMC", *(f"{COLUMN[s]} (cameras)" for s in specs), "chance"]
    rows = _state_rows(res, specs, lambda t: _chance(res, t),
                       lambda g, w=(): _chance_avg(res, g, w))
    rows = [r for r in rows if r[1] == "M(n)" or r[0] == "**average (all)**"][:-1]
    table = markdown(header, _beside_published(rows, specs))
    return (table + "\nIn parentheses: the paper's rate (arXiv "
            f"{published_source('ablations')}), where `no_key` is its w/o Key and "
            "`gt_classifier` its GT classifier.\n" + _footnote(table))


def state_policies() -> str:
    res = load("table_state.json")
    specs = list(POLICY_TABLE)
    published = list(PUBLISHED)
    header = ["task", "TMC", *(f"{COLUMN[s]} (state)" for s in specs),
              *(f"{p} (published, cameras)" for p in published), "chance"]
    rows = _state_rows(res, specs,
                       lambda t: [f"{PUBLISHED[p][t]:g}" for p in published] + _chance(res, t),
                       lambda g, w=(): [_published_avg(p, g, w) for p in published]
                       + _chance_avg(res, g, w))
    table = markdown(header, rows)
    return (table + _published_line() + _without_line(res) + _withdrawn_line(res, specs)
            + _footnote(table))


def _beside_published(rows: list[list[str]], specs: list[str]) -> list[list[str]]:
    """``rows`` (``_state_rows``') with the paper's ablations table beside each measured
    cell, in parentheses: its rate for the task, or its average for the group (as it
    states it, else the mean of its tasks)."""
    names = paper.ablation_names()
    out = []
    for row in rows:
        task = row[0].strip("*")
        group = row[1] if task.startswith("average") else None
        # (the label ``_and`` wrote: "a", "a and b", "a, b and c")
        without = (tuple(re.split(r", | and ", task.split(" without ")[1]))
                   if " without " in task else ())
        row = list(row)
        for k, spec in enumerate(specs):
            if spec not in names or row[2 + k] == "n/a":
                continue
            value = (_published_average("ablations", names[spec], group, without)
                     if group is not None
                     else paper.columns("ablations")[names[spec]].get(task))
            if value is not None:
                row[2 + k] += f" ({value:.1f})" if group is not None else f" ({value:g})"
        out.append(row)
    return out


def state_ablations() -> str:
    res = load("table_state.json")
    specs = list(ABLATION_TABLE)
    header = ["task", "TMC", *(COLUMN[s] for s in specs), "chance"]
    rows = _state_rows(res, specs, lambda t: _chance(res, t),
                       lambda g, w=(): _chance_avg(res, g, w))
    names = paper.ablation_names()
    table = markdown(header, _beside_published(rows, specs))
    ours = [s for s in specs if s in names and s != "mem0"]
    return (table + "\nrmbench's cells read the state observation; in parentheses: the paper's "
            f"rate, read from cameras (arXiv {published_source('ablations')}; "
            f"{paper.rollouts()} rollouts each), where {_and([COLUMN[s] for s in ours])} are its "
            f"{_and([names[s] for s in ours])} ({_and([COLUMN[s] for s in specs if s not in names])}"
            " are not in it); an "
            "average is the paper's where it states one, else the mean of its tasks.\n"
            + _without_line(res) + _footnote(table))


def _and(words: list[str]) -> str:
    return ", ".join(words[:-1]) + " and " + words[-1] if len(words) > 1 else "".join(words)


def _published_line() -> str:
    return (f"\nPublished: arXiv {published_source()} ({paper.rollouts()} rollouts each), "
            "read from cameras; rmbench's columns marked (state) read the state observation, "
            "so they and the paper's are compared across observations.\n")


def state_differences() -> str:
    """Mem-0 minus each ablation per task, in points, with Newcombe's 95% interval of the
    difference (``suite.tables.differences``), * where it excludes zero."""
    res = load("table_state.json")
    specs = list(ABLATION_TABLE)
    # a difference only between cells measured on the same data format and task version; a
    # pair kept apart reads "—" with the marks that kept it apart
    cells, apart = {}, {}
    for t, row in res["cells"].items():
        base = set(_older(t, "mem0", row["mem0"]).strip())
        shown = {s: c for s, c in row.items() if s in specs}
        base_on = measured_on(t, "mem0", row["mem0"])
        cells[t] = {s: c for s, c in shown.items() if measured_on(t, s, c) == base_on}
        for s, c in shown.items():
            if s not in cells[t]:
                marks = "".join(sorted(set(_older(t, s, c).strip()) ^ base)) or _older(t, s, c)
                apart.setdefault(t, {})[s] = f"— {marks.strip()}"
    left_out = "".join(sorted({m for row in apart.values() for v in row.values() for m in v[2:]}))
    # a row measured on an earlier task version says so
    labels = {t: f"{t} ‡" for t, row in res["cells"].items() if "‡" in _older(t, "mem0", row["mem0"])}
    lines = difference_table({"cells": cells, "differences": differences(cells),
                              "chance": res["chance"]}, specs, labels=labels, apart=apart,
                             against_chance=True)
    text = "\n".join(lines) + "\n"
    labelled = "‡" if any("‡" in label for label in labels.values()) else ""
    return (text + _below_chance(res, specs)
            + _footnote(text, "— {mark} where one of the two cells is", left_out)
            + _footnote(text, marks=labelled))


def _below_chance(res: dict, specs: list[str]) -> str:
    """A table naming, per column of ``specs``, the tasks where its cell's whole interval lies
    below the task's chance level, each as its rate against the chance level."""
    rows = []
    for spec in specs:
        below = []
        for task in ordered():
            cell = res["cells"].get(task.name, {}).get(spec)
            level = res["chance"].get(task.name, {}).get("rate")
            if cell and level is not None and Rate.of(cell).ci95[1] < 100 * level:
                below.append(f"{task.name} ({100 * cell['success_rate']:.0f}"
                             f"{_older(task.name, spec, cell)} against {100 * level:.1f})")
        if below:
            rows.append([COLUMN[spec], ", ".join(below)])
    if not rows:
        return ""
    return ("\nBelow chance outside the noise: the cells whose whole interval lies under their "
            "task's chance level (a †, ‡ or § marks the cell itself, as in the tables above).\n\n"
            + markdown(["column", "below chance on (rate against chance, %)"], rows))


def state_seeds() -> str:
    """The cells pooled over training seeds: each seed's rate, the pool's, and how far apart
    the seeds are (the training's noise, which one seed's interval does not cover)."""
    res = load("table_state.json")
    pooled = [(task.name, spec, cell) for task in ordered()
              for spec, cell in res["cells"].get(task.name, {}).items() if "seeds" in cell]
    names = sorted({k for _, _, cell in pooled for k in cell["seeds"]}, key=int)
    rows = []
    for task, spec, cell in pooled:
        pcts = [100 * r["successes"] / r["episodes"] for r in cell["seeds"].values()]
        rows.append([task + _older(task, spec, cell), COLUMN[spec],
                     *(rate(cell["seeds"].get(k)) for k in names), rate(cell),
                     f"{max(pcts) - min(pcts):.0f}"])
    table = markdown(["task", "column", *(f"seed {k}" for k in names), "pooled",
                      "spread (points)"], rows)
    return table + _footnote(table)


def state_reruns() -> str:
    """Recorded training seeds trained again on another machine (``reruns``): the recorded
    run and the re-run, each with the CPU its training ran on, and their difference."""
    res = load("table_state.json")
    rows = []
    for r in res.get("reruns", []):
        first = seed_records(res["cells"][r["task"]][r["column"]])[str(r["seed"])]
        a, b = Rate.of(first), Rate.of(r)
        rows.append([r["task"], COLUMN[r["column"]], r["seed"],
                     f"{rate(first)} ({_trained_on(first)})", f"{rate(r)} ({_trained_on(r)})",
                     format_difference(*difference(b.successes, b.episodes,
                                                   a.successes, a.episodes))])
    if not rows:
        return "No seed has been trained again yet.\n"
    return markdown(["task", "column", "seed", "recorded", "trained again", "difference"], rows)


def _trained_on(record: dict) -> str:
    """The CPU a record's training ran on, as its record names it: 'AMD EPYC, avx2'."""
    machines = (record.get("machines") or {}).get("train") or [{}]
    return ", ".join(str(machines[-1][k]) for k in ("cpu", "isa") if machines[-1].get(k)) or "unrecorded"


def state_failures() -> str:
    """The rows where Mem-0 stays below the published Mem-0: where its failed episodes end,
    by the plan's stage and how (``eval/endings.py``), per training seed whose records keep it."""
    return _failures(load("table_state.json"), below_published=True)


def reference_reproductions() -> str:
    """The published Mem-0 beside users' reproductions of it with the reference code and
    rmbench's Mem-0 (state, pooled over its seeds; cameras where measured), on the rows a
    reproduction reports."""
    doc = load("reference_reproductions.json")
    state, pixels = load("table_state.json")["cells"], pixel_table()["cells"]
    rows = []
    for report in doc["reports"]:
        for task in ordered():
            if task.name not in report["rates"]:
                continue
            cam = pixels.get(task.name, {}).get("mem0")
            rows.append([task.name, f"{PUBLISHED['Mem-0'][task.name]:g}",
                         f"{report['rates'][task.name]:g}",
                         rate(state[task.name]["mem0"])
                         + _older(task.name, "mem0", state[task.name]["mem0"]),
                         rate(cam) + _older(task.name, "mem0", cam) if cam else "—",
                         f"[{report['date']}]({report['source']})"])
    table = markdown(["task", "Mem-0 (published, cameras)", "reproduced with the reference code "
                     "(cameras)", "rmbench Mem-0 (state)", "rmbench Mem-0 (cameras)", "report"],
                     rows)
    return table + _footnote(table)


def pixels_failures() -> str:
    """Every measured camera row: where Mem-0's failed episodes end."""
    return _failures(pixel_table(), below_published=False)


def _ending_kinds(reasons: dict[str, int]) -> dict[str, int]:
    """Failure messages counted by kind (``failure_kind``), most frequent first."""
    kinds: Counter[str] = Counter()
    for message, n in reasons.items():
        kinds[failure_kind(message)] += n
    return dict(sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0])))


def _endings(ends: dict[str, int]) -> str:
    return "; ".join(f"{e} {n}" for e, n in ends.items())


def _failures(res: dict, below_published: bool) -> str:
    rows, unkept = [], []
    for task in ordered():
        cell = res["cells"].get(task.name, {}).get("mem0")
        if cell is None or below_published and (
                100 * cell["successes"] / cell["episodes"] >= PUBLISHED["Mem-0"][task.name]):
            continue
        label = task.name + _older(task.name, "mem0", cell)
        mem0 = f"{rate(cell)} ({PUBLISHED['Mem-0'][task.name]:g})"
        for seed, r in seed_records(cell).items():
            if "failed_at" in r:  # ({} where every episode succeeded)
                for stage, ends in r["failed_at"].items():
                    rows.append([label, mem0, seed, stage or "(none)", sum(ends.values()),
                                 _endings(ends)])
                continue
            if label not in unkept:  # evaluated before the records kept the stage
                unkept.append(label)
            if r.get("failure_reasons"):
                ends = _ending_kinds(r["failure_reasons"])
                rows.append([label, mem0, seed, "(not kept)", sum(ends.values()), _endings(ends)])
    table = markdown(["task", "Mem-0 (published in parentheses)", "seed",
                      "stage the episode ended in",
                      "failed episodes", "how they ended"], rows)
    note = (f"\n(not kept): {_and(unkept)} evaluated before the records kept the stage a failed "
            "episode ended in; how they ended is from the evaluation's failure messages where "
            "they are kept.\n") if unkept else ""
    return table + note + _footnote(table + note)


def mn_recipe() -> str:
    """Mem-0's M(n) recipe candidates (``benchmarks/mn_recipe.py``), the first the table's
    recipe on format 1 data: each cell a rate with its interval, and for Mem-0 where its
    classifier declared the subtask ends against the simulator (``rmbench boundaries``)."""
    doc = load("mn_recipe.json")
    tasks = [t.name for t in ordered() if any(t.name in c["cells"] for c in doc["candidates"])]
    specs = ["mem0", "mem0:no_key", "mem0:gt_classifier"]
    rows = []
    for cand in doc["candidates"]:
        for task in tasks:
            row = cand["cells"].get(task)
            if row is None:
                continue
            mem0 = row.get("mem0") or {}
            # a cell pooled over training seeds: each seed's ends, added up
            runs = [c.get("boundaries") for c in seed_records(mem0).values()]
            verdicts = ("on_time", "early", "late", "missed", "false")
            ends = ("—" if not all(runs) else
                    "/".join(str(sum(r[v] for r in runs)) for v in verdicts))
            version = "".join(_older(task, s, row.get(s)).strip("† ") for s in specs)
            rows.append([cand["name"], task + (" ‡" if version else ""),
                         *(rate(row.get(s)) for s in specs), ends])
    table = markdown(["recipe", "task", "Mem-0", "`no_key`", "`gt_classifier`",
                      "Mem-0's ends: on time/early/late/missed/false"], rows)
    return table + _footnote(table)


def memory_probe() -> str:
    """Each measured memory probe (``benchmarks/memory_probe.py``): the policy's rate without
    and with its memory reset at the aliasing moment, the drop, and its memoryless control."""
    rows = []
    for path in sorted(RESULTS.glob("memory_probe_*.json")):
        r = json.loads(path.read_text())
        ref, d = r["reference"], r["with_minus_reference"]
        drop = format_difference(r["drop"], *r["drop_ci95"])
        rows.append([r["task"], r["probe"], rate(r["without"] | {"episodes": r["episodes"]}),
                     rate(r["with"] | {"episodes": r["episodes"]}), drop,
                     f"{COLUMN.get(ref['cell'], ref['cell'])} {rate(ref)}",
                     format_difference(d["difference"], *d["ci95"]), f"`{path.name}`"])
    return markdown(["task", "reset at", "without", "with", "drop", "memoryless control",
                     "with − control", "results"], rows)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" + ("" if n == 1 else "s")


def _conditions(piece: dict) -> list[str]:
    """What a wall's piece was measured under, as its record keeps it (``conditions``): the
    torch threads or workers, the jobs beside it, what else the wall holds, a note."""
    out = []
    if piece.get("threads") is not None:
        out.append(_plural(piece["threads"], "torch thread"))
    if piece.get("workers") is not None:
        out.append(_plural(piece["workers"], "worker"))
    if piece.get("jobs_beside") == 0:
        out.append("alone")
    elif piece.get("beside"):
        out.append(f"beside {piece['beside']}")
    elif piece.get("jobs_beside"):
        out.append(f"beside {_plural(piece['jobs_beside'], 'other job')}")
    if piece.get("includes"):
        out.append(f"including {piece['includes']}")
    if piece.get("note"):
        out.append(piece["note"])
    return out


def _wall(cell: dict, stage: str, machines: dict[str, dict]) -> str:
    """A training's or evaluation's wall with its conditions (``conditions`` of the record):
    '43.5 min (2 torch threads, beside ...)'; a training run in pieces (another machine,
    another run) piece by piece, each to the step it reached, with its own wall where kept.
    A machine is named where it is not the page's one (``machines``' first) or the wall has
    pieces on several."""
    total = cell.get(f"{stage}_wall_s")
    pieces = cell.get("conditions", {}).get(stage) or [{}]
    default = next(iter(machines), None)
    several = len({p.get("machine") for p in pieces}) > 1

    def where(p: dict) -> list[str]:
        m = p.get("machine")
        return [f"on {machines[m]['label']}"] if m and (several or m != default) else []

    if len(pieces) == 1:
        conds = _conditions(pieces[0])
        return " ".join([minutes(total), *where(pieces[0])]) + (f" ({', '.join(conds)})" if conds else "")
    start = cell.get(f"{stage}_wall_from_step") or 0
    parts = []
    for p in pieces:
        # a piece before the step the wall is timed from: its wall was not kept
        conds = _conditions(p) + (["not timed"] if p["steps"][1] <= start else [])
        words = ([minutes(p["wall_s"])] if p.get("wall_s") is not None else []) + where(p)
        parts.append(" ".join([*words, f"to step {p['steps'][1]:,}"])
                     + (f" ({', '.join(conds)})" if conds else ""))
    return (minutes(total) + (f" from step {start:,}" if start else "") + ": " + "; ".join(parts))


def _record_rows(cells: dict[str, dict[str, dict]], machines: dict[str, dict] | None = None,
                 marks: bool = True) -> list[list[str]]:
    """Each cell's record; ``marks``: a cell on an older task or data marked as the tables
    mark it (a superseded group says instead why its cells no longer stand)."""
    machines = load("table_state.json")["machines"] if machines is None else machines
    rows = []
    for task in ordered():
        for spec, c in cells.get(task.name, {}).items():
            rec = c.get("record", {})
            progress = f"{c['mean_progress']:.3f}" + (f" ({rec['progress']})" if "progress" in rec else "")
            endings = ", ".join(f"{k} {v}" for k, v in c["endings"].items() if v)
            # a cell pooled over training seeds: each seed's success and walls, each with the
            # conditions its record keeps
            seeds = seed_records(c)
            named = len(seeds) > 1
            success = f"{c['successes']}/{c['episodes']}" + (
                " (seeds " + ", ".join(f"{s}: {r['successes']}" for s, r in seeds.items()) + ")"
                if named else "")
            train = ("(Mem-0's checkpoint)" if spec == "mem0:gt_classifier" and not named
                     else "(Mem-0's checkpoints)" if spec == "mem0:gt_classifier"
                     else " + ".join(_train_wall(r, spec, s, named, machines)
                                     for s, r in seeds.items()))
            failures = rec.get("failures") or "; ".join(
                f"{why} {n}" for why, n in list(c["failure_reasons"].items())[:4])
            evals = " + ".join(_seed_wall(r, "eval", s, named, machines) for s, r in seeds.items())
            rows.append([task.name + (_older(task.name, spec, c) if marks else ""), f"`{spec}`",
                         success, progress,
                         endings, failures, train, evals])
    return rows


def _seed_wall(cell: dict, stage: str, seed: str, named: bool, machines: dict[str, dict]) -> str:
    """One seed's training or evaluation wall with its conditions."""
    wall = _wall(cell, stage, machines)
    return f"{wall} (seed {seed})" if named else wall


def _train_wall(cell: dict, spec: str, seed: str, named: bool,
                machines: dict[str, dict]) -> str:
    """One training's wall; a planner refit's is its executor's, the refit said so."""
    wall = _seed_wall(cell, "train", seed, False, machines)
    if "planner_refit" in cell:
        wall += " (the executor), then its planner refit (`benchmarks/planner_refit.py`)"
    if "executor_of" in cell:
        wall += f" (its planner's fit; its executor is {COLUMN[executor_spec(spec)]}'s)"
    return f"{wall} (seed {seed})" if named else wall


RECORD_HEADER = ["task", "policy", "success", "progress", "endings", "most frequent failures",
                 "train wall", "eval wall"]


def state_records() -> str:
    table = markdown(RECORD_HEADER, _record_rows(load("table_state.json")["cells"]))
    return table + _footnote(table)


def state_hardware() -> str:
    """The machines the records' walls name, and the conditions a wall was measured under
    where its record names none (``machines`` and ``wall_defaults`` of the results)."""
    res = load("table_state.json")
    machines, defaults = res["machines"], res["wall_defaults"]

    def what(m: dict) -> str:
        kind = (f"an {m['gpu']} GPU" if m["gpu"] else
                f"an {m['cpu']} machine with {m['cores']} CPU cores")
        return kind + (f" ({m['about']})" if m.get("about") else "")

    train, evals = defaults["train"], defaults["eval"]
    return ("Machines: " + "; ".join(f"**{m['label']}**, {what(m)}" for m in machines.values())
            + f". Every stage (collection, training, evaluation) ran on "
            f"{machines[train['machine']]['label']}, {defaults['jobs']} jobs at a time, unless "
            f"its record says otherwise: a training with {_plural(train['threads'], 'torch thread')}"
            f" beside {_plural(train['jobs_beside'], 'other job')}, an evaluation with "
            f"{_plural(evals['workers'], 'worker')}.\n")


def state_superseded() -> str:
    """The cells a re-run replaced, each group under why it no longer stands."""
    res = load("table_state.json")
    out = []
    for group in res["superseded"]:
        out.append(f"{group['why'][0].upper()}{group['why'][1:]}:\n\n"
                   + markdown(RECORD_HEADER, _record_rows(group["cells"], res["machines"],
                                                             marks=False)))
    return "\n".join(out)


def state_cost() -> str:
    """The table's wall time, summed over what the records kept (``gt_classifier`` evaluates
    Mem-0's checkpoint and trains nothing)."""
    res = load("table_state.json")
    # a cell pooled over training seeds is one training and one evaluation per seed
    cells = [(s, r) for row in res["cells"].values() for s, c in row.items()
             for r in seed_records(c).values()]
    # a no_key cell made beside Mem-0's executor fits its planner alone
    fits = [c for s, c in cells if s != "mem0:gt_classifier" and "executor_of" in c]
    trained = [c for s, c in cells if s != "mem0:gt_classifier" and "executor_of" not in c]
    kept = [c["train_wall_s"] for c in trained if c["train_wall_s"] is not None]
    partial = sum(1 for c in trained if c["train_wall_from_step"])
    gpu = sum(1 for c in trained if any(m.get("gpu") for m in c["machines"]["train"]))
    evals = [c["eval_wall_s"] for _, c in cells if c["eval_wall_s"] is not None]
    rows = [["trainings (18,000 steps each)", str(len(trained)),
             f"{sum(kept) / 3600:.1f} h kept (CPU and GPU pieces together)"],
            ["of them timed from a resumed step (the earlier pieces' walls not kept)", str(partial), ""],
            ["of them wholly or partly on a GPU", str(gpu), ""],
            *([["planners fitted beside Mem-0's executor (`no_key`)", str(len(fits)),
                f"{sum(c['train_wall_s'] or 0 for c in fits) / 3600:.1f} h"]] if fits else []),
            ["evaluations (100 episodes each)", str(len(evals)), f"{sum(evals) / 3600:.1f} h"]]
    return markdown(["what", "count", "wall time"], rows)


def _one_eval(cell: dict | None) -> float | None:
    """One evaluation's wall on one worker: a cell pooled over training seeds ran one per
    seed, and the fastest is the one least slowed by the jobs beside it (a seed its record
    says ran on more workers is left out); None for a cell not in the table."""
    if cell is None:
        return None
    walls = [r["eval_wall_s"] for r in seed_records(cell).values()
             if all((c.get("workers") or 1) == 1
                    for c in (r.get("conditions") or {}).get("eval", []))]
    return None if not walls or None in walls else min(walls)


def eval_walls() -> str:
    """What 100 episodes of a task take to evaluate: the state table's cells, one worker."""
    res = load("table_state.json")
    rows = []
    for task in ordered():
        row = res["cells"][task.name]
        rows.append([task.name, task.step_limit,
                     *(minutes(_one_eval(row.get(s))) for s in ("mem0", "dp", "act"))])
    return markdown(["task", "step limit", "Mem-0", "DP", "ACT"], rows)


# ------------------------------------------------------------------ put_back_block, state
# the milestones of the recipe search, in order; each row shows what its --set changed
STATE_RUNS = ["learning_state_put_back_block_white0.02.json",
              "learning_state_put_back_block_no_state_noise.json",
              "learning_state_put_back_block.json",
              "learning_state_put_back_block_mats0.02.json",
              "learning_state_put_back_block_grasp_pose.json",
              "learning_state_put_back_block_layout_copies.json"]


def _recipe_change(before: dict | None, run: dict) -> str:
    """What ``run``'s recipe changed from ``before``'s: its new or changed ``--set`` items and
    its steps if they differ (the whole recipe for the first row)."""
    old = dict(x.split("=", 1) for x in before["set"]) if before else {}
    new = dict(x.split("=", 1) for x in run["set"])
    parts = [f"`{k}={v}`" for k, v in new.items() if old.get(k) != v]
    parts += [f"without `{k}`" for k in old if k not in new]
    if before is None or before["steps"] != run["steps"]:
        parts.append(f"{run['steps']:,} steps")
    return ("" if before is None else "+ ") + ", ".join(parts)


def learning_state() -> str:
    specs = ["mem0", "mem0:no_memory", "mem0:no_anchor", "mem0:no_sliding"]
    rows, before = [], None
    for name in STATE_RUNS:
        d = load(name)
        p = d["policies"]
        rows.append([_recipe_change(before, d), f"`{Path(name).stem}`", *(rate(p.get(s)) for s in specs),
                     minutes(p["mem0"].get("train_wall_s"))])
        before = d
    return markdown(["recipe (`--set`; each row changes the one above)", "results JSON",
                     *(COLUMN[s] for s in specs), "Mem-0 train wall"], rows)


def learning_state_more() -> str:
    val = load("learning_state_put_back_block_layout_copies_seed1.json")["policies"]
    more = load("learning_state_put_back_block_200demos.json")["policies"]
    base = load("learning_state_put_back_block.json")["policies"]
    rows = [["the recipe, second block of held-out layouts (seeds from 200000)", rate(val["mem0"]), "—"],
            ["1 cm noise on every position, 50 demonstrations", rate(base["mem0"]),
             rate(base["mem0:no_memory"])],
            ["the same, 200 demonstrations", rate(more["mem0"]), rate(more["mem0:no_memory"])]]
    return markdown(["run", "Mem-0", "`no_memory`"], rows)


# ------------------------------------------------------------------ put_back_block, pixels
PIXEL_RUNS = [
    ("learning_pixels_put_back_block_backbone_s8.json", "frozen EfficientNet-Lite0, stride 8"),
    ("learning_pixels_put_back_block_backbone_s16.json", "stride 16"),
    ("learning_pixels_put_back_block_layout_copies_s16.json", "stride 16, 8 rendered layout copies"),
    ("learning_pixels_put_back_block_layout_copies_s16_54k.json", "the same, 54,000 steps"),
    ("learning_pixels_put_back_block_layout_copies_s16_90k.json", "the same, 90,000 steps"),
]


def learning_pixels() -> str:
    specs = ["mem0", "mem0:no_memory", "mem0:no_anchor", "mem0:no_sliding", "dp", "act"]
    rows = []
    for name, run in PIXEL_RUNS:
        d = load(name)
        p = d["policies"]
        steps = p["mem0"].get("steps") or d.get("steps") or int(
            re.search(r"--steps (\d+)", d["train_command"]).group(1))
        rows.append([run, f"{steps:,}", *(rate(p.get(s)) for s in specs),
                     minutes(p["mem0"].get("train_wall_s")),
                     f"{d['machine'].get('torch_threads', '—')}"])
    return markdown(["run", "Mem-0 steps", *(COLUMN[s] for s in specs), "Mem-0 train wall",
                     "torch threads"], rows)


# ------------------------------------------------------------------ experts, aliasing, speed
def _robustness_cells() -> dict[tuple[str, str, float], dict]:
    cells = {}
    for path in sorted((RESULTS / "robustness").glob("*.json")):
        c = json.loads(path.read_text())
        cells[(c["task"], c["kind"], float(c["sigma"]))] = c
    return cells


ROBUSTNESS_COLUMNS = [("white", 0.0), ("smooth", 0.01), ("smooth", 0.02), ("smooth", 0.03),
                      ("offset", 0.02), ("offset", 0.03), ("white", 0.01), ("white", 0.02),
                      ("white", 0.03)]


def _expert_mark(task: type, cell: dict) -> str:
    """' ‡' for an expert cell run on an earlier version of its task."""
    return f" {_version_mark(task, cell)}".rstrip()


def robustness() -> str:
    cells = _robustness_cells()
    rows = []
    for task in ordered():
        row = [cells.get((task.name, k, s)) for k, s in ROBUSTNESS_COLUMNS]
        rows.append([task.name] + [f"{rate(c)}{_expert_mark(task, c)} ({c['episodes']})" if c
                                   else "-" for c in row])
    raised = sum(c["expert_raised"] for c in cells.values())
    episodes = sum(c["episodes"] for c in cells.values())
    wall = sum(c["wall_s"] for c in cells.values())
    head = [f"{k} {s:g}" if s else "no noise" for k, s in ROBUSTNESS_COLUMNS]
    table = markdown(["task", *head], rows)
    beyond = [key for key in cells if key[1:] not in ROBUSTNESS_COLUMNS]
    levels = sorted({f"{k} {s:g}" for _, k, s in beyond})
    extra = (f" ({len(beyond)} of them at a level the table leaves out: {_and(levels)})"
             if beyond else "")
    return (table + f"\nEpisodes: {episodes}, in which an expert raised: {raised}; wall time of "
            f"the {len(cells)} cells{extra}: {wall / 3600:.1f} h. In parentheses: episodes per "
            "cell.\n" + _footnote(table))


def robustness_margin() -> str:
    cells = _robustness_cells()
    rows = []
    for task in ordered():
        c = cells[(task.name, "white", 0.0)]
        longest = c["longest_success_steps"]
        rows.append([task.name + _expert_mark(task, c), f"{c['successes']}/{c['episodes']}",
                     f"{longest} steps", c["step_limit"], f"{c['step_limit'] / longest:.2f}x"])
    table = markdown(["task", "success", "longest successful episode", "step limit", "margin"],
                     rows)
    return table + _footnote(table)


def robustness_failures() -> str:
    cells = _robustness_cells()
    lines = []
    for task in ordered():
        for kind, sigma in ROBUSTNESS_COLUMNS:
            c = cells.get((task.name, kind, sigma))
            if c is None or not c["failures"]:
                continue
            # by kind: the coordinates in a failure message make every message unique
            merged = list(_ending_kinds(c["failures"]).items())
            ends = "; ".join(f"{r} ({n})" for r, n in merged[:4])
            lines.append(f"- {task.name}{_expert_mark(task, c)}, {kind} {sigma:g}: {ends}")
    text = "\n".join(lines) + "\n"
    return text + _footnote(text)


def aliasing() -> str:
    """Every aliasing pair at the main seed: its moments, the pixel distances (whole frame and
    scene alone), the arms'."""
    d = load("aliasing.json")
    rows = [[t["task"], t["tmc"], t["pair"], f"{t['steps'][0]} / {t['steps'][1]}",
             " / ".join(t["next_subtasks"]), f"{t['pixel_distance']:.3f}",
             f"{t['unrelated_distance']:.3f}", f"{t['ratio']:.3f}", f"{t['scene_ratio']:.3f}",
             f"{t['arm_gap']:.4f}", f"{t['gripper_gap']:.4f}"]
            for t in d["tasks"]]
    return markdown(["task", "TMC", "pair", "steps", "next subtask at each", "pixel distance",
                     "unrelated layout", "ratio", "scene ratio", "arms' joint gap (rad)",
                     "grippers' gap"], rows)


def aliasing_seeds() -> str:
    """Each aliasing pair measured from more seeds: the worst of each measure."""
    d = load("aliasing.json")
    rows = []
    for t in ordered():
        runs = d.get("more_seeds", {}).get(t.name, [])
        for pair in sorted({r["pair"] for r in runs}):
            of = [r for r in runs if r["pair"] == pair]
            differs = all(r["next_subtasks"][0] != r["next_subtasks"][1]
                          or r["action_divergence"] > 0.1 for r in of)
            rows.append([t.name, t.tmc, pair, ", ".join(str(r["seed"]) for r in of),
                         f"{max(r['ratio'] for r in of):.3f}",
                         f"{max(r['scene_ratio'] for r in of):.3f}",
                         f"{max(r['state_ratio_core'] for r in of):.4f}",
                         f"{max(r['arm_gap'] for r in of):.4f}",
                         f"{max(r['gripper_gap'] for r in of):.4f}",
                         "yes" if differs else "no"])
    return markdown(["task", "TMC", "pair", "seeds", "pixel ratio (worst)",
                     "scene ratio (worst)", "state ratio, core (worst)",
                     "arms' joint gap (rad, worst)", "grippers' gap (worst)",
                     "the expert goes on differently on each"], rows)


def speed() -> str:
    sim, collect = load("sim_speed.json"), load("collect_speed.json")
    ev, pol = load("eval_speed.json"), load("policy_speed.json")
    train = load("train_speed.json")
    smoke = next(r for r in ev["rows"] if "video" in r["run"])
    round_ = next(r for r in ev["rows"] if "each task" in r["run"])
    cams = f"{len(sim['cameras'])} cameras {sim['resolution']}"
    two = next(r for r in collect["rows"] if r["workers"] == 2)
    one = next(r for r in collect["rows"] if r["workers"] == 1 and "search" in r["run"])
    direct = next(r for r in collect["rows"] if "direct" in r["run"])
    p = pol["policies"]
    rows = [
        [f"env steps/s, {cams} ({sim['gl_backend'].upper()})", f"{sim['env_steps_per_s_rendered']}",
         "`benchmarks/sim_speed.py`"],
        ["bare MuJoCo render of the same cameras, sets/s",
         f"{sim['bare_render_sets_per_s']} (env / bare {sim['ratio_env_to_bare_render']:.2f})", "same run"],
        ["env steps/s, physics only", f"{sim['env_steps_per_s_physics_only']:.0f}", "same run"],
        [f"50 {collect['task']} demonstrations, {collect['cameras']} cameras "
         f"{collect['resolution']}, 2 workers",
         f"{collect['time_for_50_demos_s']:.0f} s ({two['demos_per_min']:.1f} demos/min; "
         f"{one['demos_per_min']:.1f} with 1 worker)", "`benchmarks/collect_speed.py`"],
        ["recorder overhead vs the expert with cameras, nothing saved",
         f"{one['overhead']:.2f}x (seed search + replay), {direct['overhead']:.2f}x (direct)", "same run"],
        ["dataset size per demonstration",
         f"{one['mb_per_demo']:.2f} MB ({one['frames_per_demo']:.0f} frames)", "same run"],
        ["evaluation harness vs bare env, `noop` policy", f"{ev['harness_vs_bare']:.2f}x",
         "`benchmarks/eval_speed.py`"],
        ["one `noop` episode with its video (the first evaluation's default)",
         f"{smoke['wall_s']:.1f} s ({smoke['steps']} steps)", "same run"],
        ["a round of the nine tasks, `noop` (every episode to its step limit), 1 worker",
         f"{round_['wall_s']:.0f} s ({round_['steps']:,} steps)", "same run"],
        [f"closed loop, {pol['inference_threads']} thread, {len(pol['cameras'])} cameras, Hz",
         f"Mem-0 {p['mem0']['hz']} (planner {p['mem0']['planner_ms']} ms), DP {p['dp']['hz']}, "
         f"ACT {p['act']['hz']}", "`benchmarks/policy_speed.py`"],
        [f"training steps/s, {pol['training_threads']} threads, batch {pol['batch_size']}",
         f"Mem-0 {p['mem0']['train_steps_per_s']}, DP {p['dp']['train_steps_per_s']}, "
         f"ACT {p['act']['train_steps_per_s']}", "same run"],
        [f"Mem-0 training step on {train['task']}, the state recipe, batch {train['batch']}, "
         f"1 thread: this tree against {train['base']['commit'][:7]}",
         f"{min(train['this']['cpu_ms_per_step']):.0f} ms of CPU against "
         f"{min(train['base']['cpu_ms_per_step']):.0f} ({train['speedup']:.2f}x); loss curves "
         + ("identical" if train["curves"]["identical"] else "differ"),
         "`benchmarks/train_speed.py`"],
    ]
    rows += [eval_ab_row(load(f.name)) for f in sorted(RESULTS.glob("eval_ab_speed*.json"))]
    fold = load("backbone_fold.json")
    cpu = fold["cpu_ms_per_frame"]
    rows.append([f"the frozen EfficientNet-Lite0 to stride {fold['stride']}, "
                 f"{fold['image_size'][0]}x{fold['image_size'][1]} frames, 1 thread: folded "
                 "(as the policies run it) against the network as written",
                 f"{cpu['folded']['batch8']:.1f} ms of CPU a frame against "
                 f"{cpu['network']['batch8']:.1f} at batch 8 ({fold['speedup']['batch8']:.2f}x), "
                 f"{cpu['folded']['batch1']:.1f} against {cpu['network']['batch1']:.1f} at batch 1 "
                 f"({fold['speedup']['batch1']:.2f}x); features within "
                 f"{fold['max_abs_difference']:.0e}", "`benchmarks/backbone_fold.py`"])
    prep = load("frame_prep.json")
    now, before = prep["cpu_ms_per_frame"]["now"], prep["cpu_ms_per_frame"]["before"]
    rows.append([f"a recorded {prep['task']} camera ({prep['frames']} frames, {prep['source']}) "
                 f"decoded and resized to {prep['size'][0]}x{prep['size'][1]} for the feature "
                 "cache, 1 thread: into one array, 32 frames a resize pass, against a stacked "
                 "list and the episode in one pass",
                 f"{now['both']:.2f} ms of CPU a frame against {before['both']:.2f} "
                 f"({prep['speedup']['both']:.2f}x; resize {prep['speedup']['resize']:.2f}x); "
                 + ("the same bytes" if all(prep["identical"].values()) else "bytes differ"),
                 "`benchmarks/frame_prep.py`"])
    poses = load("pose_stats_speed.json")
    rows.append([f"the grasp poses a state training reads when it starts ({poses['dataset']}: "
                 f"{poses['episodes']} demonstrations and {poses['copies_kept']} layout copies, "
                 f"{poses['rows']:,} joint states), 1 thread: both arms in one kinematics pass "
                 "against one arm a call",
                 f"{poses['cpu_s']['now']:.1f} s of CPU against {poses['cpu_s']['before']:.1f} "
                 f"({poses['speedup']:.2f}x); "
                 + ("the same bytes" if poses["identical"] else "bytes differ"),
                 "`benchmarks/pose_stats_speed.py`"])
    mm = load("matmul_rate.json")
    rows.append([f"float32 matmul, {mm['size']}x{mm['size']}, GFLOP/s by torch threads "
                 "(the yardstick of training walls across machines)",
                 ", ".join(f"{n} thread{'s' if n != '1' else ''}: {g}"
                           for n, g in mm["gflops"].items()) + f" ({mm['machine']['isa']})",
                 "`benchmarks/matmul_rate.py`"])
    return markdown(["what", "figure", "command"], rows)


def eval_ab_row(ab: dict) -> list[str]:
    """A row of ``benchmarks/eval_ab_speed.py``'s: a batched evaluation against one at a time."""
    ck = ab["checkpoint"]
    return [f"an evaluation of {ab['episodes']} episodes by a state Mem-0 on {ab['task']} (the "
            f"state recipe's settings, {ck['demos']} demonstrations, {ck['step']:,} steps), "
            f"1 worker: batch "
            f"{ab['this']['batch']} against one episode at a time ({ab['base']['commit'][:7]})",
            f"{min(ab['this']['cpu_s']):.1f} s of CPU against {min(ab['base']['cpu_s']):.1f} "
            f"({ab['cpu_ratio']:.2f}x less): {ab['this']['cpu_ms_per_step']:.1f} and "
            f"{ab['base']['cpu_ms_per_step']:.1f} ms a step, of which the env and harness alone "
            f"(`noop`) {ab['env_only']['cpu_ms_per_step']:.1f}; success {ab['this']['success']} "
            f"and {ab['base']['success']} of {ab['episodes']}", "`benchmarks/eval_ab_speed.py`"]


def policy_speed() -> str:
    pol = load("policy_speed.json")
    rows = []
    for name, p in pol["policies"].items():
        rows.append([COLUMN[name], f"{p['step_ms']:.1f}", f"{p['hz']}", f"{p['params'] / 1e6:.1f} M",
                     f"{p['planner_ms']} ms" if "planner_ms" in p else "—",
                     f"{p['memory_store_floats']:,}" if "memory_store_floats" in p else "—",
                     f"{p['rss_growth_mb']} MB", f"{p['train_steps_per_s']}"])
    return markdown(["policy", "closed-loop step (ms)", "Hz", "parameters", "planner call (8 keys)",
                     "memory store (floats)", f"RSS growth over {pol['steps']} steps",
                     f"training steps/s ({pol['training_threads']} threads, batch {pol['batch_size']})"],
                    rows)


def backbone_speed() -> str:
    """Mem-0's training on cached frozen-backbone features against on frames with its CNNs."""
    rows = []
    for name, label in (("policy_speed_backbone.json", "default head"),
                        ("policy_speed_backbone_recipe_b128.json", "the state recipe's head")):
        d = load(name)
        res = d["results"]
        cnn = res["cnn"]["mem0"]["train_steps_per_s"]
        for case in ("stride8", "stride16", "stride32"):
            r = res[case]
            rows.append([f"{label}, batch {d['batch_size']}", case.replace("stride", "stride "),
                         f"{r['mem0']['train_steps_per_s']} ({r['mem0']['train_steps_per_s'] / cnn:.1f}x "
                         f"of {cnn} on frames)", f"{r['mem0']['step_ms']:.1f}", f"{r['dp']['step_ms']:.1f}",
                         f"{r['act']['step_ms']:.1f}", f"{r['encode_frames_per_s']:.0f}"])
    return markdown(["Mem-0", "feature map", "training steps/s, 1 thread", "Mem-0 step (ms)",
                     "DP step (ms)", "ACT step (ms)", "cache: frames encoded/s"], rows)


TABLES: dict[str, Callable[[], str]] = {
    "tasks": tasks,
    "readme-results": readme_results, "state-policies": state_policies,
    "pixels-policies": pixels_policies, "pixels-ablations": pixels_ablations,
    "pixels-cost": pixels_cost, "pixels-failures": pixels_failures,
    "validation-probes": validation_probes,
    "pixels-validation-probes": functools.partial(validation_probes, "pixels"),
    "pixels-planner-keys": planner_keys_pixels,
    "observe-grasps": observe_grasps,
    "put-back-loops": put_back_loops, "render-size": render_size,
    "state-ablations": state_ablations, "state-differences": state_differences,
    "state-seeds": state_seeds, "state-reruns": state_reruns, "state-failures": state_failures,
    "reference-reproductions": reference_reproductions,
    "mn-recipe": mn_recipe, "memory-probe": memory_probe,
    "state-records": state_records, "state-hardware": state_hardware,
    "state-superseded": state_superseded, "state-cost": state_cost, "eval-walls": eval_walls,
    "learning-state": learning_state, "learning-state-more": learning_state_more,
    "learning-pixels": learning_pixels, "robustness": robustness,
    "robustness-margin": robustness_margin, "robustness-failures": robustness_failures,
    "aliasing": aliasing, "aliasing-seeds": aliasing_seeds, "speed": speed, "policy-speed": policy_speed,
    "backbone-speed": backbone_speed,
}


def render(text: str, path: Path) -> str:
    """``text`` with every marked table rendered; an unknown name is a ValueError."""
    def one(m: re.Match) -> str:
        name = m.group(2)
        if name not in TABLES:
            raise ValueError(f"{path}: unknown table {name!r} (known: {', '.join(TABLES)})")
        return m.group(1) + TABLES[name]() + m.group(4)
    return MARKER.sub(one, text)


def stale(paths: list[Path] = DOCS) -> list[str]:
    """'PATH: NAME' for every table whose committed text differs from its rendering."""
    out = []
    for path in paths:
        text = path.read_text()
        for m in MARKER.finditer(text):
            if m.group(2) in TABLES and TABLES[m.group(2)]() != m.group(3):
                out.append(f"{path.relative_to(ROOT)}: {m.group(2)}")
        render(text, path)  # raises on an unknown name
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--check", action="store_true", help="only list the tables that differ")
    args = p.parse_args(argv)
    if args.check:
        diff = stale()
        for line in diff:
            print(f"stale table: {line} (python scripts/render_docs.py rewrites it)")
        return 1 if diff else 0
    for path in DOCS:
        text = path.read_text()
        new = render(text, path)
        if new != text:
            write_atomic(path, new.encode())
            print(f"rewrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
