"""Fit a trained Mem-0 checkpoint's planner again with other planner settings, keeping its
executor: a planner change measured in closed loop without training the executor again.

The planner trains before the executor, from the initialisation the training's seed draws,
on its own random generators, and is frozen after: a full training with the same seed and
the new settings has this executor and this planner, tensor for tensor (checked by
``benchmarks/planner_refit_check.py``: results/planner_refit_check.json).

    python benchmarks/planner_refit.py CKPT DATASET OUT --set planner_key_delay=12
    rmbench eval --task press_button --policy mem0:OUT --episodes 100 --out EVAL
"""

from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import fields, replace
from pathlib import Path

import torch

from rmbench.data.reader import Dataset
from rmbench.policies.checkpoint import save_checkpoint
from rmbench.policies.mem0.agent import load_mem0
from rmbench.policies.mem0.config import Mem0Config
from rmbench.policies.mem0.planner import DONE
from rmbench.policies.mem0.train import build_model, fit_planner
from rmbench.policies.nn.text import sentence_embeddings
from rmbench.training.loop import TrainConfig

PLANNER_FIELDS = {"planner_key_delay", "planner_steps", "planner_batch", "planner_lr",
                  "planner_layers"}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("checkpoint")
    p.add_argument("dataset", help="the dataset the checkpoint trained on")
    p.add_argument("out", type=Path)
    p.add_argument("--set", action="append", default=[], help="PLANNER_FIELD=VALUE")
    p.add_argument("--seed", type=int, default=0, help="the checkpoint's training seed")
    args = p.parse_args(argv)
    torch.set_num_threads(1)
    model, cfg, describe = load_mem0(args.checkpoint)
    types = {f.name: type(getattr(cfg, f.name)) for f in fields(Mem0Config)}
    changes = {}
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in PLANNER_FIELDS:
            raise SystemExit(f"--set {item}: not a planner field ({', '.join(sorted(PLANNER_FIELDS))})")
        changes[key] = types[key](value)
    cfg = replace(cfg, **changes)
    texts = describe["executor_texts"] + describe["planner_texts"]
    vectors = sentence_embeddings(texts)
    if vectors is not None:
        n = len(describe["executor_texts"])
        vectors = {"executor": vectors[:n], "planner": vectors[n:]}
    torch.manual_seed(args.seed)  # the initialisation the training drew
    fresh = dict(build_model(cfg, describe, vectors).planner.named_parameters())
    with torch.no_grad():  # the planner's parameters restart; its state statistics stay
        for name, param in model.planner.named_parameters():
            param.copy_(fresh[name])
    model.train()
    report = fit_planner(model, Dataset(args.dataset), cfg, TrainConfig(seed=args.seed),
                         describe["planner_texts"].index(DONE), False)
    model.eval()
    step = describe["step"]
    describe = {k: v for k, v in describe.items() if k not in ("step", "format")}
    describe["config"] = cfg.to_dict()
    describe["planner_refit"] = {"from": str(args.checkpoint), "set": changes, "report": report}
    if args.out.exists():
        shutil.rmtree(args.out)
    save_checkpoint(args.out, model, describe, step)
    print(json.dumps(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
