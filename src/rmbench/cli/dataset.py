"""``rmbench dataset ...``: checking a dataset and deriving one from it."""

from __future__ import annotations

import json


def cmd_check(args) -> int:
    from rmbench.data.check import check_dataset

    summary = check_dataset(args.dir)
    if args.json:
        print(json.dumps({"ok": True, **summary}, indent=2))
    else:
        print(f"ok: {summary['episodes']} episodes, {summary['frames']} frames of "
              f"{summary['task']}, cameras {', '.join(summary['cameras'])}")
    return 0


def cmd_copy_layouts(args) -> int:
    from rmbench.data.layout_copies import copy_layouts

    summary = copy_layouts(args.source, args.out, args.copies, args.reach, seed=args.seed,
                           episodes=args.episodes, overwrite=args.overwrite,
                           workers=args.workers, progress=not args.json)
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        print(f"{summary.root}: {summary.episodes} episodes from {summary.source_episodes} "
              f"demonstrations ({summary.new_episodes} new, {summary.out_of_reach} copies out "
              f"of reach), {summary.frames} frames, {summary.wall_s / 60:.1f} min")
    return 0


def add_parser(sub, add_json) -> None:
    p = sub.add_parser("dataset", help="dataset tools")
    dsub = p.add_subparsers(dest="dataset_command", required=True)
    c = dsub.add_parser("check", help="validate every file of a dataset; report the first problem")
    c.add_argument("dir")
    add_json(c)
    c.set_defaults(func=cmd_check)

    c = dsub.add_parser(
        "copy-layouts", help="a dataset of each demonstration and rendered copies of it with the scene moved "
             "on the table (more layouts for pixel training; resumable)")
    c.add_argument("source", help="an rmbench dataset with cameras and the environment state")
    c.add_argument("--out", required=True, help="the new dataset's folder (resumed if it exists)")
    c.add_argument("--copies", type=int, default=8, help="copies of each demonstration (8)")
    c.add_argument("--reach", type=float, default=0.04,
                   help="largest shift along each table axis, metres (0.04)")
    c.add_argument("--seed", type=int, default=0, help="seed of the shifts (0)")
    c.add_argument("--episodes", type=int, default=None,
                   help="copy the first N demonstrations (default: all)")
    c.add_argument("--workers", type=int, default=1,
                   help="processes copying demonstrations (the dataset does not depend on it)")
    c.add_argument("--overwrite", action="store_true", help="start over if --out exists")
    add_json(c)
    c.set_defaults(func=cmd_copy_layouts)
