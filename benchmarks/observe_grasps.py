"""Where observe_and_pickup's policies close a gripper: the first grasp of each validation
episode, against the five objects on the table. The table's cells say that nearly every
episode times out in the pick; this says why, by position: whether the hand closes on an
object at all, on which one, and with the arm of the target's side.

    .venv/bin/python benchmarks/observe_grasps.py --policy LABEL=SPEC [--policy ...]
        [--episodes 100] [--seed 0] [--out benchmarks/results/observe_grasps.json]

SPEC is a policy spec as ``rmbench eval --policy`` takes it (``expert``, ``mem0:CKPT``, ...).
Each episode is one of ``--seed``'s expert-verified validation episodes (the split recipe
choices read, from ``100000 * (1 + seed) + 50000``), played until it ends; a policy's chunk is
played out step by step, and the policy is told what the evaluation tells it (never the
task's hidden entries). The first grasp is the first step after the observe phase at which a
gripper's command goes from at least half open to below it; at that step the closing hand's
grasp site is held against each object's centre: the horizontal distance, and the site's
height over the table top. "On an object" means horizontally within ``NEAR`` of its centre.
A row per policy, with Wilson 95% intervals for the rates, is written atomically to the JSON
(a label given again replaces its row).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.envs.registration import make
from rmbench.eval.intervals import share
from rmbench.eval.rows import put_row
from rmbench.eval.seeds import verified_seeds
from rmbench.policies.registry import env_options, make_policy
from rmbench.sim import robot
from rmbench.sim.station import TABLE_TOP

OUT = Path(__file__).resolve().parent / "results" / "observe_grasps.json"
TASK = "observe_and_pickup"
NEAR = 0.03  # metres: a closing hand this near an object's centre is on it
OPEN = 0.5  # a gripper command below this closes the hand (1 open, 0 closed)
GRIPPERS = (6, 13)  # the action's gripper entries, left then right (robot.SIDES' order)


def first_grasp(env, policy, seed: int) -> dict:
    """Play one episode; where its first grasp closed, and how the episode ended."""
    obs, info = env.reset(seed=seed)
    u = env.unwrapped
    # what the evaluation hands a policy (eval/episode.py): never the task's hidden entries
    policy.reset(info["instruction"], {**u.spec_info, "seed": seed,
                                       "instruction": info["instruction"]})
    task, sim = u.task, u.sim
    target = task.objects[task.target]
    grasp, chunk, was_open = None, [], [True, True]
    while True:
        if not chunk:
            out = np.asarray(policy.act(obs), np.float64)
            chunk = list(out) if out.ndim == 2 else [out]
        action = chunk.pop(0)
        is_open = [bool(action[i] >= OPEN) for i in GRIPPERS]
        closing = [k for k in range(2) if was_open[k] and not is_open[k]]
        was_open = is_open
        if grasp is None and closing and task.screen_up:
            grasp = _grasp(sim, task, target, closing)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            ended = ("success" if info["is_success"] else
                     info.get("failure_reason") or ("timeout" if truncated else "ended"))
            break
    return {"seed": seed, "ended": ended, "grasp": grasp}


def _grasp(sim, task, target, closing: list[int]) -> dict:
    """Where the closing hand (of ``closing``, the one nearer an object where both close at
    once) stands against the objects: horizontal distances, and its height over the table."""
    pose = sim.ee_pose(sim.data)
    objects = np.array([sim.data.xpos[o.body_id][:2] for o in task.objects])

    def distances(side: int) -> np.ndarray:
        return np.linalg.norm(objects - pose[7 * side: 7 * side + 2], axis=1)

    side = min(closing, key=lambda k: distances(k).min())
    dist = distances(side)
    nearest = int(np.argmin(dist))
    target_side = 0 if sim.data.xpos[target.body_id][0] < 0 else 1  # the expert's rule
    return {"arm": robot.SIDES[side], "both_closed": len(closing) == 2,
            "target_side_arm": side == target_side,
            "nearest": nearest, "nearest_m": round(float(dist[nearest]), 4),
            "target_m": round(float(dist[task.target]), 4),
            "height_m": round(float(pose[7 * side + 2] - TABLE_TOP), 4),
            "on_target": bool(nearest == task.target and dist[nearest] < NEAR),
            "on_object": bool(dist[nearest] < NEAR)}


def summarize(label: str, spec: str, episodes: list[dict], seed: int, wall_s: float) -> dict:
    grasps = [e["grasp"] for e in episodes if e["grasp"] is not None]
    n = len(episodes)
    return {
        "label": label, "policy": spec, "task": TASK, "split": "validation", "seed": seed,
        "episodes": n, "near_m": NEAR,
        "success": share(sum(e["ended"] == "success" for e in episodes), n),
        "grasped": share(len(grasps), n),
        "on_object": share(sum(g["on_object"] for g in grasps), n),
        "on_target": share(sum(g["on_target"] for g in grasps), n),
        "target_side_arm": share(sum(g["target_side_arm"] for g in grasps), n),
        "median_nearest_m": (round(float(np.median([g["nearest_m"] for g in grasps])), 4)
                             if grasps else None),
        "median_target_m": (round(float(np.median([g["target_m"] for g in grasps])), 4)
                            if grasps else None),
        "median_height_m": (round(float(np.median([g["height_m"] for g in grasps])), 4)
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
        put_row(args.out, row, key=("label",))
        print(f"{label}: success {row['success']['count']}/{row['episodes']}, first grasp on an "
              f"object {row['on_object']['count']}, on the target {row['on_target']['count']}, "
              f"with the target side's arm {row['target_side_arm']['count']}; median distance "
              f"to the nearest object {row['median_nearest_m']} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
