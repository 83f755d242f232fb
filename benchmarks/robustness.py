"""The scripted experts under action noise, every task and noise kind: the table in
docs/results/robustness.md.

    .venv/bin/python benchmarks/robustness.py [--tasks T ...] [--kinds white smooth offset]
        [--noise 0.01,0.02,0.03] [--episodes 100] [--workers 2] [--render-only]

Each (task, kind, sigma) cell is its own JSON file in benchmarks/results/robustness/, written
atomically when the cell is done, so an interrupted run re-run with the same arguments does
only the missing cells. The clean expert (sigma 0) is a cell too. ``--render-only`` writes the
markdown from the cells there are.

Floor (the robustness issue): on 100 seeds, >= 90% under smooth 0.02 (tau 0.5 s) and offset
0.02, >= 95% under white 0.01, 100% without noise; no expert raises.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.robustness import sweep
from rmbench.tasks.registry import ordered
from rmbench.video import write_atomic

ROOT = Path(__file__).resolve().parent
CELLS = ROOT / "results" / "robustness"
DOC = ROOT.parent / "docs" / "results" / "robustness.md"
FLOOR = {("smooth", 0.02): 0.90, ("offset", 0.02): 0.90, ("white", 0.01): 0.95,
         ("white", 0.0): 1.0}


def cell_path(task: str, kind: str, sigma: float) -> Path:
    return CELLS / f"{task}_{kind}_{sigma:g}.json"


def run_cell(task: str, kind: str, sigma: float, episodes: int, seed: int, workers: int,
             tau: float) -> dict:
    t0 = time.perf_counter()
    result = sweep(task, [sigma], kind=kind, tau=tau, episodes=episodes, seed=seed,
                   workers=workers)[0]
    cell = {"task": task, "seed": seed, "wall_s": round(time.perf_counter() - t0, 1),
            **result.to_dict()}
    cell["command"] = (f"rmbench robustness {task} --kind {kind} --noise {sigma:g} "
                       f"--episodes {episodes} --seed {seed}"
                       + (f" --tau {tau:g}" if kind == "smooth" else ""))
    write_atomic(cell_path(task, kind, sigma), json.dumps(cell, indent=1).encode())
    return cell


def load_cells() -> dict[tuple[str, str, float], dict]:
    cells = {}
    for path in sorted(CELLS.glob("*.json")):
        c = json.loads(path.read_text())
        cells[(c["task"], c["kind"], float(c["sigma"]))] = c
    return cells


def render(cells: dict, columns: list[tuple[str, float]]) -> str:
    tasks = [t.name for t in ordered()]
    head = " | ".join(f"{k} {s:g}" if s else "no noise" for k, s in columns)
    lines = [
        "# The experts under action noise",
        "",
        "Success of each task's scripted expert (%) when noise is added to every arm-joint",
        "target it sends (grippers untouched), on consecutive seeds from 100000. Kinds:",
        "**white**, a new N(0, sigma) draw every control step; **smooth**, an Ornstein-Uhlenbeck",
        "drift with stationary std sigma and time constant 0.5 s (what a learned policy's error",
        "mostly looks like); **offset**, one draw per episode. Sigma in radians. A cell marked *",
        "is short of the floor (>= 90% under smooth and offset 0.02, >= 95% under white 0.01,",
        "100% without noise); `-` was not run.",
        "",
        f"| task | {head} |",
        "|---|" + "---|" * len(columns),
    ]
    for task in tasks:
        row = []
        for kind, sigma in columns:
            c = cells.get((task, kind, sigma))
            if c is None:
                row.append("-")
                continue
            mark = "*" if c["success_rate"] < FLOOR.get((kind, sigma), 0.0) else ""
            row.append(f"{100 * c['success_rate']:.0f}{mark} ({c['episodes']})")
        lines.append(f"| {task} | " + " | ".join(row) + " |")
    clean = [(t, cells[(t, "white", 0.0)]) for t in tasks if (t, "white", 0.0) in cells]
    if clean and all("longest_success_steps" in c for _, c in clean):
        lines += ["", "## Without noise: the step limits' margin", "",
                  "| task | success | longest successful episode | step limit | margin |",
                  "|---|---|---|---|---|"]
        for task, c in clean:
            longest = c["longest_success_steps"]
            margin = f"{c['step_limit'] / longest:.2f}x" if longest else "-"
            lines.append(f"| {task} | {c['successes']}/{c['episodes']} | {longest} steps | "
                         f"{c['step_limit']} | {margin} |")
    raised = sum(c["expert_raised"] for c in cells.values())
    episodes = sum(c["episodes"] for c in cells.values())
    lines += ["", f"Episodes in the table: {episodes}; episodes in which an expert raised: "
              f"{raised}. (In parentheses: episodes per cell.)", "",
              "## How the failures end", "",
              "The most common endings of each cell that is not 100%:", ""]
    for task in tasks:
        for kind, sigma in columns:
            c = cells.get((task, kind, sigma))
            if c is None or not c["failures"]:
                continue
            merged: dict[str, int] = {}
            for reason, n in c["failures"].items():
                merged[_short(reason)] = merged.get(_short(reason), 0) + n
            ends = "; ".join(f"{r} ({n})" for r, n in sorted(merged.items(), key=lambda x: -x[1])[:4])
            lines.append(f"- {task}, {kind} {sigma:g}: {ends}")
    commands = sorted({c["command"] for c in cells.values()})
    lines += ["", "## Commands", "",
              "Every cell: `python benchmarks/robustness.py` (resumes; the cells are in",
              "`benchmarks/results/robustness/`). One cell, e.g.:", "", "```",
              *commands[:3], "```", "",
              f"Machine: {platform.machine()}, {platform.system()}, 2 CPU cores; wall time per "
              "cell is in its JSON."]
    return "\n".join(lines) + "\n"


def _short(reason: str) -> str:
    """A failure reason without the coordinates that make every one unique."""
    for cut in (" to [", " at [", " reach ["):
        if cut in reason:
            reason = reason.split(cut)[0] + cut.rstrip(" [")
    return reason


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--tasks", nargs="+", default=[t.name for t in ordered()])
    p.add_argument("--kinds", nargs="+", default=["smooth", "offset", "white"])
    p.add_argument("--noise", default="0.02,0.01,0.03",
                   help="sigmas, comma-separated, run in this order")
    p.add_argument("--clean", action=argparse.BooleanOptionalAction, default=True,
                   help="also the expert without noise")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=100000)
    p.add_argument("--tau", type=float, default=0.5)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--render-only", action="store_true")
    args = p.parse_args()
    sigmas = [float(s) for s in args.noise.split(",")]
    columns = [("white", 0.0)] + [(k, s) for k in ("smooth", "offset", "white")
                                  for s in sorted(sigmas)]
    # the floor's cells first, so an interrupted run has the ones that matter most
    todo = [cell for cell in FLOOR if cell[1] in sigmas or cell[1] == 0.0]
    todo += [(k, s) for s in sigmas for k in args.kinds if (k, s) not in todo]
    todo = [(k, s) for k, s in todo if k in args.kinds and (s > 0 or args.clean)]
    if not args.render_only:
        CELLS.mkdir(parents=True, exist_ok=True)
        for kind, sigma in todo:
            for task in args.tasks:
                old = cell_path(task, kind, sigma)
                if old.exists() and json.loads(old.read_text())["episodes"] >= args.episodes:
                    continue
                c = run_cell(task, kind, sigma, args.episodes, args.seed, args.workers, args.tau)
                print(f"{task:<20} {kind:<6} {sigma:<5g} {c['successes']:>3}/{c['episodes']}"
                      f"  {c['wall_s']:.0f}s", flush=True)
    write_atomic(DOC, render(load_cells(), columns).encode())
    print(f"wrote {DOC}")


if __name__ == "__main__":
    main()
