"""A table's results: ``table.json`` (every cell's row, the plan, wall times, the machine) and
``table.md``, the benchmark's two tables (policies beside the paper's main results table,
Mem-0's ablations beside its ablations table, task by task: ``published.py``) with M(1) and
M(n) groups and averages. A cell not evaluated yet reads "—" and keeps its group's average
empty. Every success rate carries its Wilson 95% interval (``success_ci95`` in each cell of
table.json, "[low, high]" in table.md); a column trained with several seeds is one cell,
their episodes pooled, each seed's row in it and Mem-0 against each other column of its row
carries the difference's (``differences``): whether two cells differ by more than the
episodes' noise."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Any

from rmbench.eval.chance import chance
from rmbench.eval.intervals import difference, format_difference, outside_noise, signed
from rmbench.eval.published import ablation_names
from rmbench.eval.report import PUBLISHED, Rate, format_cell, published_source, table
from rmbench.files import read_json_or, write_atomic, write_json
from rmbench.machine import describe, short
from rmbench.suite.cell_rows import cell_row, pooled_row
from rmbench.suite.clock import DATA_WALLS, TIMING
from rmbench.suite.plan import Plan, applies, split_seed
from rmbench.suite.progress import column
from rmbench.tasks import get_task

POLICY_TABLE = ("mem0", "mem0:no_memory", "dp", "act")
ABLATION_TABLE = ("mem0", "mem0:no_anchor", "mem0:no_sliding", "mem0:no_memory", "mem0:no_key",
                  "mem0:gt_classifier", "mem0:no_memory+no_key")


def results(plan: Plan, out: Path, command: str = "",
            failed: dict[str, str] | None = None) -> dict[str, Any]:
    """Every cell's row (None where not evaluated) with the plan, the failures of the last
    run, the wall times (per model in each row; the table's summed over its runs) and the
    machine."""
    seeds: dict[str, dict[str, dict[int, Any]]] = {}
    for task, spec in plan.cells():
        base, seed = split_seed(spec)
        seeds.setdefault(task, {}).setdefault(base, {})[seed] = cell_row(plan, out, task, spec)
    cells = {task: {base: pooled_row(rows) for base, rows in columns.items()}
             for task, columns in seeds.items()}
    timing = {t: read_json_or(Path(out) / t / TIMING, {}) for t in cells}
    data = {t: {k: timing[t][k] for k in DATA_WALLS if timing[t].get(k) is not None}
            for t in cells}
    levels = {t: asdict(chance(t)) for t in cells}
    return {"command": command, "plan": plan.to_dict(), "cells": cells, "chance": levels,
            "differences": differences(cells), "failed": failed or {},
            "wall_s": {"table": read_json_or(Path(out) / TIMING, {}).get("table_wall_s"),
                       "data": data},
            "machine": describe()}


def differences(cells: dict[str, dict[str, Any]], base: str = "mem0") -> dict[str, dict]:
    """Per task, ``base``'s success rate minus each other evaluated column's, as fractions,
    with Newcombe's 95% interval and whether it excludes zero (the cells' episodes are
    independent draws of the same seeds' layouts: the interval is, if anything, wide)."""
    out: dict[str, dict] = {}
    for task, row in cells.items():
        if not row.get(base):
            continue
        a = Rate.of(row[base])
        for spec, cell in row.items():
            if spec == base or not cell:
                continue
            b = Rate.of(cell)
            d, low, high = difference(a.successes, a.episodes, b.successes, b.episodes)
            # (unrounded: a table rounds once, to whole points; 4 decimals first moved an
            # end such as 0.654976 to 0.6550 and so to 66 where it is 65)
            out.setdefault(task, {})[spec] = {
                "difference": d, "ci95": [low, high],
                "outside_noise": outside_noise(a.successes, a.episodes, b.successes, b.episodes)}
    return out


def _columns(res: dict[str, Any], specs: tuple[str, ...] | None = None) -> list[str]:
    """The table's columns among ``specs`` (all, in the plan's order, if None): one per
    policy spec, whatever its training seeds."""
    planned = list(dict.fromkeys(split_seed(p)[0] for p in res["plan"]["policies"]))
    return planned if specs is None else [s for s in specs if s in planned]


def _markdown_table(res: dict[str, Any], specs: list[str], published: list[str] = (),
                    metric: str = "success_rate", intervals: bool = False,
                    published_table: str = "main") -> list[str]:
    """``eval.report.table`` over the plan's tasks, one column per spec: "—" where a cell is
    not evaluated yet, "n/a" where the column has no cell (no_key on an M(1) task, and so in
    the average over both groups) or the paper gives no number. ``intervals``: each success rate
    "value [low, high]". ``published``: columns of the paper's ``published_table`` after the
    specs'."""
    runs = [{"name": column(s), "summary": {"tasks": {t: row[s] for t, row in res["cells"].items()
                                                      if row.get(s)}}} for s in specs]
    header, rows = table(runs, list(published), metric, list(res["cells"]), with_chance=True,
                         intervals=intervals, published_table=published_table)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    groups = {r[1] for r in rows if r[1]}
    for r in rows:
        name = f"**{r[0]}**" if str(r[0]).startswith("average") else r[0]
        values = []
        for k, v in enumerate(r[2:]):
            # the overall average spans every group listed: a column absent from one has none
            scope = [r[1]] if r[1] else groups
            absent = (not all(applies(specs[k], g) for g in scope) if k < len(specs)
                      else v is None)  # a published column: no number for the task
            values.append("n/a" if absent else format_cell(v))
        lines.append("| " + " | ".join([name, r[1], *values]) + " |")
    return lines


def difference_table(res: dict[str, Any], specs: list[str], base: str = "mem0",
                     labels: dict[str, str] | None = None,
                     apart: dict[str, dict[str, str]] | None = None,
                     against_chance: bool = False) -> list[str]:
    """Per task, ``base`` minus each column in points with the difference's 95% interval;
    "*" where the interval excludes zero, "—" where either cell is missing. ``labels``: a
    task's name in the table, where it is not the task's own; ``apart``: per task and column,
    what a cell left out of the comparison reads instead of "—". ``against_chance``: a last
    column, ``base`` minus the task's chance level (``res["chance"]``), its interval
    ``base``'s Wilson interval moved by the same amount (chance is exact)."""
    others = [s for s in specs if s != base]
    lines = ["| task | TMC | " + " | ".join(f"{column(base)} − {column(s)}" for s in others)
             + (f" | {column(base)} − chance" if against_chance else "")
             + " |", "|---|---|" + "---|" * (len(others) + against_chance)]
    for task in res["cells"]:
        diffs = res.get("differences", {}).get(task, {})
        values = []
        for s in others:
            if not applies(s, get_task(task).tmc):
                values.append("n/a")
            elif s not in diffs:
                values.append((apart or {}).get(task, {}).get(s, "—"))
            else:
                d, (low, high) = diffs[s]["difference"], diffs[s]["ci95"]
                values.append(format_difference(d, low, high)
                              + ("*" if diffs[s]["outside_noise"] else ""))
        if against_chance:
            values.append(minus_chance(res["cells"][task].get(base), res["chance"][task]["rate"]))
        label = (labels or {}).get(task, task)
        lines.append(f"| {label} | {get_task(task).tmc} | " + " | ".join(values) + " |")
    return lines


def minus_chance(cell: dict[str, Any] | None, level: float) -> str:
    """'+25 [+23, +25]*': a cell's success rate minus a chance level (a fraction), in points,
    with the cell's Wilson interval moved by as much; "*" where that interval excludes zero;
    "—" where the cell is missing."""
    if not cell:
        return "—"
    r = Rate.of(cell)
    if not isinstance(r, Rate):  # an older row without its episodes: no interval
        return signed(r - 100 * level)
    low, high = r.ci95
    text = format_difference(r / 100 - level, low / 100 - level, high / 100 - level)
    return text + ("*" if low > 100 * level or high < 100 * level else "")


def markdown(res: dict[str, Any], intervals: bool = True) -> str:
    plan = res["plan"]
    ci = " [95% interval]" if intervals else ""
    lines = [f"# Benchmark table: {plan['obs']} observation", "",
             f"{plan['demos']} demonstrations per task, {plan['steps']} training steps at batch "
             f"{plan['batch']}, {plan['episodes']} evaluation episodes per cell"
             + (f", `--set {' '.join(plan['sets'])}`" if plan["sets"] else "")
             + "".join(f"; on {task} also `--set {' '.join(items)}`"
                       for task, items in plan.get("task_sets", {}).items()) + ".", "",
             f"## Policies (success rate, %{ci})", ""]
    specs = _columns(res, POLICY_TABLE)
    if specs:
        lines += _markdown_table(res, specs, list(PUBLISHED), intervals=intervals) + [""]
        lines += [f"Published: arXiv {published_source()}.", ""]
    specs = _columns(res, ABLATION_TABLE)
    if specs:
        lines += [f"## Mem-0's ablations (success rate, %{ci})", ""]
        names = ablation_names()
        lines += _markdown_table(res, specs, [names[s] for s in specs if s in names],
                                 intervals=intervals, published_table="ablations") + [""]
        lines += [f"Published: arXiv {published_source('ablations')}.", ""]
        if intervals and "mem0" in specs and len(specs) > 1:
            lines += ["Mem-0 minus each ablation (points) [95% interval of the difference, "
                      "Newcombe's], and minus the task's chance level [Mem-0's interval moved "
                      "by it]; * where it excludes zero, the difference outside the "
                      "episodes' noise:", ""]
            lines += difference_table(res, specs, against_chance=True) + [""]
    lines += ["Chance (no memory): the best success rate of a policy with every skill and no "
              "memory, which guesses where only the past would tell (`eval/chance.py`):", ""]
    lines += [f"- {t}: {100 * c['rate']:.1f}%, {c['basis']}" for t, c in res["chance"].items()]
    lines += ["", "## Progress (mean of each episode's best, %)", ""]
    lines += _markdown_table(res, _columns(res), metric="mean_progress")
    wall = res["wall_s"]
    machines = {short(m) for row in res["cells"].values() for cell in row.values() if cell
                for stage in cell.get("machines", {}).values() for m in stage}
    lines += ["", f"Wall time: {wall['table'] or 0:.0f} s for the table's runs; the cells' "
              f"stages ran on {'; '.join(sorted(machines)) or short(res['machine'])}.", ""]
    if res["failed"]:
        lines += ["Failed in the last run: " + "; ".join(f"{k}: {v}" for k, v in res["failed"].items()), ""]
    return "\n".join(lines)


def write(plan: Plan, out: Path, command: str = "", failed: dict[str, str] | None = None
          ) -> dict[str, Any]:
    """``OUT/table.json`` and ``OUT/table.md``; the results."""
    res = results(plan, out, command, failed)
    write_json(Path(out) / "table.json", res)
    write_atomic(Path(out) / "table.md", markdown(res).encode())
    return res
