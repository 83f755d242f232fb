"""``--policy act:CKPT[?temporal_ensemble=M&execute=N]``: ACT's closed loop, with temporal
ensembling: a chunk every step, and the current step's action the weighted mean of every
chunk's prediction for it, the oldest weighted most (exp(-m i), i = 0 the oldest)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from rmbench.policies.act.config import ACTConfig
from rmbench.policies.act.modeling import ACTModel, ACTTrainer
from rmbench.policies.visuomotor import VisuomotorPolicy, train_visuomotor


class ACTPolicy(VisuomotorPolicy):
    name = "act"
    config_cls = ACTConfig
    model_cls = ACTModel

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        super().reset(instruction, task_info)
        self.chunks: list[tuple[int, np.ndarray]] = []  # (step predicted at, chunk), oldest first

    def schedule(self, state: torch.Tensor) -> np.ndarray:
        m = self.cfg.temporal_ensemble
        if m <= 0:
            return super().schedule(state)
        horizon = self.cfg.horizon
        self.chunks = [(t0, c) for t0, c in self.chunks if self.t - t0 < horizon]
        self.chunks.append((self.t, self.chunk(state)))
        predictions = np.stack([c[self.t - t0] for t0, c in self.chunks])
        weights = np.exp(-m * np.arange(len(predictions)))
        return (weights / weights.sum()) @ predictions


def train_act(dataset, out, cfg: ACTConfig, train_cfg, progress: bool = True, workers: int = 0):
    return train_visuomotor("act", cfg, ACTModel, ACTTrainer, dataset, out, train_cfg,
                            progress, workers)
