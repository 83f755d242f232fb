"""What ``rmbench train POLICY`` runs: the policy's config from defaults, ``--ablation`` and
``--set FIELD=VALUE`` overrides, then its training function."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from rmbench.policies.config import parse_overrides
from rmbench.policies.trainable import trainable
from rmbench.training.loop import TrainConfig


def run_training(policy: str, dataset: str, out: str, *, steps: int, batch_size: int, device: str,
                 seed: int, save_every: int, ablations: list[str], overrides: list[str],
                 workers: int = 0, progress: bool = True) -> dict[str, Any]:
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
    elif ablations:
        raise ValueError(f"--ablation is Mem-0's; {policy} has none")
    cfg = config_cls(**parse_overrides(config_cls, overrides))
    if ablations:
        cfg = replace(cfg, ablations=tuple(ablations))
    return fit(dataset, out, cfg, train_cfg, progress=progress, workers=workers)
