"""The memory probe of an evaluation folder against a memoryless control, as a results JSON.

    rmbench eval --task put_back_block --policy mem0:CKPT --episodes 100 --seed 0 \
        --out EVAL --memory-reset aliasing
    python benchmarks/memory_probe.py --eval EVAL --task put_back_block \
        --reference benchmarks/results/learning_state_put_back_block_layout_copies.json \
        --reference-cell mem0:no_memory --out benchmarks/results/memory_probe_state_put_back_block.json

Writes the policy's rate without and with the probe (Wilson 95% intervals), the drop with
Newcombe's 95% interval, and the probed rate against the reference cell (a policy trained
without memory on the same recipe, from a results JSON of ``benchmarks/learning.py`` or a
table.json): whether wiping the memory at the aliasing moment brings the policy down to
its memoryless control.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from rmbench.eval.intervals import difference, format_difference, outside_noise, wilson
from rmbench.eval.report import Rate
from rmbench.files import write_json
from rmbench.machine import describe


def reference_cell(path: Path, task: str, cell: str) -> dict:
    """successes and episodes of ``cell`` in a learning.py results JSON or a table.json."""
    data = json.loads(path.read_text())
    row = (data["policies"] if "policies" in data else data["cells"][task]).get(cell)
    if not row:
        raise SystemExit(f"{path}: no {cell} cell for {task}")
    n = row["episodes"]
    return {"source": str(path), "cell": cell, "episodes": n, "successes": Rate.of(row).successes,
            "success_rate": row["success_rate"]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--eval", required=True, help="an rmbench eval folder with a memory probe")
    p.add_argument("--task", required=True)
    p.add_argument("--probe", default="aliasing", help="the probe's name (aliasing, every-K)")
    p.add_argument("--reference", required=True, help="results JSON holding the control cell")
    p.add_argument("--reference-cell", default="mem0:no_memory")
    p.add_argument("--out", required=True, help="results JSON to write")
    args = p.parse_args(argv)

    summary = json.loads((Path(args.eval) / "summary.json").read_text())
    task = summary["tasks"][args.task]
    probe = task.get("memory_reset", {}).get(args.probe)
    if not probe or not probe.get("episodes"):
        raise SystemExit(f"{args.eval}: no {args.probe} probe for {args.task} "
                         f"(rmbench eval ... --memory-reset)")
    ref = reference_cell(Path(args.reference), args.task, args.reference_cell)
    ref["success_ci95"] = [round(v, 4) for v in wilson(ref["successes"], ref["episodes"])]
    k, n = probe["with"]["successes"], probe["episodes"]
    d, low, high = difference(k, n, ref["successes"], ref["episodes"])
    run = json.loads((Path(args.eval) / "run.json").read_text())
    result = {"command": "python " + " ".join(shlex.quote(a) for a in sys.argv),
              "task": args.task, "policy": summary["policy"], "evaluation": run,
              "probe": args.probe, **probe, "mean_progress_without": task["mean_progress"],
              "reference": ref,
              "with_minus_reference": {"difference": round(d, 4),
                                       "ci95": [round(low, 4), round(high, 4)],
                                       "outside_noise": outside_noise(k, n, ref["successes"],
                                                                      ref["episodes"])},
              "machine": describe()}
    write_json(Path(args.out), result)
    w, r = probe["without"], probe["with"]
    print(f"{args.task}: {w['successes']}/{n} without the probe, {r['successes']}/{n} with it "
          f"(drop {format_difference(probe['drop'], *probe['drop_ci95'], digits=1)}); "
          f"{args.reference_cell} {ref['successes']}/{ref['episodes']}, probed minus it "
          f"{format_difference(d, low, high, digits=1)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
