"""Evaluation speed, this tree against an earlier commit, side by side in one run: the CPU
time of one worker's evaluation of a policy (a Mem-0 checkpoint, say) on the same seeds, and
whether the two evaluations' records agree.

    .venv/bin/python benchmarks/eval_ab_speed.py --base COMMIT --policy mem0:CKPT
        [--task put_back_block] [--episodes 8] [--batch 8] [--rounds 1] [--out FILE]

The earlier commit is checked out once into a git worktree (``train_speed.py`` does the same)
and run with this tree's virtual environment (``PYTHONPATH`` set to its ``src``); the two sides
alternate, round after round. Each side evaluates in a fresh process, and the time is that
process's CPU time (user + system) around ``evaluate`` alone: the policy's loading, the
imports and the expert's seed verification (done once beforehand, into a shared seed cache)
are not in it. Records agree when every episode has the same ending, steps and progress; a
batch size other than 1 may change an episode's last float bits and so its course
(``EvalConfig.batch``), so their success rates are compared with their intervals too. A
``noop`` evaluation of the same seeds gives what the env and the harness alone cost a step,
which no batching of the policy removes. Writes JSON (default
benchmarks/results/eval_ab_speed.json) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from train_speed import ROOT, run, worktree

from rmbench.eval.intervals import wilson
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.policies.config import split_policy

PYTHON = Path(sys.executable)
# One side's evaluation, run under that side's rmbench: its CPU time around evaluate() and
# its records. (EvalConfig has ``batch`` only where batches exist.)
SIDE = """
import json, resource, sys
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.records import read_records
task, policy, out, episodes, batch, cache = json.loads(sys.argv[1])
kw = {"batch": batch} if "batch" in EvalConfig.__dataclass_fields__ else {}
cfg = EvalConfig((task,), policy, out, episodes=episodes, workers=1, video="none",
                 progress=False, seed_cache=cache, **kw)
def cpu():
    return sum(getattr(resource.getrusage(w), f) for w in (resource.RUSAGE_SELF,
               resource.RUSAGE_CHILDREN) for f in ("ru_utime", "ru_stime"))
t0 = cpu()
evaluate(cfg)
used = cpu() - t0
records = [{k: r[k] for k in ("seed", "success", "steps", "reason", "progress")}
           for r in read_records(__import__("pathlib").Path(out) / task / "episodes.jsonl")]
print(json.dumps({"cpu_s": used, "batched": bool(kw), "records": records}))
"""


def side(src: Path, task: str, policy: str, out: Path, episodes: int, batch: int,
         cache: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(src), "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    if out.exists():
        run(["rm", "-rf", str(out)])
    args = json.dumps([task, policy, str(out), episodes, batch, str(cache)])
    return json.loads(run([str(PYTHON), "-c", SIDE, args], env).strip().splitlines()[-1])


def checkpoint_facts(policy: str) -> dict | None:
    """A checkpoint's step and recipe, from its config.json (a ``NAME:CKPT`` spec)."""
    path = Path(split_policy(policy)[1]) / "config.json"
    if not path.is_file():
        return None
    config = json.loads(path.read_text())
    return {"path": str(path.parent), "step": config.get("step"), "task": config.get("task"),
            "demos": (config.get("dataset") or {}).get("episodes"), "config": config.get("config")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, help="the earlier commit to compare against")
    ap.add_argument("--policy", required=True, help="a policy spec, e.g. mem0:CKPT")
    ap.add_argument("--task", default="put_back_block")
    ap.add_argument("--episodes", type=int, default=8)
    ap.add_argument("--batch", type=int, default=8, help="this tree's batch size")
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--work", type=Path, default=ROOT / "runs" / "bench" / "eval_ab_speed")
    ap.add_argument("--out", type=Path,
                    default=ROOT / "benchmarks" / "results" / "eval_ab_speed.json")
    args = ap.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    sha, base_tree = worktree(args.base, args.work.parent / "train_speed")
    head = run(["git", "rev-parse", "HEAD"]).strip()
    dirty = bool(run(["git", "status", "--porcelain", "--untracked-files=no", "src"]).strip())
    cache = args.work / "seeds"
    # the expert verifies the seeds once, before anything is timed
    side(ROOT / "src", args.task, "noop", args.work / "warm", args.episodes, 1, cache)
    sides = {"base": (base_tree / "src", 1), "this": (ROOT / "src", args.batch)}
    cpu: dict[str, list[float]] = {name: [] for name in sides}
    records: dict[str, list] = {}
    for r in range(args.rounds):
        for name, (src, batch) in sides.items():
            result = side(src, args.task, args.policy, args.work / f"run-{name}",
                          args.episodes, batch, cache)
            cpu[name].append(round(result["cpu_s"], 2))
            records.setdefault(name, result["records"])
            print(f"round {r + 1}: {name} {cpu[name][-1]:.1f} s CPU", flush=True)
    # what the env and the harness alone cost a step: a policy that costs nothing (noop)
    # on the same seeds, this tree
    floor = side(ROOT / "src", args.task, "noop", args.work / "run-noop", args.episodes, 1, cache)
    floor_ms = floor["cpu_s"] / sum(r["steps"] for r in floor["records"]) * 1e3
    best = {name: min(c) for name, c in cpu.items()}
    rates = {}
    for name, recs in records.items():
        k = sum(r["success"] for r in recs)
        lo, hi = wilson(k, len(recs))
        steps = sum(r["steps"] for r in recs)
        rates[name] = {"success": k, "episodes": len(recs), "ci95": [round(lo, 4), round(hi, 4)],
                       "steps": steps, "cpu_ms_per_step": round(best[name] / steps * 1e3, 3)}
    report = {
        "task": args.task, "policy": args.policy, "episodes": args.episodes, "workers": 1,
        "threads": 1, "rounds": args.rounds,
        "base": {"commit": sha, "batch": 1, "cpu_s": cpu["base"], **rates["base"]},
        "this": {"commit": head, "uncommitted_changes": dirty, "batch": args.batch,
                 "cpu_s": cpu["this"], **rates["this"]},
        "cpu_ratio": round(best["base"] / best["this"], 3),
        "env_only": {"policy": "noop", "cpu_ms_per_step": round(floor_ms, 3),
                     "steps": sum(r["steps"] for r in floor["records"])},
        "checkpoint": checkpoint_facts(args.policy),
        "records_identical": records["base"] == records["this"],
        "machine": describe(),
    }
    write_json(args.out, report, indent=2)
    print(f"| side | commit | batch | CPU s (best of {args.rounds}) | success |\n|---|---|---|---|---|")
    for name in sides:
        s = report[name]
        print(f"| {name} | {s['commit'][:10]} | {s['batch']} | {best[name]:.1f} | "
              f"{s['success']}/{s['episodes']} |")
    print(f"env and harness alone (noop): {floor_ms:.2f} ms of CPU a step")
    print(f"CPU time ratio {report['cpu_ratio']:.2f}x; records "
          + ("identical" if report["records_identical"] else "differ"))


if __name__ == "__main__":
    main()
