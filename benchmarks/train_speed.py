"""Training speed, this tree against an earlier commit, side by side in one run: Mem-0 on the
state table's recipe (its ``--set`` items below, batch 128), one thread, the same dataset and
seed on both sides; their CPU time per step, the ratio, and whether their loss curves agree.

    .venv/bin/python benchmarks/train_speed.py --base COMMIT [--task press_button]
        [--episodes 6] [--steps 300] [--rounds 2] [--out FILE]

The earlier commit is checked out once into a git worktree under ``--work`` and run with this
tree's virtual environment (``PYTHONPATH`` set to its ``src``); the two sides alternate, round
after round, so a load that comes and goes on the machine reaches both. A step's time is CPU
time (user + system, one thread, so other jobs on the machine barely move it): that of a
``--steps`` training less that of a 20-step one, over the steps between (the loading, the
planner's fit, shortened to 20 steps on both sides, and the saves cancel). Writes JSON
(default benchmarks/results/train_speed.json) and prints a table.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.suite.plan import sets_for
from rmbench.suite.recipes import RECIPES

ROOT = Path(__file__).resolve().parents[1]
PYTHON = Path(sys.executable)
# The state table's recipe for Mem-0 (rmbench table --obs state's, suite/recipes.py RECIPES), as
# rmbench train takes it; the state observation named, since the dataset holds a camera too.
# (Mem-0's two M(n) settings, the event end classifier and the key delay, are its defaults.)
RECIPE = ('observation="state"', *sets_for("mem0", RECIPES["state"]["sets"]))
# The planner trains first and alone (train_mem0): a few steps of it keep the fixed cost down.
PLANNER = ("planner_steps=20",)
SHORT = 20  # the steps of the short run whose CPU time is the fixed cost


def run(cmd: list[str], env: dict | None = None) -> str:
    done = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if done.returncode:
        sys.exit(f"{' '.join(cmd[:6])} ...: exit {done.returncode}: "
                 f"{done.stderr.strip().splitlines()[-1] if done.stderr.strip() else ''}")
    return done.stdout


def worktree(base: str, work: Path) -> tuple[str, Path]:
    """The earlier commit's full hash and a checkout of it (made once, kept for re-runs)."""
    sha = run(["git", "rev-parse", "--verify", f"{base}^{{commit}}"]).strip()
    tree = work / f"base-{sha[:12]}"
    if not (tree / "src" / "rmbench").is_dir():
        run(["git", "worktree", "add", "--detach", "--force", str(tree), sha])
    return sha, tree


def dataset(task: str, episodes: int, work: Path) -> Path:
    """The state table's demonstrations (noise 0.02 white, the smallest head video), collected
    by this tree once."""
    out = work / f"data-{task}-{episodes}"
    run([str(PYTHON), "-m", "rmbench.cli.main", "collect", task, "--episodes", str(episodes),
         "--seed", "0", "--out", str(out), "--cameras", "head", "--resolution", "16x16",
         "--noise", "0.02", "--noise-kind", "white", "--workers", "1", "--json"])
    return out


def train(src: Path, data: Path, out: Path, steps: int) -> dict:
    """One training of ``steps`` steps by the rmbench under ``src``, one thread; with the CPU
    time (user + system) of its whole process."""
    env = {**os.environ, "PYTHONPATH": str(src), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    cmd = [str(PYTHON), "-c", "import sys, torch; torch.set_num_threads(1); "
           "from rmbench.cli.main import main; sys.exit(main())",
           "train", "mem0", "--dataset", str(data), "--out", str(out), "--steps", str(steps),
           "--batch-size", "128", "--save-every", str(steps), "--json"]
    for item in RECIPE + PLANNER:
        cmd += ["--set", item]
    if out.exists():
        run(["rm", "-rf", str(out)])
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    result = json.loads(run(cmd, env))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    result["cpu_s"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    with open(out / "training" / "loss.csv", newline="") as f:
        result["curve"] = list(csv.DictReader(f))
    return result


def curves_agree(a: list[dict], b: list[dict]) -> dict:
    """Whether two loss curves are the same, row for row; else their largest relative gap."""
    keys = [k for k in a[0] if k == "loss" or k.startswith("loss/")]
    gap = max(abs(float(x[k]) - float(y[k])) / max(abs(float(x[k])), 1e-12)
              for x, y in zip(a, b, strict=True) for k in keys)
    return {"identical": a == b, "max_relative_gap": gap, "logged_steps": len(a), "keys": keys}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, help="the earlier commit to compare against")
    ap.add_argument("--task", default="press_button")
    ap.add_argument("--episodes", type=int, default=6)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--work", type=Path, default=ROOT / "runs" / "bench" / "train_speed")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "train_speed.json")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    sha, base_tree = worktree(args.base, args.work)
    head = run(["git", "rev-parse", "HEAD"]).strip()
    dirty = bool(run(["git", "status", "--porcelain", "--untracked-files=no", "src"]).strip())
    data = dataset(args.task, args.episodes, args.work)
    sides = {"base": base_tree / "src", "this": ROOT / "src"}
    walls: dict[str, list[float]] = {side: [] for side in sides}
    curves: dict[str, list] = {}
    cpu: dict[str, list[float]] = {side: [] for side in sides}
    for r in range(args.rounds):
        for side, src in sides.items():
            short = train(src, data, args.work / f"run-{side}", SHORT)
            result = train(src, data, args.work / f"run-{side}", args.steps)
            # a step's CPU time: the long run's less the short one's (loading, the planner's
            # fit and the saves are in both), over the steps between them
            cpu[side].append((result["cpu_s"] - short["cpu_s"]) / (args.steps - SHORT) * 1e3)
            walls[side].append(result["train_wall_s"] / args.steps * 1e3)
            curves.setdefault(side, result["curve"])
            print(f"round {r + 1}: {side} {cpu[side][-1]:.1f} ms of CPU a step "
                  f"({walls[side][-1]:.1f} ms of wall)", flush=True)
    ms = {side: min(c) for side, c in cpu.items()}  # the least disturbed round of each side
    report = {
        "task": args.task, "episodes": args.episodes, "steps": args.steps, "batch": 128,
        "threads": 1, "recipe": list(RECIPE), "rounds": args.rounds,
        "base": {"commit": sha, "cpu_ms_per_step": cpu["base"], "wall_ms_per_step": walls["base"]},
        "this": {"commit": head, "uncommitted_changes": dirty, "cpu_ms_per_step": cpu["this"],
                 "wall_ms_per_step": walls["this"]},
        "speedup": round(ms["base"] / ms["this"], 3),
        "curves": curves_agree(curves["base"], curves["this"]),
        "machine": describe(),
    }
    write_json(args.out, report, indent=2)
    print(f"| side | commit | CPU ms/step (best of {args.rounds}) |\n|---|---|---|")
    for side in sides:
        print(f"| {side} | {report[side]['commit'][:10]} | {ms[side]:.1f} |")
    print(f"speedup {report['speedup']:.2f}x; loss curves "
          + ("identical" if report["curves"]["identical"]
             else f"differ by at most {report['curves']['max_relative_gap']:.2e} (relative)"))


if __name__ == "__main__":
    main()
