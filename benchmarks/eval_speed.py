"""Evaluation speed: env steps/s through the harness with the ``noop`` policy against the bare
env stepped by hand with the same actions, episodes/hour with 1 and N workers, and what the
README's first evaluation costs (one episode with its video; a round of the nine tasks by a
policy that never succeeds), in one run.

    .venv/bin/python benchmarks/eval_speed.py [--task put_back_block] [--episodes 6]
        [--workers 2] [--out FILE]

Target: harness >= 0.9x the bare env. ``noop`` reads no camera, so both sides run
physics only; a camera policy adds the same rendering to both. Prints a table and writes JSON
(default benchmarks/results/eval_speed.json).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.envs.registration import make
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.records import read_records
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.seeds import eval_seed_start
from rmbench.tasks.registry import ordered

ALL_TASKS = tuple(t.name for t in ordered())


def bare_env(task: str, seeds) -> tuple[int, float]:
    """The env stepped by hand, holding the arms still (what noop sends), physics only."""
    env = make(task, render=False)
    steps, t0 = 0, time.perf_counter()
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        while True:
            obs, _, terminated, truncated, _ = env.step(np.asarray(obs["agent_pos"]).copy())
            steps += 1
            if terminated or truncated:
                break
    wall = time.perf_counter() - t0
    env.close()
    return steps, wall


def harness(tasks: tuple[str, ...], policy: str, episodes: int, workers: int, tmp: Path,
            cache: Path, video: str = "none") -> tuple[int, float]:
    out = tmp / f"{policy}-{workers}-{len(tasks)}-{video}"
    t0 = time.perf_counter()
    evaluate(EvalConfig(tasks, policy, out, episodes=episodes, workers=workers, video=video,
                        progress=False, seed_cache=cache))
    wall = time.perf_counter() - t0
    steps = sum(r["steps"] for task in tasks
                for r in read_records(out / task / "episodes.jsonl"))
    return steps, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="put_back_block")
    ap.add_argument("--episodes", type=int, default=6)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", default="benchmarks/results/eval_speed.json")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        cache = tmp / "seeds"
        # Verify the seeds first so that no timed run pays for the search.
        evaluate(EvalConfig((args.task,), "noop", tmp / "warm", episodes=args.episodes,
                            video="none", progress=False, seed_cache=cache))
        seeds = json.loads(next(cache.glob("*.json")).read_text())["verified"][: args.episodes]
        assert seeds[0] >= eval_seed_start(0)
        bare_steps, bare_s = bare_env(args.task, seeds)
        task = (args.task,)
        h_steps, h_s = harness(task, "noop", args.episodes, 1, tmp, cache)
        e1_steps, e1_s = harness(task, "expert", args.episodes, 1, tmp, cache)
        en_steps, en_s = harness(task, "expert", args.episodes, args.workers, tmp, cache)
        # What the README's first evaluation costs: one episode, with the video it writes by
        # default, and a round of the nine tasks by a policy that never succeeds (each
        # episode to its step limit), seeds verified beforehand.
        v_steps, v_s = harness(task, "noop", 1, 1, tmp, cache, video="first:1")
        evaluate(EvalConfig(ALL_TASKS, "noop", tmp / "warm-all", episodes=1, video="none",
                            progress=False, seed_cache=cache))
        r_steps, r_s = harness(ALL_TASKS, "noop", 1, 1, tmp, cache)
    rows = [
        {"run": "bare env, hold still", "workers": 1, "steps": bare_steps, "wall_s": bare_s},
        {"run": "harness, noop policy", "workers": 1, "steps": h_steps, "wall_s": h_s},
        {"run": "harness, expert policy", "workers": 1, "steps": e1_steps, "wall_s": e1_s},
        {"run": "harness, expert policy", "workers": args.workers, "steps": en_steps, "wall_s": en_s},
        {"run": "harness, noop, one episode with its video", "workers": 1, "steps": v_steps,
         "wall_s": v_s, "episodes": 1},
        {"run": "harness, noop, one episode of each task", "workers": 1, "steps": r_steps,
         "wall_s": r_s, "episodes": len(ALL_TASKS)},
    ]
    for r in rows:
        r["steps_per_s"] = round(r["steps"] / r["wall_s"], 1)
        r["episodes_per_hour"] = round(3600 * r.get("episodes", args.episodes) / r["wall_s"], 1)
        r["wall_s"] = round(r["wall_s"], 2)
    ratio = rows[1]["steps_per_s"] / rows[0]["steps_per_s"]
    result = {"benchmark": "eval_speed", "task": args.task, "episodes": args.episodes,
              "rows": rows, "harness_vs_bare": round(ratio, 3),
              "machine": describe()}
    print(f"{'run':<42} {'workers':>7} {'steps':>6} {'wall s':>7} {'steps/s':>8} {'episodes/h':>10}")
    for r in rows:
        print(f"{r['run']:<42} {r['workers']:>7} {r['steps']:>6} {r['wall_s']:>7.1f} "
              f"{r['steps_per_s']:>8.1f} {r['episodes_per_hour']:>10.1f}")
    print(f"harness / bare env: {ratio:.3f}x")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    write_json(args.out, result, indent=2)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
