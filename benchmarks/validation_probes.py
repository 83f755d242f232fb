"""Recipe probes on the validation episodes: each ``rmbench eval --split validation`` folder
given becomes one row of benchmarks/results/validation_probes.json (the task, what the
checkpoint reads (state or pixels: which table the probe is for), the checkpoint and what the
probe changes, success with its Wilson 95% interval, how the episodes ended and in which stage
of the task's plan the failed ones did, and an M(n) policy's choices at the ends it declared
against the plan, ``eval/decisions.py``, with its planner's fit), so a recipe choice reads
episodes that no table reports.

    python benchmarks/validation_probes.py --probe "CHANGE=FOLDER" [--probe ...]
        [--out benchmarks/results/validation_probes.json]

CHANGE says in words what the probe changes against the table's recipe ("the recipe" for
the checkpoint as trained), and may hold "=" (``mem0.sliding_window=16``): the folder is what
follows the last one. A probe of the same task, policy and change replaces its row.
"""

from __future__ import annotations

import argparse
import filecmp
import json
from pathlib import Path

from rmbench.eval.decisions import decision_counts
from rmbench.eval.endings import failures_by_stage
from rmbench.eval.records import read_records
from rmbench.eval.rows import put_row
from rmbench.policies.builtin import checkpoint_observation
from rmbench.policies.config import split_policy
from rmbench.suite.records import planner_report

OUT = Path(__file__).resolve().parent / "results" / "validation_probes.json"


def probe_row(change: str, folder: Path) -> dict:
    """One validation evaluation's row; a folder of test episodes, or not finished, is a
    SystemExit saying so."""
    try:
        run = json.loads((folder / "run.json").read_text())
        summary = json.loads((folder / "summary.json").read_text())
    except (OSError, json.JSONDecodeError) as err:
        raise SystemExit(f"{folder}: not a finished evaluation ({err})") from None
    if run.get("split") != "validation":
        raise SystemExit(f"{folder}: evaluated on the {run.get('split', 'test')} episodes, not "
                         f"the validation ones")
    ((task, res),) = summary["tasks"].items()
    if res["episodes"] < run["episodes"]:
        raise SystemExit(f"{folder}: {res['episodes']} of {run['episodes']} episodes so far")
    records = folder / task / "episodes.jsonl"  # where the failures ended, where kept
    # which table the probe chooses for: what its checkpoint reads
    obs = checkpoint_observation(split_policy(run["policy"])[1] or None)
    if obs is None:
        raise SystemExit(f"{folder}: {run['policy']!r} is not a trained checkpoint whose "
                         f"config can be read, so the table it is for is not known")
    kept = read_records(records) if records.exists() else None
    failed_at = failures_by_stage(kept) if kept is not None else None
    # an M(n) policy's choices at the ends it declared: where its memory is read
    decisions = decision_counts(kept) if kept is not None else None
    return {"task": task, "obs": obs, "change": change, "policy": run["policy"], "seed": run["seed"],
            "episodes": res["episodes"], "successes": res["successes"],
            "success_rate": res["success_rate"], "success_ci95": res["success_ci95"],
            "endings": res["endings"], "failed_at": failed_at, "decisions": decisions,
            "planner": planner_report(Path(split_policy(run["policy"])[1])),
            "gym_id": res.get("gym_id"),
            "command": f"rmbench eval --task {task} --policy '{run['policy']}' --episodes "
                       f"{run['episodes']} --split validation --seed {run['seed']}"}


def same_weights(row: dict, checkpoint: Path) -> dict:
    """``row`` naming ``checkpoint`` in place of the one evaluated, whose weights are the same
    bytes (a refit run again into a table's folder); a SystemExit where they are not."""
    kind, path, query = split_policy(row["policy"])
    ours, theirs = Path(path) / "model.safetensors", checkpoint / "model.safetensors"
    if not (ours.is_file() and theirs.is_file() and filecmp.cmp(ours, theirs, shallow=False)):
        raise SystemExit(f"{checkpoint}: its weights are not those of {path}")
    return {**row, "policy": f"{kind}:{checkpoint}" + (f"?{query}" if query else ""),
            "evaluated_as": row["policy"]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--probe", action="append", required=True, metavar="CHANGE=FOLDER")
    p.add_argument("--trained-by", metavar="COMMAND",
                   help="the command that trained the probes' checkpoint, where the probe "
                        "changes the training (kept in their rows as trained_by)")
    p.add_argument("--same-weights-as", metavar="CKPT", type=Path,
                   help="the probe's checkpoint holds CKPT's weights byte for byte (checked): "
                        "its row names CKPT, and the folder evaluated as evaluated_as (one "
                        "--probe)")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    if args.same_weights_as and len(args.probe) != 1:
        raise SystemExit("--same-weights-as names the checkpoint of one --probe")
    for item in args.probe:
        change, sep, folder = item.rpartition("=")
        if not sep or not change.strip():
            raise SystemExit(f"--probe {item!r}: give CHANGE=FOLDER")
        row = probe_row(change.strip(), Path(folder))
        if args.trained_by:
            row["trained_by"] = args.trained_by
        if args.same_weights_as:
            row = same_weights(row, args.same_weights_as)
        put_row(args.out, row, key=("task", "policy", "change"), field="probes")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
