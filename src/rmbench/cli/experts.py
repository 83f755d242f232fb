"""``rmbench tasks``, ``expert``, ``robustness`` and ``quickstart``: the tasks and their
scripted experts."""

from __future__ import annotations

import argparse
import json

from rmbench.cli.common import add_json, whole


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


def cmd_robustness(args) -> int:
    from rmbench.robustness import sweep
    from rmbench.tasks import get_task

    task = get_task(args.task).name

    def show(noise, chunk):
        if not args.json:
            ok = sum(r.success for r in chunk)
            print(f"  {noise.kind} {noise.sigma:g}: seeds {chunk[0].seed}-{chunk[-1].seed} "
                  f"{ok}/{len(chunk)}", flush=True)

    results = sweep(task, args.noise, kind=args.kind, tau=args.tau, episodes=args.episodes,
                    seed=args.seed, workers=args.workers, on_chunk=show)
    rows = [r.to_dict() for r in results]
    if args.json:
        print(json.dumps({"task": task, "kind": args.kind, "tau": args.tau,
                          "seed": args.seed, "results": rows}, indent=2))
        return 0
    print(f"\n{task}: the expert under {args.kind} noise"
          + (f" (tau {args.tau:g} s)" if args.kind == "smooth" else ""))
    for r in rows:
        fails = "; ".join(f"{reason} ({n})" for reason, n in r["failures"].items())
        print(f"  sigma {r['sigma']:<6g} {r['successes']:>4}/{r['episodes']}"
              f"  {100 * r['success_rate']:5.1f}%  {fails}")
    return 0


def _floats(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers like 0.01,0.02, got {text!r}") from None
    if not values or any(not (v >= 0) or v == float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"expected finite numbers >= 0, got {text!r}")
    return values


def cmd_quickstart(args) -> int:
    from rmbench.quickstart import quickstart

    summary = quickstart(args.out, episodes=args.episodes, seed=args.seed,
                         log=None if args.json else print)
    if args.json:
        print(json.dumps(summary, indent=2))
    return 0 if summary["all_succeeded"] else 1


def add_parsers(sub) -> None:
    p = sub.add_parser("tasks", help="list the tasks: gym id, TMC, step limit, subtasks")
    add_json(p)
    p.set_defaults(func=cmd_tasks)

    p = sub.add_parser("expert", help="run the scripted expert and report its success rate")
    p.add_argument("task", help="task name or gym id (see `rmbench tasks`)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--seed", type=whole(0), default=100000,
                   help="first seed (seeds are consecutive)")
    p.add_argument("--render", action=argparse.BooleanOptionalAction, default=False,
                   help="render the observation cameras each step (default: physics only)")
    p.add_argument("--video", metavar="DIR", help="write a third-person video per episode")
    add_json(p)
    p.set_defaults(func=cmd_expert)

    p = sub.add_parser("robustness", help="the scripted expert under action noise: success and "
                       "failure reasons per noise level")
    p.add_argument("task", help="task name or gym id (see `rmbench tasks`)")
    p.add_argument("--kind", choices=("white", "smooth", "offset"), default="white",
                   help="white: a new draw every step; smooth: Ornstein-Uhlenbeck drift with "
                   "time constant --tau; offset: one draw per episode")
    p.add_argument("--noise", type=_floats, default=[0.01, 0.02, 0.03], metavar="S1,S2,...",
                   help="standard deviations in radians on the arm-joint targets")
    p.add_argument("--tau", type=float, default=0.5, help="smooth noise time constant (s)")
    p.add_argument("--episodes", type=int, default=100, help="seeds per noise level")
    p.add_argument("--seed", type=whole(0), default=100000,
                   help="first seed (seeds are consecutive)")
    p.add_argument("--workers", type=whole(1), default=1)
    add_json(p)
    p.set_defaults(func=cmd_robustness)

    p = sub.add_parser("quickstart", help="expert on every task for a few seeds, with videos")
    p.add_argument("--out", default="runs/quickstart", help="output folder")
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--seed", type=whole(0), default=100000)
    add_json(p)
    p.set_defaults(func=cmd_quickstart)
