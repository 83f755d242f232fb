"""The ``rmbench`` command line: argument parsing only; the work is in the library."""

from __future__ import annotations

import argparse
import json
import logging
import sys

from rmbench.cli import dataset
from rmbench.suite.plan import add_recipe_arguments
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


def _resolution(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 320x240, got {text!r}") from None
    return w, h


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


def cmd_eval(args) -> int:
    from rmbench.eval import EvalConfig, evaluate
    from rmbench.tasks.registry import ordered

    tasks = [c.name for c in ordered()] if args.all else (args.task or [])
    if not tasks:
        raise ValueError("name a task with --task, or --all")
    cfg = EvalConfig(tuple(tasks), args.policy, args.out, episodes=args.episodes, seed=args.seed,
                     workers=args.workers, backend=args.backend, video=args.video,
                     instructions=args.instructions, progress=not args.json,
                     seeds_of=args.seeds_of)
    summary = evaluate(cfg)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        for task, r in summary["tasks"].items():
            print(f"{task:<20} {r['tmc']:<5} success {r['successes']:>3}/{r['episodes']:<3} "
                  f"({100 * r['success_rate']:5.1f}%)  progress {r['mean_progress']:.3f}")
        print(f"records and summary in {args.out}")
    return 0


def cmd_serve(args) -> int:
    from rmbench.serve.server import PolicyServer
    from rmbench.tasks import get_task

    PolicyServer(args.policy, get_task(args.task).name, args.host, args.port).serve_forever()
    return 0


def cmd_open_loop(args) -> int:
    from rmbench.eval.open_loop import open_loop_error

    result = open_loop_error(args.policy, args.dataset, args.indices)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"{'episode':>7} {'seed':>6} {'frames':>6} {'policy':>8} {'hold':>8}")
    for r in result["episodes"]:
        print(f"{r['episode']:>7} {r['seed']:>6} {r['frames']:>6} {r['error']:>8.4f} "
              f"{r['hold_error']:>8.4f}")
    print(f"{'all':>7} {'':>6} {'':>6} {result['error']:>8.4f} {result['hold_error']:>8.4f}")
    return 0


def cmd_report(args) -> int:
    from rmbench.eval.report import write_report

    out = write_report(args.dirs, args.out, args.published or [], args.labels)
    print(f"wrote {out}")
    return 0


def cmd_table(args) -> int:
    import shlex
    from pathlib import Path

    from rmbench.suite import runner, tables
    from rmbench.suite.plan import ALL_POLICIES, Plan
    from rmbench.tasks.registry import ordered

    tasks = ([t.name for t in ordered()] if args.tasks == "all"
             else [t.strip() for t in args.tasks.split(",") if t.strip()])
    policies = [p.strip() for p in (args.policies or ",".join(ALL_POLICIES)).split(",") if p.strip()]
    plan = Plan(args.obs, tuple(tasks), tuple(policies), demos=args.demos, steps=args.steps,
                batch=args.batch, episodes=args.episodes, noise=args.noise,
                noise_kind=args.noise_kind, sets=tuple(args.set), video=args.video)
    out = Path(args.out or f"runs/table_{args.obs}")
    failed = runner.run(plan, out, jobs=args.jobs, backend=args.backend)
    command = "rmbench " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    tables.write(plan, out, command, {job.name: err for job, err in failed.items()})
    print((out / "table.md").read_text())
    print(f"wrote {out / 'table.md'} and {out / 'table.json'}")
    if failed:
        print(f"rmbench: {len(failed)} job(s) failed (logs in {out / 'logs'}); a re-run "
              f"resumes what is missing", file=sys.stderr)
        return 1
    return 0


