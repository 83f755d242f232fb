"""``--policy act:CKPT[?temporal_ensemble=M&ensemble_window=K&execute=N]``: ACT's closed loop,
with temporal ensembling (policies/ensemble.py): a chunk every step, and the current step's
action the weighted mean of every chunk's prediction for it (of the last K steps' chunks)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from rmbench.policies.act.config import ACTConfig
from rmbench.policies.act.modeling import ACTModel, ACTTrainer
from rmbench.policies.ensemble import TemporalEnsemble
from rmbench.policies.visuomotor import VisuomotorPolicy, train_visuomotor


class ACTPolicy(VisuomotorPolicy):
    """An ACT checkpoint in the closed loop: each 20 Hz step's observation in, one 14-d joint
    target out. A chunk is predicted every step and the predictions for the step averaged
    (temporal ensembling), or without it every ``execute`` steps."""

    name = "act"
    config_cls = ACTConfig
    model_cls = ACTModel

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        super().reset(instruction, task_info)
        self.ensemble = TemporalEnsemble(self.cfg.horizon, self.cfg.temporal_ensemble,
                                         self.cfg.ensemble_window)

    def schedule(self, state: torch.Tensor) -> np.ndarray:
        if self.cfg.temporal_ensemble <= 0:
            return super().schedule(state)
        self.ensemble.add(self.t, self.chunk(state))
        return self.ensemble.action(self.t)


def train_act(dataset, out, cfg: ACTConfig, train_cfg, progress: bool = True, workers: int = 0):
    return train_visuomotor("act", cfg, ACTModel, ACTTrainer, dataset, out, train_cfg,
                            progress, workers)
