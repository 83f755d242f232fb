"""Recipe probes on the validation episodes: each ``rmbench eval --split validation`` folder
given becomes one row of benchmarks/results/validation_probes.json (the task, what the
checkpoint reads (state or pixels: which table the probe is for), the checkpoint and what the
probe changes, success with its Wilson 95% interval, how the episodes ended and in which stage
of the task's plan the failed ones did), so a recipe choice reads episodes that no table
reports.

    python benchmarks/validation_probes.py --probe "CHANGE=FOLDER" [--probe ...]
        [--out benchmarks/results/validation_probes.json]

CHANGE says in words what the probe changes against the table's recipe ("the recipe" for
the checkpoint as trained), and may hold "=" (``mem0.sliding_window=16``): the folder is what
follows the last one. A probe of the same task, policy and change replaces its row.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rmbench.eval.endings import failures_by_stage
from rmbench.eval.harness import read_records
from rmbench.eval.rows import put_row

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
    checkpoint = Path(run["policy"].partition(":")[2].split("?")[0])
    try:  # which table the probe chooses for: what its checkpoint reads
        obs = json.loads((checkpoint / "config.json").read_text())["config"]["observation"]
    except (OSError, json.JSONDecodeError, KeyError) as err:
        raise SystemExit(f"{folder}: its policy's checkpoint config does not say what it "
                         f"reads ({err})") from None
    failed_at = failures_by_stage(read_records(records)) if records.exists() else None
    return {"task": task, "obs": obs, "change": change, "policy": run["policy"], "seed": run["seed"],
            "episodes": res["episodes"], "successes": res["successes"],
            "success_rate": res["success_rate"], "success_ci95": res["success_ci95"],
            "endings": res["endings"], "failed_at": failed_at, "gym_id": res.get("gym_id"),
            "command": f"rmbench eval --task {task} --policy '{run['policy']}' --episodes "
                       f"{run['episodes']} --split validation --seed {run['seed']}"}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--probe", action="append", required=True, metavar="CHANGE=FOLDER")
    p.add_argument("--trained-by", metavar="COMMAND",
                   help="the command that trained the probes' checkpoint, where the probe "
                        "changes the training (kept in their rows as trained_by)")
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    for item in args.probe:
        change, sep, folder = item.rpartition("=")
        if not sep or not change.strip():
            raise SystemExit(f"--probe {item!r}: give CHANGE=FOLDER")
        row = probe_row(change.strip(), Path(folder))
        if args.trained_by:
            row["trained_by"] = args.trained_by
        put_row(args.out, row, key=("task", "policy", "change"), field="probes")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