def cmd_train(args) -> int:
    from rmbench.cli.train import run_training

    result = run_training(args.policy, args.dataset, args.out, steps=args.steps,
                          batch_size=args.batch_size, device=args.device, seed=args.seed,
                          save_every=args.save_every, ablations=args.ablation or [],
                          overrides=args.set or [], workers=args.workers, progress=not args.json)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(f"trained {args.policy} for {result['steps']} steps "
              f"(resumed from {result['resumed_from']}); checkpoint in {args.out}")
    return 0


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
    p.add_argument("--seed", type=int, default=100000, help="first seed (seeds are consecutive)")
    p.add_argument("--workers", type=int, default=1)
    _add_json(p)
    p.set_defaults(func=cmd_robustness)

    p = sub.add_parser("collect", help="record expert demonstrations into a LeRobot v3.0 dataset")
    p.add_argument("task", help="task name or gym id (see `rmbench tasks`)")
    p.add_argument("--episodes", type=int, default=50, help="demonstrations wanted in all")
    p.add_argument("--seed", type=int, default=0, help="first candidate seed, in [0, 100000) "
                   "(evaluation uses 100000 and up)")
    p.add_argument("--out", required=True, help="dataset folder (resumed if it exists)")
    p.add_argument("--workers", type=int, default=1, help="local worker processes")
    p.add_argument("--cameras", nargs="+", metavar="CAM",
                   help="cameras to record (default: head left_wrist right_wrist)")
    p.add_argument("--resolution", type=_resolution, default=(320, 240), metavar="WxH")
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
    _add_json(p)
    p.set_defaults(func=cmd_collect)

    p = sub.add_parser("eval", help="evaluate a policy on expert-verified seeds")
    p.add_argument("--task", action="append", help="task name or gym id (repeatable)")
    p.add_argument("--all", action="store_true", help="every task")
    p.add_argument("--policy", required=True,
                   help="expert | random | noop | replay:DATASET | remote:ws://HOST:PORT | ...")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0,
                   help="evaluation seed s: episodes from 100000 * (1 + s) up")
    p.add_argument("--seeds-of", metavar="DATASET",
                   help="run the seeds DATASET's demonstrations were recorded on instead (the "
                        "layouts a policy trained on: its score there against --seed's held-out "
                        "layouts is what it memorised)")
    p.add_argument("--out", required=True, help="results folder (resumed if it exists)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--backend", choices=["local", "ray"], default="local")
    p.add_argument("--video", default="first:1", help="first:K | failures | none")
    p.add_argument("--instructions", choices=["seen", "unseen"], default="seen")
    _add_json(p)
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("train", help="train a learned policy on a dataset (resumes in --out)")
    p.add_argument("policy", choices=["mem0", "dp", "act"], help="which policy")
    p.add_argument("--dataset", required=True, help="an rmbench dataset folder")
    p.add_argument("--out", required=True, help="checkpoint folder (resumed if it exists)")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--batch-size", type=int, default=32)
    p.add_argument("--device", default="cpu", help="cpu | cuda")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--save-every", type=int, default=500)
    p.add_argument("--ablation", action="append",
                   help="Mem-0 only: no_anchor | no_sliding | no_memory | no_key (repeatable)")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE",
                   help="override a config field, VALUE as JSON (e.g. --set dim=64)")
    p.add_argument("--workers", type=int, default=0, help="data-loading processes")
    _add_json(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("open-loop", help="a policy's action error on recorded demonstrations, "
                                         "fed the recorded observations, beside holding still")
    p.add_argument("--policy", required=True, help="policy spec, e.g. mem0:CKPT")
    p.add_argument("--dataset", required=True, help="an rmbench dataset folder")
    p.add_argument("--episodes", type=int, nargs="+", default=[0, 1], metavar="E",
                   dest="indices", help="episode indices (default: 0 1)")
    _add_json(p)
    p.set_defaults(func=cmd_open_loop)

    p = sub.add_parser("report", help="tasks x policies table from evaluation folders")
    p.add_argument("dirs", nargs="+", metavar="DIR", help="rmbench eval output folders")
    p.add_argument("--out", default="report.md", help="report.md or report.html")
    p.add_argument("--published", nargs="*", metavar="POLICY",
                   help="add published success rates: DP ACT Pi0.5 X-VLA Mem-0")
    p.add_argument("--labels", nargs="+", metavar="NAME",
                   help="column names, one per DIR in order (default: the policy spec)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("table", help="the benchmark's tables in one resumable command: collect, "
                       "train every policy and ablation, evaluate, report")
    p.add_argument("--obs", choices=("state", "pixels"), required=True)
    p.add_argument("--tasks", default="all", help="comma-separated task names, or all")
    p.add_argument("--policies", default=None,
                   help="comma-separated: mem0, mem0:ABLATION (no_anchor, no_sliding, "
                        "no_memory, no_key, gt_classifier), dp, act (default: all of them; "
                        "no_key and gt_classifier on M(n) tasks only)")
    add_recipe_arguments(p)
    p.add_argument("--video", default="none", help="evaluation videos: first:K, failures, none")
    p.add_argument("--out", default=None, help="the table's folder (default runs/table_<obs>)")
    p.add_argument("--jobs", type=int, default=1,
                   help="jobs at once (local: each a process with cores/jobs torch threads)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="ray: jobs on a Ray cluster (RAY_ADDRESS); --out on a shared file system")
    p.set_defaults(func=cmd_table)

    p = sub.add_parser("serve", help="serve a policy over a websocket (msgpack-numpy)")
    p.add_argument("--policy", required=True, help="policy spec, e.g. random or replay:DATASET")
    p.add_argument("--task", required=True, help="the task the policy acts in")
    p.add_argument("--host", default="127.0.0.1", help="bind address (default: this machine only)")
    p.add_argument("--port", type=int, default=8000)
    p.set_defaults(func=cmd_serve)

    dataset.add_parser(sub, _add_json)

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
    episodes = getattr(args, "episodes", None)
    if episodes is not None and episodes < 1:
        print("rmbench: error: --episodes must be at least 1", file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except (UnknownTaskError, ValueError, RuntimeError) as err:
        print(f"rmbench: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rmbench: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
