"""ACT's settings: one frozen dataclass, stored in every checkpoint."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from rmbench.policies.visuomotor import VisuomotorConfig


@dataclass(frozen=True)
class ACTConfig(VisuomotorConfig):
    """ACT's fields beside the baselines' shared ones; the defaults are the CPU-sized model."""

    obs_steps: int = 1
    """ACT sees the current step only."""
    horizon: int = 50
    """Chunk size k."""
    execute: int = 50
    """Actions executed per chunk when temporal ensembling is off."""
    temporal_ensemble: float = 0.01
    """m in the ensembling weights exp(-m i) (i = 0 the oldest prediction): a chunk is predicted
    every step and the predictions for the current step averaged. 0: no ensembling; execute
    ``execute`` actions per chunk."""
    ensemble_window: int = 0
    """Only the chunks predicted in the last this many steps are averaged (0: every chunk that
    covers the step, ``horizon`` steps back). The ensemble acts on that much of the past, so
    it is a memory of that many steps."""
    dim: int = 128
    """Transformer width (the paper's 512, CPU-sized); the CNN's feature maps project to it."""
    heads: int = 4
    encoder_layers: int = 2
    """Layers of the observation encoder and of the CVAE encoder (the paper's 4)."""
    decoder_layers: int = 1
    """The paper lists 7, but its released code uses only the first decoder layer's output;
    1 reproduces what was evaluated (as LeRobot does)."""
    feedforward: int = 512
    dropout: float = 0.1
    latent_dim: int = 32
    """The CVAE's style variable z (0 at inference)."""
    kl_weight: float = 10.0
    """beta on the KL term beside the L1 action loss."""

    INFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ("execute", "temporal_ensemble",
                                                   "ensemble_window")

    def __post_init__(self):
        super().__post_init__()
        if self.obs_steps != 1:
            raise ValueError("ACT reads one observation step (obs_steps = 1)")
        if self.heads < 1 or self.dim % self.heads:
            raise ValueError(f"dim {self.dim} must be divisible by heads {self.heads} (>= 1)")
        if self.temporal_ensemble < 0:
            raise ValueError("temporal_ensemble must be >= 0 (0 turns it off)")
        if not 0 <= self.ensemble_window <= self.horizon:
            raise ValueError(f"ensemble_window must be 0 (the whole horizon) to horizon "
                             f"({self.horizon}), got {self.ensemble_window}")
