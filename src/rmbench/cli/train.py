"""What ``rmbench train POLICY`` runs: the policy's config from defaults, ``--ablation`` and
``--set FIELD=VALUE`` overrides, then its training function."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

from rmbench.cli.common import add_json, whole


def run_training(policy: str, dataset: str, out: str, *, steps: int, batch_size: int, device: str,
                 seed: int, save_every: int, ablations: list[str], overrides: list[str],
                 workers: int = 0, progress: bool = True,
                 executor_from: str | None = None) -> dict[str, Any]:
    # Imported here: torch takes seconds to import, and only training needs it.
    from rmbench.policies.config import parse_overrides
    from rmbench.policies.trainable import trainable
    from rmbench.training.loop import TrainConfig

    train_cfg = TrainConfig(steps=steps, batch_size=batch_size, device=device, seed=seed,
                            save_every=save_every)
    config_cls, fit = trainable(policy)
    if policy == "mem0":
        from rmbench.policies.mem0.config import TRAINED_ABLATIONS

        bad = [a for a in ablations if a not in TRAINED_ABLATIONS]
        if bad:
            raise ValueError(f"--ablation {bad[0]} is not a training ablation; training "
                             f"ablations: {', '.join(TRAINED_ABLATIONS)} (gt_classifier is "
                             f"chosen at evaluation: mem0:CKPT?ablation=gt_classifier)")
    elif ablations or executor_from:
        raise ValueError(f"--ablation and --executor-from are Mem-0's; {policy} has neither")
    try:
        cfg = config_cls(**parse_overrides(config_cls, overrides))
    except (TypeError, ZeroDivisionError) as err:  # (a value of the wrong type or size)
        raise ValueError(f"--set {' '.join(overrides)}: {err}") from None
    if ablations:
        cfg = replace(cfg, ablations=tuple(ablations))
    extra = {} if executor_from is None else {"executor_from": executor_from}
    return fit(dataset, out, cfg, train_cfg, progress=progress, workers=workers, **extra)


def cmd_train(args) -> int:
    result = run_training(args.policy, args.dataset, args.out, steps=args.steps,
                          batch_size=args.batch_size, device=args.device, seed=args.seed,
                          save_every=args.save_every, ablations=args.ablation or [],
                          overrides=args.set or [], workers=args.workers, progress=not args.json,
                          executor_from=args.executor_from)
    if args.json:
        print(json.dumps(result, indent=2))
    elif result.get("executor_from"):
        print(f"fitted {args.policy}'s planner beside the executor of {result['executor_from']} "
              f"(step {result['steps']}); checkpoint in {args.out}")
    else:
        print(f"trained {args.policy} for {result['steps']} steps "
              f"(resumed from {result['resumed_from']}); checkpoint in {args.out}")
    return 0


def add_parsers(sub) -> None:
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
    p.add_argument("--executor-from", metavar="CKPT",
                   help="Mem-0 with --ablation no_key only: fit the planner alone and take the "
                        "executor of CKPT, the finished training folder (with its "
                        "training/state.pt) of the same arguments but no_key: the checkpoint a "
                        "full run would write, for the planner's cost, in a new --out")
    p.add_argument("--set", action="append", metavar="FIELD=VALUE",
                   help="override a config field, VALUE as JSON (e.g. --set dim=64)")
    p.add_argument("--workers", type=whole(0), default=0, help="data-loading processes")
    add_json(p)
    p.set_defaults(func=cmd_train)
