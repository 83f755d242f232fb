"""Aliasing points, measured for every task and every pair of moments its expert's plan
revisits (``Task.aliasing_pairs``, the first its headline): head-camera pixel distance between
the two moments vs the same moment in an unrelated seed, for the whole frame and for the scene
alone (the robot's pixels left out), the same for the state observation (vs the distance
between layouts' first frames; "core" leaves out the headings of symmetric pieces), the
largest difference of the arms' joints (rad, grippers apart), and how far the expert's
subsequent actions diverge.

    python benchmarks/aliasing.py [--seed 100000] [--tasks T ...]
        [--more-seeds 150000,150001,150002] [--out benchmarks/results/aliasing.json]

``--tasks`` measures those tasks again and keeps the other rows of ``--out`` (same seed).
``--more-seeds`` measures every pair again from each of those seeds (validation episodes by
default: no table reports them) and keeps them under ``more_seeds``, so each pair is
certified on several layouts, not one.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import rmbench  # noqa: F401  (GL backend before mujoco)
from rmbench.aliasing import measure
from rmbench.files import write_json
from rmbench.tasks.registry import ordered


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=100000)
    ap.add_argument("--out", default="benchmarks/results/aliasing.json")
    ap.add_argument("--tasks", nargs="+", default=None, help="measure only these (default: all)")
    ap.add_argument("--more-seeds", default="150000,150001,150002",
                    help="comma-separated seeds to measure every pair from as well "
                         "(empty: none; default three validation seeds)")
    args = ap.parse_args()
    out = Path(args.out)
    kept, more_kept = [], {}
    if args.tasks is not None and out.exists():
        saved = json.loads(out.read_text())
        if saved["seed"] != args.seed:
            raise SystemExit(f"{out} was measured at seed {saved['seed']}, not {args.seed}")
        kept = saved["tasks"]
        more_kept = saved.get("more_seeds", {})
    rows = []
    print(f"{'task':<20} {'pair':>4} {'alias px':>9} {'unrelated px':>13} {'ratio':>6} "
          f"{'scene':>6} {'state':>7} {'core':>6} {'arms':>6} {'hands':>6} {'action div':>10}"
          f"  next subtasks")
    for cls in ordered():
        if args.tasks is not None and cls.name not in args.tasks:
            rows += [r for r in kept if r["task"] == cls.name]
            continue
        for pair in range(len(cls.aliasing_pairs)):
            r = measure(cls.name, seed=args.seed, pair=pair)
            rows.append({**r.to_dict(), "tmc": cls.tmc, "gym_id": cls.gym_id})
            same = r.next_subtasks[0] == r.next_subtasks[1]
            nxt = f"same text ({r.next_subtasks[0]})" if same else " / ".join(r.next_subtasks)
            print(f"{r.task:<20} {pair:>4} {r.pixel_distance:>9.3f} {r.unrelated_distance:>13.3f} "
                  f"{r.ratio:>6.3f} {r.scene_ratio:>6.3f} {r.state_ratio:>7.3f} "
                  f"{r.state_ratio_core:>6.3f} {r.arm_gap:>6.3f} {r.gripper_gap:>6.3f} "
                  f"{r.action_divergence:>10.3f}  {nxt}", flush=True)
    seeds = [int(s) for s in args.more_seeds.split(",") if s]
    more = {}
    for cls in ordered():
        if args.tasks is not None and cls.name not in args.tasks:
            if cls.name in more_kept:
                more[cls.name] = more_kept[cls.name]
            continue
        more[cls.name] = [{**measure(cls.name, seed=s, pair=pair).to_dict(), "gym_id": cls.gym_id}
                          for pair in range(len(cls.aliasing_pairs)) for s in seeds]
        print(f"{cls.name:<20} seeds {','.join(map(str, seeds))}, "
              f"{len(cls.aliasing_pairs)} pair(s): scene ratio up to "
              f"{max(r['scene_ratio'] for r in more[cls.name]):.3f}, state (core) up to "
              f"{max(r['state_ratio_core'] for r in more[cls.name]):.3f}, arms up to "
              f"{max(r['arm_gap'] for r in more[cls.name]):.4f}", flush=True)
    write_json(out, {"seed": args.seed, "camera": "head 320x240", "tasks": rows,
                     "more_seeds": more}, indent=2)
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
