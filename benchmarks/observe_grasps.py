"""Where observe_and_pickup's policies close a gripper: the first grasp of each validation
episode, against the five objects on the table. The table's cells say that nearly every
episode times out in the pick; this says why, by position: whether the hand closes on an
object at all, on which one, and with the arm of the target's side.

    .venv/bin/python benchmarks/observe_grasps.py --policy LABEL=SPEC [--policy ...]
        [--episodes 100] [--seed 0] [--out benchmarks/results/observe_grasps.json]

SPEC is a policy spec as ``rmbench eval --policy`` takes it (``expert``, ``mem0:CKPT``, ...).
Each episode is one of ``--seed``'s expert-verified validation episodes (the split recipe
choices read, from ``100000 * (1 + seed) + 50000``), played until it ends; a policy's chunk is
played out step by step. The first grasp is the first step after the observe phase at which
a gripper's command falls below half open; at that step the
closing hand's position is held against each object's (horizontal distance). "On an object"
means within ``NEAR`` of its centre. A row per policy, with Wilson 95% intervals for the
rates, is written atomically to the JSON (a label given again replaces its row).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.envs.registration import make
from rmbench.eval.intervals import wilson
from rmbench.eval.seeds import verified_seeds
from rmbench.policies.registry import env_options, make_policy
from rmbench.sim import robot
from rmbench.video import write_atomic

OUT = Path(__file__).resolve().parent / "results" / "observe_grasps.json"
TASK = "observe_and_pickup"
NEAR = 0.03  # metres: a closing hand this near an object's centre is on it
OPEN = 0.5  # a gripper command below this closes the hand (1 open, 0 closed)
GRIPPERS = (6, 13)  # the action's gripper entries, left then right (robot.SIDES' order)


def first_grasp(env, policy, seed: int) -> dict:
    """Play one episode; where its first grasp closed, and how the episode ended."""
    obs, info = env.reset(seed=seed)
    policy.reset(info["instruction"], info)
    task, sim = env.unwrapped.task, env.unwrapped.sim
    target = task.objects[task.target]
    grasp, chunk = None, []
    while True:
        if not chunk:
            out = np.asarray(policy.act(obs), np.float64)
            chunk = list(out) if out.ndim == 2 else [out]
        action = chunk.pop(0)
        closing = [k for k, i in enumerate(GRIPPERS) if action[i] < OPEN]
        if grasp is None and closing and task.screen_up:
            side = closing[0]  # the left hand first where both close at once
            hand = sim.ee_pose(sim.data)[7 * side: 7 * side + 2]
            dist = [float(np.linalg.norm(sim.data.xpos[o.body_id][:2] - hand))
                    for o in task.objects]
            nearest = int(np.argmin(dist))
            target_side = 0 if sim.data.xpos[target.body_id][0] < 0 else 1
            grasp = {"step": int(info.get("step", 0)),
                     "arm": robot.SIDES[side], "target_side_arm": side == target_side,
                     "nearest": nearest, "nearest_m": round(dist[nearest], 4),
                     "target_m": round(dist[task.target], 4),
                     "on_target": nearest == task.target and dist[nearest] < NEAR,
                     "on_object": dist[nearest] < NEAR}
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            ended = ("success" if info["is_success"] else
                     info.get("failure_reason") or ("timeout" if truncated else "ended"))
            break
    return {"seed": seed, "ended": ended, "grasp": grasp}


def rate(k: int, n: int) -> dict:
    lo, hi = wilson(k, n)
    return {"count": k, "of": n, "rate": round(k / n, 4) if n else None,
            "ci95": [round(lo, 4), round(hi, 4)]}


def summarize(label: str, spec: str, episodes: list[dict], seed: int, wall_s: float) -> dict:
    grasps = [e["grasp"] for e in episodes if e["grasp"] is not None]
    n = len(episodes)
    return {
        "label": label, "policy": spec, "task": TASK, "split": "validation", "seed": seed,
        "episodes": n, "near_m": NEAR,
        "success": rate(sum(e["ended"] == "success" for e in episodes), n),
        "grasped": rate(len(grasps), n),
        "on_object": rate(sum(g["on_object"] for g in grasps), n),
        "on_target": rate(sum(g["on_target"] for g in grasps), n),
        "target_side_arm": rate(sum(g["target_side_arm"] for g in grasps), n),
        "median_nearest_m": (round(float(np.median([g["nearest_m"] for g in grasps])), 4)
                             if grasps else None),
        "median_target_m": (round(float(np.median([g["target_m"] for g in grasps])), 4)
                            if grasps else None),
        "wall_s": round(wall_s, 1), "per_episode": episodes,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--policy", action="append", required=True, metavar="LABEL=SPEC")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    seeds = verified_seeds(TASK, args.seed, args.episodes, split="validation")
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []
    for item in args.policy:
        label, _, spec = item.partition("=")
        if not spec:
            p.error(f"--policy takes LABEL=SPEC, got {item!r}")
        env = make(TASK, **env_options(spec))
        policy = make_policy(spec, env)
        t0 = time.perf_counter()
        episodes = [first_grasp(env, policy, s) for s in seeds]
        row = summarize(label, spec, episodes, args.seed, time.perf_counter() - t0)
        env.close()
        rows = [r for r in rows if r["label"] != label] + [row]
        write_atomic(args.out, (json.dumps({"rows": rows}, indent=1) + "\n").encode())
        print(f"{label}: success {row['success']['count']}/{row['episodes']}, first grasp on an "
              f"object {row['on_object']['count']}, on the target {row['on_target']['count']}, "
              f"with the target side's arm {row['target_side_arm']['count']}; median distance "
              f"to the nearest object {row['median_nearest_m']} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
