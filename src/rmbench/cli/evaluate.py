"""``rmbench eval``, ``open-loop``, ``report``, ``table`` and ``serve``: policies measured."""

from __future__ import annotations

import argparse
import json
import sys

from rmbench.cli.common import add_json, whole, width_height
from rmbench.seeds import SPLITS
from rmbench.suite.recipes import add_recipe_arguments


def cmd_eval(args) -> int:
    from rmbench.eval import EvalConfig, evaluate
    from rmbench.tasks.registry import ordered

    tasks = [c.name for c in ordered()] if args.all else (args.task or [])
    if not tasks:
        raise ValueError("name a task with --task, or --all")
    cfg = EvalConfig(tuple(tasks), args.policy, args.out, episodes=args.episodes, seed=args.seed,
                     workers=args.workers, batch=args.batch, backend=args.backend,
                     video=args.video,
                     instructions=args.instructions, progress=not args.json,
                     seeds_of=args.seeds_of, memory_reset=args.memory_reset,
                     split=args.split)
    summary = evaluate(cfg)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        from rmbench.eval.summary import drop_text, rate_text

        for task, r in summary["tasks"].items():
            print(f"{task:<20} {r['tmc']:<5} success {r['successes']:>3}/{r['episodes']:<3} "
                  f"({rate_text(r)})  progress {r['mean_progress']:.3f}")
            for name, c in r.get("memory_reset", {}).items():
                if c.get("episodes"):
                    print(f"{'':<20} memory reset {name}: {rate_text(c['with'], c['episodes'])}"
                          f" against {rate_text(c['without'], c['episodes'])}, drop "
                          f"{drop_text(c)} points"
                          + ("" if c["outside_noise"] else " (within the noise)"))
        print(f"records and summary in {args.out}")
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


def cmd_boundaries(args) -> int:
    from pathlib import Path

    from rmbench.eval.boundaries import VERDICTS, boundary_counts
    from rmbench.eval.records import read_records

    folder = Path(args.dir)
    tasks = sorted(p.parent.name for p in folder.glob("*/episodes.jsonl"))
    if not tasks:
        raise ValueError(f"{folder}: no <task>/episodes.jsonl (not an `rmbench eval` folder)")
    print("| task | episodes | " + " | ".join(VERDICTS) + " | median delay | first wrong |")
    print("|---|---|" + "---|" * len(VERDICTS) + "---|---|")
    for task in tasks:
        s = boundary_counts(read_records(folder / task / "episodes.jsonl"))
        if s is None:
            print(f"| {task} | no subtask ends declared by the policy |" + " |" * (len(VERDICTS) + 1))
            continue
        first = ", ".join(f"{k} {v}" for k, v in s["first_wrong"].items()) or "-"
        capped = f" ({s['capped']} more past the event limit, left out)" if "capped" in s else ""
        print(f"| {task} | {s['episodes']}{capped} | " + " | ".join(str(s[v]) for v in VERDICTS)
              + f" | {s['median_delay']} | {first} |")
    return 0


def cmd_table(args) -> int:
    import shlex
    from pathlib import Path

    from rmbench.suite import data_stage, runner, tables
    from rmbench.suite.plan import COLUMNS, Plan, with_seed
    from rmbench.suite.recipes import RECIPES, recipe_of
    from rmbench.tasks.registry import ordered

    tasks = ([t.name for t in ordered()] if args.tasks == "all"
             else [t.strip() for t in args.tasks.split(",") if t.strip()])
    policies = [p.strip() for p in (args.policies or ",".join(COLUMNS[args.obs])).split(",") if p.strip()]
    try:
        seeds = [int(s) for s in args.train_seeds.split(",") if s.strip()]
    except ValueError:
        seeds = []
    if not seeds or min(seeds) < 0:
        raise ValueError(f"--train-seeds takes whole numbers >= 0, got {args.train_seeds!r}")
    policies = [with_seed(p, s) for p in policies for s in seeds]
    plan = Plan(args.obs, tuple(tasks), tuple(policies), video=args.video, device=args.device,
                split=args.split,
                **recipe_of(args, None if args.no_recipe else RECIPES[args.obs]))
    out = Path(args.out or f"runs/table_{args.obs}")
    if args.report_only:
        # a table built a few cells at a time (calls narrowed with --tasks and --policies)
        # is reported whole from what its folder holds
        if not out.is_dir() or not any((out / t).is_dir() for t in plan.tasks):
            raise ValueError(f"no table at {out}: no folder of {', '.join(plan.tasks)} "
                             f"(--report-only runs nothing)")
        data_stage.check_data(plan, out)
        failed = {}
    else:
        failed = runner.run(plan, out, jobs=args.jobs, backend=args.backend)
    # the command that makes these cells (a report reads what that command writes), which
    # the results record beside each cell
    command = "rmbench " + " ".join(shlex.quote(a) for a in args.argv if a != "--report-only")
    tables.write(plan, out, command, {job.name: err for job, err in failed.items()})
    print((out / "table.md").read_text())
    print(f"wrote {out / 'table.md'} and {out / 'table.json'}")
    if failed:
        print(f"rmbench: {len(failed)} job(s) failed (logs in {out / 'logs'}); a re-run "
              f"resumes what is missing", file=sys.stderr)
        return 1
    return 0


