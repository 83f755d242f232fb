"""The grasp poses of a dataset's every joint state, read once when a state training starts
(``set_state_stats``: the pose input's mean and spread over the demonstrations and their
layout copies). Side by side in one run, the way it is done now (``EEActions.from_joints``:
one kinematics pass per row for both arms, MuJoCo's arrays read through views) against the way
it was done before (``GraspKinematics.forward`` per arm and row): CPU time, one thread, and
whether both give the same bytes.

    .venv/bin/python benchmarks/pose_stats_speed.py --dataset runs/table_state/cover_blocks/data
        [--copies 16] [--reach 0.04] [--rounds 2] [--out benchmarks/results/pose_stats_speed.json]

The dataset is a table's (its layout copies solved and cached by the collection, as a
training reads them); its demonstrations and copies are the rows, as in training. The two
sides alternate round after round; each figure is its least disturbed round.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.data.layout_shift import COPIES_SEED, cache_path, shifted_copies
from rmbench.data.reader import Dataset
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.policies.action_space import EE_ARM, EE_DIM, EEActions
from rmbench.sim import robot
from rmbench.sim.kinematics import GraspKinematics

ROOT = Path(__file__).resolve().parents[1]


def per_arm(kin: GraspKinematics, joints: np.ndarray) -> np.ndarray:
    """Before: ``forward`` for each arm at each row, packed as ``from_joints`` packs them."""
    out = np.empty((len(joints), EE_DIM), np.float32)
    for k, side in enumerate(robot.SIDES):
        for t, a in enumerate(joints):
            pos, mat = kin.forward(side, a[7 * k: 7 * k + 6])
            o = EE_ARM * k
            out[t, o: o + 3] = pos
            out[t, o + 3: o + 9] = mat[:, :2].T.reshape(6)
            out[t, o + 9] = a[7 * k + 6]
    return out


def cpu_s(fn, *args) -> tuple[float, np.ndarray]:
    start = time.process_time()
    out = fn(*args)
    return time.process_time() - start, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", type=Path, required=True)
    ap.add_argument("--copies", type=int, default=16)
    ap.add_argument("--reach", type=float, default=0.04)
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--out", type=Path,
                    default=ROOT / "benchmarks" / "results" / "pose_stats_speed.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    ds = Dataset(args.dataset)
    episodes = [ds.episode(e, cameras=[]) for e in range(ds.num_episodes)]
    cache = cache_path(ds, list(range(ds.num_episodes)), args.copies, args.reach, COPIES_SEED)
    if not cache.exists():
        raise SystemExit(f"{args.dataset} holds no cached layout copies for {args.copies}x"
                         f"{args.reach:g}: benchmark a table's dataset (its collection solves them)")
    copies = shifted_copies(episodes, ds.state_names, args.copies, args.reach, COPIES_SEED, cache)
    joints = np.concatenate([ep.state for ep in episodes + copies]).astype(np.float64)
    sides = {"before": lambda q: per_arm(GraspKinematics(), q),
             "now": lambda q: EEActions().from_joints(q)}
    seconds: dict[str, list[float]] = {s: [] for s in sides}
    made: dict[str, np.ndarray] = {}
    for _ in range(args.rounds):
        for side, fn in sides.items():
            t, made[side] = cpu_s(fn, joints)
            seconds[side].append(t)
    best = {s: min(v) for s, v in seconds.items()}
    report = {"dataset": ds.gym_id, "episodes": len(episodes), "copies_kept": len(copies),
              "rows": int(len(joints)), "rounds": args.rounds, "threads": 1,
              "cpu_s": {s: round(v, 2) for s, v in best.items()},
              "cpu_us_per_row": {s: round(v / len(joints) * 1e6, 2) for s, v in best.items()},
              "speedup": round(best["before"] / best["now"], 3),
              "identical": bool(np.array_equal(made["before"], made["now"])),
              "machine": describe()}
    write_json(args.out, report, indent=2)
    print(f"{ds.gym_id}: {len(episodes)} demonstrations and {len(copies)} layout copies, "
          f"{len(joints):,} joint states; CPU time, one thread:")
    print("| side | s | µs a row |\n|---|---|---|")
    for s in sides:
        print(f"| {s} | {best[s]:.1f} | {report['cpu_us_per_row'][s]:.1f} |")
    print(f"speed-up {report['speedup']:.2f}x, same bytes: {report['identical']}")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
