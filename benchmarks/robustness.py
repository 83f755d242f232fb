"""The scripted experts under action noise, every task and noise kind: the cells behind the
tables of docs/results/robustness.md (rendered by scripts/render_docs.py).

    .venv/bin/python benchmarks/robustness.py [--tasks T ...] [--kinds white smooth offset]
        [--noise 0.01,0.02,0.03] [--episodes 100] [--workers 2] [--render-only]

Each (task, kind, sigma) cell is its own JSON file in benchmarks/results/robustness/, written
atomically when the cell is done, so an interrupted run re-run with the same arguments does
only the missing cells, and those of an earlier task version (the gym id a cell records).
The clean expert (sigma 0) is a cell too. ``--render-only`` rewrites the doc's tables from
the cells there are.

The experts' bar, the cells run first: on 100 seeds, >= 90% under smooth 0.02 (tau 0.5 s) and
offset 0.02, >= 95% under white 0.01, 100% without noise; no expert raises.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import time
from pathlib import Path

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.files import write_json
from rmbench.robustness import sweep
from rmbench.tasks.registry import get_task, on_current_version, ordered

ROOT = Path(__file__).resolve().parent
CELLS = ROOT / "results" / "robustness"
RENDER = ROOT.parent / "scripts" / "render_docs.py"
BAR = {("smooth", 0.02): 0.90, ("offset", 0.02): 0.90, ("white", 0.01): 0.95,
         ("white", 0.0): 1.0}


def cell_path(task: str, kind: str, sigma: float) -> Path:
    return CELLS / f"{task}_{kind}_{sigma:g}.json"


def run_cell(task: str, kind: str, sigma: float, episodes: int, seed: int, workers: int,
             tau: float) -> dict:
    t0 = time.perf_counter()
    result = sweep(task, [sigma], kind=kind, tau=tau, episodes=episodes, seed=seed,
                   workers=workers)[0]
    cell = {"task": task, "gym_id": get_task(task).gym_id, "seed": seed,
            "wall_s": round(time.perf_counter() - t0, 1), **result.to_dict()}
    cell["command"] = (f"rmbench robustness {task} --kind {kind} --noise {sigma:g} "
                       f"--episodes {episodes} --seed {seed}"
                       + (f" --tau {tau:g}" if kind == "smooth" else ""))
    write_json(cell_path(task, kind, sigma), cell)
    return cell


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
    # the bar's cells first, so an interrupted run has the ones that matter most
    todo = [cell for cell in BAR if cell[1] in sigmas or cell[1] == 0.0]
    todo += [(k, s) for s in sigmas for k in args.kinds if (k, s) not in todo]
    todo = [(k, s) for k, s in todo if k in args.kinds and (s > 0 or args.clean)]
    if not args.render_only:
        CELLS.mkdir(parents=True, exist_ok=True)
        for kind, sigma in todo:
            for task in args.tasks:
                old = cell_path(task, kind, sigma)
                if old.exists():
                    saved = json.loads(old.read_text())
                    if (saved["episodes"] >= args.episodes
                            and on_current_version(task, saved)):
                        continue
                c = run_cell(task, kind, sigma, args.episodes, args.seed, args.workers, args.tau)
                print(f"{task:<20} {kind:<6} {sigma:<5g} {c['successes']:>3}/{c['episodes']}"
                      f"  {c['wall_s']:.0f}s", flush=True)
    spec = importlib.util.spec_from_file_location("render_docs", RENDER)
    render_docs = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(render_docs)
    render_docs.main([])


if __name__ == "__main__":
    main()
