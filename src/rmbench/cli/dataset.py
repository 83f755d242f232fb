"""``rmbench collect`` and ``rmbench dataset ...``: recording, checking and deriving datasets."""

from __future__ import annotations

import json

from rmbench.cli.common import add_json, width_height


def cmd_collect(args) -> int:
    from rmbench.data import CollectConfig, collect

    width, height = args.resolution
    kwargs = {"cameras": tuple(args.cameras)} if args.cameras else {}
    from rmbench.envs.noise import NoiseSpec

    cfg = CollectConfig(args.task, args.out, episodes=args.episodes, seed=args.seed,
                        width=width, height=height, workers=args.workers, search=args.search,
                        backend=args.backend, overwrite=args.overwrite,
                        progress=not args.json,
                        noise=NoiseSpec(args.noise_kind, args.noise, args.noise_tau), **kwargs)
    summary = collect(cfg)
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        print(f"{summary.task}: {summary.episodes} episodes ({summary.new_episodes} new, "
              f"{summary.frames} frames) in {summary.root}; {len(summary.skipped)} seed(s) "
              f"skipped; {summary.demos_per_min:.1f} demos/min")
        for s in summary.skipped:
            print(f"  skipped seed {s['seed']}: {s['reason']}")
    return 0


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
                           workers=args.workers, backend=args.backend,
                           progress=not args.json)
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        print(f"{summary.root}: {summary.episodes} episodes from {summary.source_episodes} "
              f"demonstrations ({summary.new_episodes} new, {summary.out_of_reach} copies out "
              f"of reach), {summary.frames} frames, {summary.wall_s / 60:.1f} min")
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("collect", help="record expert demonstrations into a LeRobot v3.0 dataset")
    p.add_argument("task", help="task name or gym id (see `rmbench tasks`)")
    p.add_argument("--episodes", type=int, default=50, help="demonstrations wanted in all")
    p.add_argument("--seed", type=int, default=0, help="first candidate seed, in [0, 100000) "
                   "(evaluation uses 100000 and up)")
    p.add_argument("--out", required=True, help="dataset folder (resumed if it exists)")
    p.add_argument("--workers", type=int, default=1, help="local worker processes")
    p.add_argument("--cameras", nargs="+", metavar="CAM",
                   help="cameras to record (default: head left_wrist right_wrist)")
    p.add_argument("--resolution", type=width_height, default=(320, 240), metavar="WxH")
    p.add_argument("--search", choices=["search", "direct"], default="search",
                   help="search: solve each seed without rendering, then record a replay; "
                   "direct: record while solving, drop failures")
    p.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="ray: spread episodes over a Ray cluster (pip install 'rmbench[ray]')")
    p.add_argument("--overwrite", action="store_true", help="delete the dataset in --out first")
    p.add_argument("--noise", type=float, default=0.0, metavar="SIGMA",
                   help="DART: execute the expert's action plus noise of this std (radians, arm "
                   "joints) and record the expert's action (default 0: clean demonstrations)")
    p.add_argument("--noise-kind", choices=("white", "smooth", "offset"), default="white",
                   help="see `rmbench robustness --help`")
    p.add_argument("--noise-tau", type=float, default=0.5, help="smooth noise time constant (s)")
    add_json(p)
    p.set_defaults(func=cmd_collect)

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
    c.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="ray: spread demonstrations over a Ray cluster")
    c.add_argument("--overwrite", action="store_true", help="start over if --out exists")
    add_json(c)
    c.set_defaults(func=cmd_copy_layouts)
