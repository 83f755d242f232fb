"""The ``rmbench`` command line: argument parsing only; the work is in the library."""

from __future__ import annotations

import argparse
import json
import logging
import sys

from rmbench.tasks.registry import UnknownTaskError


def _add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print machine-readable JSON only")


def cmd_tasks(args) -> int:
    from rmbench.tasks.registry import ordered

    rows = [{"name": c.name, "gym_id": c.gym_id, "tmc": c.tmc, "step_limit": c.step_limit,
             "subtasks": list(c.subtasks)} for c in ordered()]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(f"{'task':<20} {'gym id':<28} {'TMC':<5} {'limit':>5}  subtasks")
    for r in rows:
        print(f"{r['name']:<20} {r['gym_id']:<28} {r['tmc']:<5} {r['step_limit']:>5}  "
              + " | ".join(r["subtasks"]))
    return 0


def cmd_expert(args) -> int:
    from rmbench.rollout import run_expert
    from rmbench.tasks import get_task

    task = get_task(args.task).name
    seeds = range(args.seed, args.seed + args.episodes)

    def show(r):
        if not args.json:
            mark = "ok  " if r.success else "FAIL"
            print(f"{mark} seed {r.seed:>7}  steps {r.steps:>4}/{r.step_limit}  "
                  f"progress {r.progress:.2f}  {r.wall_s:6.2f}s  {r.reason}", flush=True)

    results = run_expert(task, seeds, render=args.render, video_dir=args.video,
                         videos=args.episodes if args.video else 0, on_result=show)
    ok = sum(r.success for r in results)
    summary = {"task": task, "episodes": len(results), "successes": ok,
               "success_rate": ok / max(len(results), 1),
               "max_steps": max((r.steps for r in results if r.success), default=0),
               "failures": [{"seed": r.seed, "reason": r.reason} for r in results
                            if not r.success]}
    if args.json:
        print(json.dumps({**summary, "episodes_detail": [r.to_dict() for r in results]},
                         indent=2))
    else:
        print(f"\n{task}: success {ok}/{len(results)} = {100 * summary['success_rate']:.1f}%  "
              f"(longest successful episode {summary['max_steps']} steps)")
        for f in summary["failures"]:
            print(f"  failed seed {f['seed']}: {f['reason']}")
    return 0 if ok == len(results) else 1


def cmd_quickstart(args) -> int:
    from rmbench.quickstart import quickstart

    summary = quickstart(args.out, episodes=args.episodes, seed=args.seed,
                         log=None if args.json else print)
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0 if summary["all_succeeded"] else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rmbench", description="RMBench: memory-dependent "
                                     "dual-arm manipulation on MuJoCo")
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("tasks", help="list the tasks: gym id, TMC, step limit, subtasks")
    _add_json(p)
    p.set_defaults(func=cmd_tasks)

    p = sub.add_parser("expert", help="run the scripted expert and report its success rate")
    p.add_argument("task", help="task name or gym id (see `rmbench tasks`)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--seed", type=int, default=100000, help="first seed (seeds are consecutive)")
    p.add_argument("--render", action=argparse.BooleanOptionalAction, default=False,
                   help="render the observation cameras each step (default: physics only)")
    p.add_argument("--video", metavar="DIR", help="write a third-person video per episode")
    _add_json(p)
    p.set_defaults(func=cmd_expert)

    p = sub.add_parser("quickstart", help="expert on every task for a few seeds, with videos")
    p.add_argument("--out", default="runs/quickstart", help="output folder")
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--seed", type=int, default=100000)
    _add_json(p)
    p.set_defaults(func=cmd_quickstart)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    if getattr(args, "episodes", 1) < 1:
        print("rmbench: error: --episodes must be at least 1", file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except (UnknownTaskError, ValueError) as err:
        print(f"rmbench: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rmbench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
