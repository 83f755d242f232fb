"""``--policy act:CKPT[?temporal_ensemble=M&ensemble_window=K&execute=N]``: ACT's closed loop,
with temporal ensembling (policies/ensemble.py): a chunk every step, and the current step's
action the weighted mean of every chunk's prediction for it (of the last K steps' chunks)."""

from __future__ import annotations

import numpy as np

from rmbench.policies.act.config import ACTConfig
from rmbench.policies.act.modeling import ACTModel, ACTTrainer
from rmbench.policies.ensemble import TemporalEnsemble
from rmbench.policies.visuomotor import VisuomotorPolicy, _Slot, train_visuomotor


class ACTPolicy(VisuomotorPolicy):
    """An ACT checkpoint in the closed loop: each 20 Hz step's observation in, one 14-d joint
    target out. A chunk is predicted every step and the predictions for the step averaged
    (temporal ensembling), or without it every ``execute`` steps."""

    name = "act"
    config_cls = ACTConfig
    model_cls = ACTModel

    def new_slot(self, seed: int = 0) -> _Slot:
        slot = super().new_slot(seed)
        slot.ensemble = TemporalEnsemble(self.cfg.horizon, self.cfg.temporal_ensemble,
                                         self.cfg.ensemble_window)
        return slot

    def due(self, slot: _Slot) -> bool:
        return self.cfg.temporal_ensemble > 0 or super().due(slot)

    def take(self, slot: _Slot, chunk: np.ndarray | None) -> np.ndarray:
        if self.cfg.temporal_ensemble <= 0:
            return super().take(slot, chunk)
        slot.ensemble.add(slot.t, chunk)
        return slot.ensemble.action(slot.t)


def train_act(dataset, out, cfg: ACTConfig, train_cfg, progress: bool = True, workers: int = 0):
    return train_visuomotor("act", cfg, ACTModel, ACTTrainer, dataset, out, train_cfg,
                            progress, workers)
