"""``--policy dp:CKPT[?execute=N&ddim_steps=N]``: Diffusion Policy's closed loop."""

from __future__ import annotations

from rmbench.policies.dp.config import DPConfig
from rmbench.policies.dp.modeling import DiffusionPolicyModel, DPTrainer
from rmbench.policies.visuomotor import VisuomotorPolicy, train_visuomotor


class DPPolicy(VisuomotorPolicy):
    name = "dp"
    config_cls = DPConfig
    model_cls = DiffusionPolicyModel


def train_dp(dataset, out, cfg: DPConfig, train_cfg, progress: bool = True, workers: int = 0):
    return train_visuomotor("dp", cfg, DiffusionPolicyModel, DPTrainer, dataset, out, train_cfg,
                            progress, workers)
