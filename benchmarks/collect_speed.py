"""Collection speed: demonstrations per minute for one worker and for N workers, the recorder's
overhead against running the expert with the cameras on and nothing saved, and MB per
demonstration, all in one run.

    .venv/bin/python benchmarks/collect_speed.py [--task put_back_block] [--episodes 50]
        [--workers 2] [--single 8] [--out FILE]

Target: 50 demonstrations of put_back_block with three 320x240 cameras in <= 5 min
on 2 cores; recorder overhead <= 1.3x. Prints a table and writes JSON (default
benchmarks/results/collect_speed.json).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from pathlib import Path

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.data import CollectConfig, collect
from rmbench.data.record import run_expert
from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.files import write_json
from rmbench.machine import describe


def folder_mb(path: Path) -> float:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file()) / 2**20


def expert_with_cameras(task: str, seeds) -> tuple[float, int]:
    """The baseline: the expert acting with the three cameras rendered every step, nothing
    encoded or written. Returns (seconds, successes)."""
    t0 = time.perf_counter()
    env = make(task, render=True)
    expert = make_expert(env)
    ok = sum(run_expert(env, expert, s).success for s in seeds)
    env.close()
    return time.perf_counter() - t0, ok


def timed_collect(tmp: Path, name: str, **kw) -> dict:
    out = tmp / name
    t0 = time.perf_counter()
    summary = collect(CollectConfig(out=out, progress=False, **kw))
    wall = time.perf_counter() - t0
    row = {"episodes": summary.episodes, "skipped": len(summary.skipped), "wall_s": round(wall, 2),
           "demos_per_min": round(60 * summary.episodes / wall, 2),
           "mb_per_demo": round(folder_mb(out) / summary.episodes, 3),
           "frames_per_demo": round(summary.frames / summary.episodes, 1)}
    shutil.rmtree(out)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="put_back_block")
    ap.add_argument("--episodes", type=int, default=50, help="demonstrations for the N-worker run")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--single", type=int, default=8, help="episodes for the one-worker runs")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="benchmarks/results/collect_speed.json")
    args = ap.parse_args()

    seeds = range(args.seed, args.seed + args.single)
    base = {"task": args.task, "seed": args.seed}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        base_s, base_ok = expert_with_cameras(args.task, seeds)
        search = timed_collect(tmp, "search", **base, episodes=args.single)
        direct = timed_collect(tmp, "direct", **base, episodes=args.single, search="direct")
        pool = timed_collect(tmp, "pool", **base, episodes=args.episodes, workers=args.workers)
    baseline_per_demo = base_s / args.single
    rows = [
        {"run": "expert + 3 cameras, nothing saved (baseline)", "workers": 1,
         "episodes": args.single, "wall_s": round(base_s, 2),
         "demos_per_min": round(60 * args.single / base_s, 2), "overhead": 1.0},
        {"run": "collect, search + recorded replay", "workers": 1, **search,
         "overhead": round(search["wall_s"] / search["episodes"] / baseline_per_demo, 3)},
        {"run": "collect, direct recording", "workers": 1, **direct,
         "overhead": round(direct["wall_s"] / direct["episodes"] / baseline_per_demo, 3)},
        {"run": "collect, search + recorded replay", "workers": args.workers, **pool},
    ]
    result = {
        "benchmark": "collect_speed", "task": args.task, "cameras": 3, "resolution": "320x240",
        "baseline_successes": base_ok, "rows": rows,
        "time_for_50_demos_s": round(50 * pool["wall_s"] / pool["episodes"], 1),
        "machine": describe(),
    }
    print(f"{'run':<46} {'workers':>7} {'demos':>5} {'wall s':>8} {'demos/min':>9} "
          f"{'overhead':>8} {'MB/demo':>8}")
    for r in rows:
        print(f"{r['run']:<46} {r['workers']:>7} {r['episodes']:>5} {r['wall_s']:>8.1f} "
              f"{r['demos_per_min']:>9.2f} {r.get('overhead', float('nan')):>8.3f} "
              f"{r.get('mb_per_demo', float('nan')):>8.3f}")
    print(f"50 demos with {args.workers} workers: {result['time_for_50_demos_s']:.0f} s")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    write_json(args.out, result, indent=2)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
