"""The policies ``rmbench train`` can train: each one's config class and training function."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

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
