"""Check that a planner refit (``benchmarks/planner_refit.py``) is what a full training with
the new planner settings holds: the full training's planner equals the refit's tensor for
tensor, and its losses equal the original training's at every logged step (the executor's
training does not read the planner's settings).

    python benchmarks/planner_refit_check.py FULL ORIGINAL REFIT \\
        [--out benchmarks/results/planner_refit_check.json]

FULL: a training folder with the new settings (finished or not: its planner trains first);
ORIGINAL: the checkpoint the refit came from; REFIT: the refit. The result is added to
``--out`` under REFIT's folder name.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from safetensors.torch import load_file

from rmbench.files import write_json
from rmbench.training.curve import CURVE_CSV
from rmbench.training.state import STATE

OUT = Path(__file__).resolve().parent / "results" / "planner_refit_check.json"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("full", type=Path)
    p.add_argument("original", type=Path)
    p.add_argument("refit", type=Path)
    p.add_argument("--out", type=Path, default=OUT)
    args = p.parse_args(argv)
    state = torch.load(args.full / STATE, weights_only=True, map_location="cpu")
    model, refit = state["model"], load_file(args.refit / "model.safetensors")
    names = [k for k in refit if k.startswith("planner.")]
    same = sum(torch.equal(model[f"model.{k}"], refit[k]) for k in names)
    full_curve = (args.full / CURVE_CSV).read_text().splitlines()
    original_curve = (args.original / CURVE_CSV).read_text().splitlines()
    rows = len(full_curve) - 1  # the header
    identical = full_curve == original_curve[:len(full_curve)]
    task = json.loads((args.refit / "config.json").read_text())["task"]
    doc = json.loads(args.out.read_text()) if args.out.exists() else {}
    doc[args.refit.name] = {"task": task, "full_training_step": state["step"], "planner_tensors": len(names),
                 "planner_tensors_equal": int(same), "loss_rows": rows,
                 "loss_rows_equal": identical, "full": str(args.full),
                 "original": str(args.original), "refit": str(args.refit)}
    write_json(args.out, doc)
    print(json.dumps(doc[args.refit.name]))
    return 0 if names and rows > 0 and same == len(names) and identical else 1


if __name__ == "__main__":
    raise SystemExit(main())