def cmd_serve(args) -> int:
    from rmbench.serve.server import PolicyServer
    from rmbench.tasks import get_task

    PolicyServer(args.policy, get_task(args.task).name, args.host, args.port,
                 max_connections=args.max_connections, idle_timeout=args.idle_timeout,
                 origins=args.origin, frame_max=args.frame_max[::-1]).serve_forever()
    return 0


class PolicyHelp(argparse.Action):
    """``-h``/``--help`` that ends with the registered policies, plugins included. The plugins
    are imported only when the help is asked for, so no other command pays for them."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS,
                 help=None):
        super().__init__(option_strings, dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from rmbench.policies.registry import registered_policies

        entries = registered_policies()
        names = [e.name + (":ARG" if e.needs_argument else "") for e in entries]
        width = max(map(len, names), default=0)
        parser.epilog = "policies (--policy):\n" + "\n".join(
            f"  {name:<{width}}  {e.help}" for name, e in zip(names, entries, strict=True))
        parser.print_help()
        parser.exit()


def policy_parser(sub, name: str, help: str) -> argparse.ArgumentParser:
    """A subcommand taking ``--policy``, whose help lists the policies it can run."""
    p = sub.add_parser(name, help=help, add_help=False,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-h", "--help", action=PolicyHelp,
                   help="show this help message, with the registered policies, and exit")
    return p


def add_parsers(sub) -> None:
    p = policy_parser(sub, "eval", "evaluate a policy on expert-verified seeds")
    p.add_argument("--task", action="append", help="task name or gym id (repeatable)")
    p.add_argument("--all", action="store_true", help="every task")
    p.add_argument("--policy", required=True,
                   help="expert | random | noop | replay:DATASET | remote:ws://HOST:PORT | "
                        "... (every registered policy: below)")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--seed", type=int, default=0,
                   help="evaluation seed s: episodes from 100000 * (1 + s) up")
    p.add_argument("--split", choices=SPLITS, default="test",
                   help="test: the evaluation seed's test episodes, the ones tables report; "
                        "validation: its validation episodes, disjoint from them, where recipes "
                        "are chosen and compared (from 100000 * (1 + s) + 50000 up)")
    p.add_argument("--seeds-of", metavar="DATASET",
                   help="run the seeds DATASET's demonstrations were recorded on instead (the "
                        "layouts a policy trained on: its score there against --seed's held-out "
                        "layouts is what it memorised)")
    p.add_argument("--memory-reset", metavar="aliasing|every:K",
                   help="memory probe: also run the same seeds with the policy reset at the "
                        "task's aliasing moment (or every K steps); the summary gives both "
                        "rates and the drop with its 95%% interval. Adds to a folder already "
                        "evaluated without it")
    p.add_argument("--out", required=True, help="results folder (resumed if it exists)")
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--batch", type=int, default=8,
                   help="episodes each worker plays side by side, the policy asked once per "
                        "step for all of them (a policy with act_batch; others play one at a "
                        "time)")
    p.add_argument("--backend", choices=["local", "ray"], default="local")
    p.add_argument("--video", default="first:1", help="first:K | failures | none")
    p.add_argument("--instructions", choices=["seen", "unseen"], default="seen")
    add_json(p)
    p.set_defaults(func=cmd_eval)

    p = policy_parser(sub, "open-loop", "a policy's action error on recorded demonstrations, "
                                        "fed the recorded observations, beside holding still")
    p.add_argument("--policy", required=True, help="policy spec, e.g. mem0:CKPT")
    p.add_argument("--dataset", required=True, help="an rmbench dataset folder")
    p.add_argument("--episodes", type=int, nargs="+", default=[0, 1], metavar="E",
                   dest="indices", help="episode indices (default: 0 1)")
    add_json(p)
    p.set_defaults(func=cmd_open_loop)

    p = sub.add_parser("report", help="tasks x policies table from evaluation folders")
    p.add_argument("dirs", nargs="+", metavar="DIR", help="rmbench eval output folders")
    p.add_argument("--out", default="report.md", help="report.md or report.html")
    p.add_argument("--published", nargs="*", metavar="POLICY",
                   help="add published success rates: DP ACT Pi0.5 X-VLA Mem-0")
    p.add_argument("--labels", nargs="+", metavar="NAME",
                   help="column names, one per DIR in order (default: the policy spec)")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("boundaries", help="where a policy declared its subtask ends against "
                       "where the simulator counted them (early, on time, late, missed, false)")
    p.add_argument("dir", help="an `rmbench eval` folder")
    p.set_defaults(func=cmd_boundaries)

    p = sub.add_parser("table", help="the benchmark's tables in one resumable command: collect, "
                       "train every policy and ablation, evaluate, report")
    p.add_argument("--obs", choices=("state", "pixels"), required=True)
    p.add_argument("--tasks", default="all", help="comma-separated task names, or all")
    p.add_argument("--policies", default=None,
                   help="comma-separated: mem0, mem0:ABLATION[+ABLATION...] (no_anchor, "
                        "no_sliding, no_memory, no_key, gt_classifier), dp, act (default: "
                        "those and mem0:no_memory+no_key; with --obs pixels all but no_anchor "
                        "and no_sliding; a column with no_key or gt_classifier on M(n) tasks "
                        "only); SPEC@N: trained with seed N")
    p.add_argument("--train-seeds", default="0", metavar="N[,N...]",
                   help="train every column with each of these seeds; its cell pools their "
                        "evaluations (the mean over seeds), each seed's row kept (default 0)")
    add_recipe_arguments(p, defaults="recipe")
    p.add_argument("--no-recipe", action="store_true",
                   help="start from the generic defaults (3,000 steps at batch 32, no noise, no "
                        "--set items) instead of the --obs recipe: a quick or custom table")
    p.add_argument("--video", default="none", help="evaluation videos: first:K, failures, none")
    p.add_argument("--split", choices=SPLITS, default="test",
                   help="the cells' evaluation episodes: test (what a table reports) or "
                        "validation (disjoint from them: where a recipe is chosen)")
    p.add_argument("--device", default="cpu",
                   help="where the cells train: cpu | cuda | cuda:N (a run started on a GPU "
                        "resumes on a CPU; collection and evaluation stay on the CPU)")
    p.add_argument("--out", default=None,
                   help="the table's folder (default runs/table_<obs>), resumed if it exists; "
                        "one table runs in it at a time, and the demonstrations it holds must "
                        "be this table's (other --demos, --noise or --obs: another --out)")
    p.add_argument("--jobs", type=int, default=1,
                   help="jobs at once (local: each a process with (usable cores) / --jobs "
                        "torch threads, usable being this process's affinity; on a shared "
                        "machine start the table under taskset -c). Where no other job can "
                        "start, a collection or evaluation takes the idle jobs' cores too")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="ray: jobs on a Ray cluster (RAY_ADDRESS); --out on a shared file system")
    p.add_argument("--report-only", action="store_true",
                   help="run nothing: write table.md and table.json for these tasks and policies "
                        "from the cells --out already holds")
    p.set_defaults(func=cmd_table)

    p = policy_parser(sub, "serve", "serve a policy over a websocket (msgpack-numpy)")
    p.add_argument("--policy", required=True, help="policy spec, e.g. random or replay:DATASET")
    p.add_argument("--task", required=True, help="the task the policy acts in")
    p.add_argument("--host", default="127.0.0.1", help="bind address (default: this machine only)")
    p.add_argument("--port", type=whole(0, 65535), default=8000,
                   help="TCP port (default 8000; 0: any free one)")
    p.add_argument("--max-connections", type=int, default=4,
                   help="clients served at once; more are refused (default 4)")
    p.add_argument("--idle-timeout", type=float, default=300.0, metavar="SECONDS",
                   help="close a connection that sends nothing for this long (default 300)")
    p.add_argument("--origin", action="append", metavar="ORIGIN",
                   help="accept only browsers' connections from this Origin (repeatable); "
                        "default: no check (a web page on this machine can then connect)")
    p.add_argument("--frame-max", type=width_height, default=(640, 480), metavar="WxH",
                   help="the largest camera frame accepted (default 640x480)")
    p.set_defaults(func=cmd_serve)
