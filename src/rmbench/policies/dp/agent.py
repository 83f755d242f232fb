"""``--policy dp:CKPT[?execute=N&ddim_steps=N]``: Diffusion Policy's closed loop."""

from __future__ import annotations

from rmbench.policies.dp.config import DPConfig
from rmbench.policies.dp.modeling import DiffusionPolicyModel, DPTrainer
from rmbench.policies.visuomotor import VisuomotorPolicy, train_visuomotor


class DPPolicy(VisuomotorPolicy):
    """A Diffusion Policy checkpoint in the closed loop: each 20 Hz step's observation in, one
    14-d joint target out; a chunk is sampled every ``execute`` steps (8 of its 16 by default)."""

    name = "dp"
    config_cls = DPConfig
    model_cls = DiffusionPolicyModel


def train_dp(dataset, out, cfg: DPConfig, train_cfg, progress: bool = True, workers: int = 0):
    return train_visuomotor("dp", cfg, DiffusionPolicyModel, DPTrainer, dataset, out, train_cfg,
                            progress, workers)
