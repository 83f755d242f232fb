"""What ``rmbench train POLICY`` runs: the policy's config from defaults, ``--ablation`` and
``--set FIELD=VALUE`` overrides, then its training function."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import fields, replace
from typing import Any

from rmbench.training.loop import TrainConfig


def parse_overrides(config_cls, items: list[str]) -> dict[str, Any]:
    names = {f.name for f in fields(config_cls)}
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set takes FIELD=VALUE, got {item!r}")
        if key not in names:
            raise ValueError(f"unknown config field {key!r}; fields: {', '.join(sorted(names))}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value  # a bare string
    return out


TRAINABLE = ("mem0", "dp", "act")


def trainable(policy: str) -> tuple[type, Callable[..., dict[str, Any]]]:
    """A trainable policy's config class and training function
    ``fit(dataset, out, cfg, train_cfg, progress=..., workers=...)``."""
    if policy == "mem0":
        from rmbench.policies.mem0.config import Mem0Config
        from rmbench.policies.mem0.train import train_mem0

        return Mem0Config, train_mem0
    if policy == "dp":
        from rmbench.policies.dp.agent import train_dp
        from rmbench.policies.dp.config import DPConfig

        return DPConfig, train_dp
    if policy == "act":
        from rmbench.policies.act.agent import train_act
        from rmbench.policies.act.config import ACTConfig

        return ACTConfig, train_act
    raise ValueError(f"unknown policy {policy!r} to train; policies: {', '.join(TRAINABLE)}")


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
