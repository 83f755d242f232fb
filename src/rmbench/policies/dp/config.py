"""Diffusion Policy's settings: one frozen dataclass, stored in every checkpoint."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from rmbench.policies.visuomotor import VisuomotorConfig


@dataclass(frozen=True)
class DPConfig(VisuomotorConfig):
    """Diffusion Policy's fields beside the baselines' shared ones; the defaults are the
    CPU-sized model."""

    obs_steps: int = 2
    """Observation horizon (the paper's T_o = 2): the current and the previous step."""
    horizon: int = 16
    """Prediction horizon T_p; a multiple of 2^(U-Net levels - 1)."""
    execute: int = 8
    """Action horizon T_a: actions executed per chunk."""
    dim: int = 64
    """Feature width per camera (spatial-softmax keypoints and channel mean, projected)."""
    keypoints: int = 32
    down_dims: tuple[int, ...] = (64, 128, 256)
    """U-Net widths per level (the paper's (256, 512, 1024) at a quarter, CPU-sized)."""
    kernel: int = 5
    groups: int = 8
    """GroupNorm groups in the U-Net."""
    train_steps: int = 100
    """DDPM noise steps in training (squared-cosine schedule, epsilon prediction)."""
    ddim_steps: int = 10
    """DDIM steps when sampling a chunk."""
    ema_power: float = 0.75
    ema_max_decay: float = 0.9999

    INFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ("execute", "ddim_steps")

    def __post_init__(self):
        super().__post_init__()
        levels = 2 ** (len(self.down_dims) - 1)
        if self.horizon % levels:
            raise ValueError(f"horizon {self.horizon} must be a multiple of {levels} "
                             f"({len(self.down_dims)} U-Net levels)")
        if not 1 <= self.ddim_steps <= self.train_steps:
            raise ValueError(f"ddim_steps must be in [1, train_steps={self.train_steps}]")
        if any(d % self.groups for d in self.down_dims):
            raise ValueError(f"every down_dims width must be divisible by groups={self.groups}")
