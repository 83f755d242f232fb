"""One job of a table: collect a task's demonstrations, train a cell's checkpoint or evaluate
it, in its own process (``python -m rmbench.suite.job``, the local backend) or in a Ray
worker (``run_job``). Output goes to the job's log file; the stage's own files are the result.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import sys
from pathlib import Path

from rmbench import source
from rmbench.parallel import exit_with_parent
from rmbench.suite import data_stage, stages
from rmbench.suite.plan import Plan

KINDS = ("collect", "train", "eval")


def source_digest() -> str:
    """One hash of the rmbench source this process imported."""
    return hashlib.sha1(json.dumps(source.AT_IMPORT, sort_keys=True).encode()).hexdigest()


def run_job(plan: dict, out: str, kind: str, task: str, spec: str, threads: int,
            digest: str, log: str | None = None) -> None:
    """Run one stage (``data_stage``, ``stages``), refusing if this process imported other rmbench source than
    the table's runner (a table must not mix two versions of the code)."""
    if digest != source_digest():
        raise source.SourceChangedError(
            "the rmbench source changed since the table started; re-run the table command "
            "(finished cells are kept)")
    if kind not in KINDS:
        raise ValueError(f"job kind must be one of {KINDS}, got {kind!r}")
    import torch

    torch.set_num_threads(max(1, threads))
    p, out_dir = Plan.from_dict(plan), Path(out)
    with contextlib.ExitStack() as stack:
        if log is not None:  # a Ray worker: its output to the job's log, as a subprocess's
            f = stack.enter_context(open(log, "a"))
            stack.enter_context(contextlib.redirect_stdout(f))
            stack.enter_context(contextlib.redirect_stderr(f))
        # a job's share of the cores: torch threads in training, worker processes in
        # collection and evaluation (whose results do not depend on their number)
        if kind == "collect":
            data_stage.collect_stage(p, out_dir, task, workers=max(1, threads))
        elif kind == "train":
            stages.train_stage(p, out_dir, task, spec)
        else:
            stages.eval_stage(p, out_dir, task, spec, workers=max(1, threads))


def main(argv: list[str] | None = None) -> int:
    a = argparse.ArgumentParser(description="one job of `rmbench table`")
    a.add_argument("--plan", required=True, help="the table's plan as JSON")
    a.add_argument("--out", required=True)
    a.add_argument("--kind", required=True, choices=KINDS)
    a.add_argument("--task", required=True)
    a.add_argument("--spec", default="")
    a.add_argument("--threads", type=int, default=1)
    a.add_argument("--digest", required=True)
    a.add_argument("--parent", type=int, required=True,
                   help="the pid of the table's runner: the job ends when it does")
    args = a.parse_args(argv)
    exit_with_parent(args.parent)
    try:
        run_job(json.loads(args.plan), args.out, args.kind, args.task, args.spec, args.threads,
                args.digest)
    except (ValueError, RuntimeError, OSError) as err:
        print(f"error: {type(err).__name__}: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
