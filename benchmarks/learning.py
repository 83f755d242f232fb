"""Learning curve in one command: collect demonstrations of a task, train each policy on them
from the state observation or from the cameras, evaluate each on expert-verified seeds, and
tabulate what each learned with which memory.

    .venv/bin/python benchmarks/learning.py --task put_back_block --obs state \\
        [--policies mem0,mem0:no_memory,mem0:no_anchor,mem0:no_sliding,dp,act] [--demos 50] \\
        [--steps 3000] [--batch 32] [--episodes 100] [--noise SIGMA --noise-kind white|smooth] \\
        [--set FIELD=VALUE ...] [--out runs/learning/state] [--jobs N]

``--set`` overrides a field of every trained policy's config that has it (as ``rmbench train
--set``; a field no policy has is an error), e.g. ``--set head_layers=2 --set execute=20``;
the overrides name the training and evaluation folders, so runs with different ones coexist.

Checked end to end at toy scale (40 s on a loaded 2-core machine)::

    .venv/bin/python benchmarks/learning.py --task observe_and_pickup --obs state \\
        --policies mem0,mem0:no_memory,dp,act --demos 3 --steps 20 --episodes 2 \\
        --out /tmp/learning --results /tmp/learning/result.json

With ``--jobs 2`` the same toy run trains and evaluates two policies at once, one process
and one torch thread each (2 min 34 s beside two training runs).

This is ``rmbench table`` (``rmbench.suite``) for one task, with the results file below: the
same stages, folders and resumption. Every stage resumes, so a re-run after an interruption
does only what is missing:

- collection (``rmbench.data.collect``) continues the dataset in ``OUT/<task>/data``. With ``--obs
  state`` it records the smallest video collection allows (the head camera at 16x16; datasets
  hold at least one camera) beside ``observation.environment_state``, and the policies are
  trained with ``observation="state"``: no frame is decoded. With ``--obs pixels`` it records
  the three cameras at 320x240, as evaluation renders them;
- training (the shared loop) continues from ``OUT/<task>/train/<policy>-s<steps>-b<batch>``'s last
  saved state (every 500 steps); a finished run is not touched;
- evaluation (the harness) runs only the seeds missing from ``OUT/<task>/eval/<run>-e<episodes>``;
  the env gets the observation each checkpoint declares (the state for a state checkpoint).

Wall times are the sums over the calls that completed a stage's piece (a call killed midway
loses its own time, not what it saved). Writes ``benchmarks/results/learning_<obs>_<task>.json``
(or ``--results``): the command, and per policy its success rate, mean progress, endings (how
episodes ended, failure reasons counted), training and evaluation wall times and its memory.
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.eval.episode import ENDINGS
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.suite import cell_rows, data_stage, runner
from rmbench.suite.plan import Plan
from rmbench.suite.recipes import add_recipe_arguments, recipe_of
from rmbench.tasks import get_task

ROOT = Path(__file__).resolve().parent
POLICIES = ("mem0", "mem0:no_memory", "mem0:no_anchor", "mem0:no_sliding", "dp", "act")


def plan_noise(plan: Plan) -> dict | None:
    from rmbench.envs.noise import NoiseSpec

    return NoiseSpec(plan.noise_kind, plan.noise).to_dict() if plan.noise else None


def table(rows: dict[str, dict]) -> str:
    head = (f"{'policy':<18} {'success':>8} {'95% interval':>14} {'progress':>9} {'train s':>8} "
            f"{'eval s':>8}  "
            + " ".join(f"{e[:8]:>8}" for e in ENDINGS) + "  memory")
    lines = [head, "-" * len(head)]
    for spec, r in rows.items():
        low, high = r["success_ci95"] or (float("nan"), float("nan"))
        lines.append(f"{spec:<18} {100 * r['success_rate']:>7.1f}% "
                     f"{f'[{100 * low:.0f}, {100 * high:.0f}]':>14} {r['mean_progress']:>9.3f} "
                     f"{r['train_wall_s'] or 0:>8.0f} {r['eval_wall_s'] or 0:>8.0f}  "
                     + " ".join(f"{r['endings'].get(e, 0):>8}" for e in ENDINGS)
                     + f"  {r['memory']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--task", required=True)
    p.add_argument("--obs", choices=("state", "pixels"), required=True)
    p.add_argument("--policies", default=",".join(POLICIES),
                   help="comma-separated: mem0, mem0:ABLATION (no_memory, no_anchor, "
                        "no_sliding, no_key, gt_classifier), dp, act")
    add_recipe_arguments(p)
    p.add_argument("--out", type=Path, default=None,
                   help="data, checkpoints and evaluations, per task (default runs/learning/<obs>)")
    p.add_argument("--results", type=Path, default=None,
                   help="the JSON written (default benchmarks/results/learning_<obs>_<task>.json)")
    p.add_argument("--jobs", type=int, default=1,
                   help="policies trained and evaluated at once, each in its own process with "
                        "cores / jobs torch threads (logs in OUT/logs)")
    args = p.parse_args(argv)
    try:
        task = get_task(args.task)
        plan = Plan(args.obs, (task.name,), tuple(s.strip() for s in args.policies.split(",")
                                                  if s.strip()),
                    **recipe_of(args))
    except ValueError as err:
        raise SystemExit(f"learning.py: {err}") from None
    noise = f"_{args.noise_kind}{args.noise:g}" if args.noise else ""
    out = args.out or ROOT.parent / "runs" / "learning" / f"{args.obs}{noise}"
    results_path = args.results or ROOT / "results" / f"learning_{args.obs}_{task.name}{noise}.json"
    failed = runner.run(plan, out, jobs=args.jobs)
    if failed:
        raise SystemExit("; ".join(f"{job.name}: {err}" for job, err in failed.items())
                         + " (a re-run resumes)")
    rows = {spec: cell_rows.cell_row(plan, out, task.name, spec) for _, spec in plan.cells()}
    command = "python benchmarks/learning.py " + " ".join(
        shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    result = {"command": command, "task": task.name, "tmc": task.tmc, "obs": args.obs,
              "demos": args.demos, "steps": args.steps, "batch": args.batch, "set": args.set,
              "episodes": args.episodes, "noise": plan_noise(plan),
              "dataset": data_stage.collect_stage(plan, out, task.name), "policies": rows,
              "machine": {**describe(), "jobs": args.jobs,
                          "torch_threads": max(1, (os.cpu_count() or 1) // args.jobs)}}
    results_path.parent.mkdir(parents=True, exist_ok=True)
    write_json(results_path, result)
    print(table(rows))
    print(f"wrote {results_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
