"""A table's results: ``table.json`` (every cell's row, the plan, wall times, the machine) and
``table.md``, the benchmark's two tables (policies beside the published ones, Mem-0's
ablations beside the published averages) with M(1) and M(n) groups and averages. A cell not
evaluated yet reads "—" and keeps its group's average empty."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

from rmbench.eval.chance import chance
from rmbench.eval.report import PUBLISHED, table
from rmbench.machine import describe, short
from rmbench.suite.plan import Plan, applies
from rmbench.suite.runner import column
from rmbench.suite.stages import TIMING, cell_row, read_json
from rmbench.video import write_atomic

POLICY_TABLE = ("mem0", "mem0:no_memory", "dp", "act")
ABLATION_TABLE = ("mem0", "mem0:no_anchor", "mem0:no_sliding", "mem0:no_memory", "mem0:no_key",
                  "mem0:gt_classifier")
# Published Mem-0 ablation averages (%), by group (../MEM0.md: per-task numbers unpublished)
PUBLISHED_ABLATIONS = {"M(1)": {"mem0": 52.8, "mem0:no_anchor": 26.8, "mem0:no_sliding": 40.4},
                       "M(n)": {"mem0": 28.5, "mem0:no_key": 4.8, "mem0:no_anchor": 26.8,
                                "mem0:no_sliding": 25.3, "mem0:gt_classifier": 45.3}}


def results(plan: Plan, out: Path, command: str = "",
            failed: dict[str, str] | None = None) -> dict[str, Any]:
    """Every cell's row (None where not evaluated) with the plan, the failures of the last
    run, the wall times (per model in each row; the table's summed over its runs) and the
    machine."""
    cells: dict[str, dict[str, Any]] = {}
    for task, spec in plan.cells():
        cells.setdefault(task, {})[spec] = cell_row(plan, out, task, spec)
    collect = {t: read_json(Path(out) / t / TIMING, {}).get("collect_wall_s") for t in cells}
    levels = {t: asdict(chance(t)) for t in cells}
    return {"command": command, "plan": plan.to_dict(), "cells": cells, "chance": levels,
            "failed": failed or {},
            "wall_s": {"table": read_json(Path(out) / TIMING, {}).get("table_wall_s"),
                       "collect": collect},
            "machine": describe()}


def _columns(res: dict[str, Any], specs: tuple[str, ...]) -> list[str]:
    return [s for s in specs if s in res["plan"]["policies"]]


def _markdown_table(res: dict[str, Any], specs: list[str], published: list[str] = (),
                    metric: str = "success_rate") -> list[str]:
    """``eval.report.table`` over the plan's tasks, one column per spec: "—" where a cell is
    not evaluated yet, "n/a" where the column has no cell (no_key on an M(1) task, and so in
    the average over both groups)."""
    runs = [{"name": column(s), "summary": {"tasks": {t: row[s] for t, row in res["cells"].items()
                                                      if row.get(s)}}} for s in specs]
    header, rows = table(runs, list(published), metric, list(res["cells"]), with_chance=True)
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    groups = {r[1] for r in rows if r[1]}
    for r in rows:
        name = f"**{r[0]}**" if str(r[0]).startswith("average") else r[0]
        values = []
        for k, v in enumerate(r[2:]):
            # the overall average spans every group listed: a column absent from one has none
            scope = [r[1]] if r[1] else groups
            absent = k < len(specs) and not all(applies(specs[k], g) for g in scope)
            values.append("n/a" if absent else "—" if v is None else f"{v:.1f}")
        lines.append("| " + " | ".join([name, r[1], *values]) + " |")
    return lines


def markdown(res: dict[str, Any]) -> str:
    plan = res["plan"]
    lines = [f"# Benchmark table: {plan['obs']} observation", "",
             f"{plan['demos']} demonstrations per task, {plan['steps']} training steps at batch "
             f"{plan['batch']}, {plan['episodes']} evaluation episodes per cell"
             + (f", `--set {' '.join(plan['sets'])}`" if plan["sets"] else "") + ".", "",
             "## Policies (success rate, %)", ""]
    specs = _columns(res, POLICY_TABLE)
    if specs:
        lines += _markdown_table(res, specs, list(PUBLISHED)) + [""]
    specs = _columns(res, ABLATION_TABLE)
    if specs:
        lines += ["## Mem-0's ablations (success rate, %)", ""]
        lines += _markdown_table(res, specs) + [""]
        lines += ["Published averages: " + "; ".join(
            f"{group}: " + ", ".join(f"{column(s)} {v}" for s, v in vals.items())
            for group, vals in PUBLISHED_ABLATIONS.items()) + ".", ""]
    lines += ["Chance (no memory): the best success rate of a policy with every skill and no "
              "memory, which guesses where only the past would tell (`eval/chance.py`):", ""]
    lines += [f"- {t}: {100 * c['rate']:.1f}%, {c['basis']}" for t, c in res["chance"].items()]
    lines += ["", "## Progress (mean of each episode's best, %)", ""]
    lines += _markdown_table(res, list(plan["policies"]), metric="mean_progress")
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
    write_atomic(Path(out) / "table.json", (json.dumps(res, indent=1) + "\n").encode())
    write_atomic(Path(out) / "table.md", markdown(res).encode())
    return res
