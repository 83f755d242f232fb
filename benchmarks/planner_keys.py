"""How a Mem-0 planner's decisions hold up when its key frames come late: at run time a key
is the frame the end classifier declared the end at, some steps after the step ended.

Teacher-forced on a dataset's demonstrations, each key frame is taken ``delay`` frames after
its step's end (capped at the episode's last frame) and the planner's choice after every
finished step is compared with the demonstration's. Writes, per checkpoint and delay, the
decisions right and the episodes whose every decision is right.

    python benchmarks/planner_keys.py --dataset runs/table_state/press_button/data \\
        --checkpoint NAME=CKPT [--checkpoint NAME=CKPT ...] --out benchmarks/results/planner_keys.json
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import torch

from rmbench.data.reader import Dataset
from rmbench.files import write_json
from rmbench.policies.mem0.agent import load_mem0
from rmbench.policies.mem0.planner import DONE, planner_examples
from rmbench.policies.mem0.train import planner_batch, planner_frames

DELAYS = (0, 2, 4, 6, 8, 10, 12)


def decisions(model, frames, done: int, ds: Dataset, delay: int) -> dict[str, int]:
    right = total = episodes = 0
    for e in range(ds.num_episodes):
        ep = ds.episode(e, cameras=[])
        last = len(ep.subtask_step) - 1
        xs = [replace(x, keys=tuple((s, min(f + delay, last)) for s, f in x.keys),
                      current=min(x.current + delay, last))
              for x in planner_examples(e, ep.subtask_index, ep.subtask_step, done)]
        with torch.no_grad():
            b = planner_batch(model.planner, frames, xs, None, "cpu")
            logits = model.planner(b["first"], b["keys"], b["key_text"], b["key_valid"])
        logits[[not x.keys for x in xs], done] = -torch.inf  # as the policy: no "done" first
        good = logits.argmax(-1) == b["target"]
        right, total, episodes = right + int(good.sum()), total + len(xs), episodes + int(good.all())
    return {"delay": delay, "decisions_right": right, "decisions": total,
            "episodes_all_right": episodes, "episodes": ds.num_episodes}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--dataset", required=True)
    p.add_argument("--checkpoint", action="append", required=True, help="NAME=FOLDER")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--note", default="", help="how the checkpoints were made, in words")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    ds = Dataset(args.dataset)
    rows = {}
    for item in args.checkpoint:
        name, _, ckpt = item.partition("=")
        model, cfg, describe = load_mem0(ckpt)  # once per checkpoint: every delay reads it
        frames, done = planner_frames(ds, cfg), describe["planner_texts"].index(DONE)
        rows[name] = {"checkpoint": ckpt, "planner_key_delay": cfg.planner_key_delay,
                      "delays": [decisions(model, frames, done, ds, d) for d in DELAYS]}
        for r in rows[name]["delays"]:
            print(f"{name} delay {r['delay']:2d}: decisions {r['decisions_right']}/{r['decisions']}, "
                  f"episodes all right {r['episodes_all_right']}/{r['episodes']}")
    doc = {"task": ds.task, "dataset": args.dataset, "episodes": ds.num_episodes,
           "note": args.note, "checkpoints": rows}
    write_json(args.out, doc)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
