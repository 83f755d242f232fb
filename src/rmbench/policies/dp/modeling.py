"""Diffusion Policy: per-camera CNN features and the normalised state over the last
``obs_steps`` steps form the global condition of a 1-D U-Net that predicts the noise of an
action chunk; DDPM in training, DDIM at inference, EMA weights exported.

    f_t      = [CNN_cam(o_t^cam) for each camera; state_t]     (observation "pixels")
             = [MLP(env_state_t, state_t) as state_tokens; state_t]   (observation "state")
    cond     = [f_{t-1}; f_t]
    eps      = UNet(a_k, k / K, cond)          a_0 ~ DDIM(eps, 10 steps)
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from rmbench.policies.dp.config import DPConfig
from rmbench.policies.nn.diffusion import DDPMSchedule
from rmbench.policies.nn.ema import EMA
from rmbench.policies.nn.normalize import Normalizer
from rmbench.policies.nn.unet1d import ConditionalUnet1D
from rmbench.policies.visuomotor import VisuomotorTrainer, observation_encoder
from rmbench.sim.simulator import ACTION_DIM


class DiffusionPolicyModel(nn.Module):
    """Diffusion Policy's network: the last ``obs_steps`` control steps' features (camera images
    or the environment state, with the joint state) in, a normalised chunk of ``horizon``
    joint targets (B, H, 14) out, denoised from Gaussian noise in ``ddim_steps`` steps."""

    def __init__(self, cfg: DPConfig, state_dim: int = 0):
        super().__init__()
        self.cfg = cfg
        self.encoders = observation_encoder(cfg, state_dim, cfg.keypoints)
        self.normalizer = Normalizer(ACTION_DIM)
        step_features = cfg.step_tokens * cfg.dim + ACTION_DIM
        self.unet = ConditionalUnet1D(ACTION_DIM, cfg.obs_steps * step_features, cfg.down_dims,
                                      cfg.kernel, cfg.groups)
        self.schedule = DDPMSchedule(cfg.train_steps)

    def observe(self, inputs: list[torch.Tensor], state: torch.Tensor) -> torch.Tensor:
        """One step: (B, cameras (or state_tokens) * dim + 14)."""
        return torch.cat([self.encoders(inputs).flatten(1), self.normalizer.state(state)], -1)

    def noise(self, x: torch.Tensor, k: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        return self.unet(x, k.float() / self.cfg.train_steps, cond)

    def predict(self, window: list[torch.Tensor], state: torch.Tensor,
                generators: list[torch.Generator | None]) -> torch.Tensor:
        """The normalised chunk (B, H, 14) sampled by DDIM, conditioned on the window's
        features (oldest first); row i's starting noise comes from ``generators[i]`` (zeros
        for None: a row whose chunk is not used)."""
        cond = torch.cat(window, -1)
        row = (1, self.cfg.horizon, ACTION_DIM)
        start = torch.cat([torch.randn(row, generator=g, device="cpu") if g is not None
                           else torch.zeros(row) for g in generators])
        return self.schedule.ddim_sample(lambda x, k: self.noise(x, k, cond), tuple(start.shape),
                                         self.cfg.ddim_steps, None, cond.device, start)


class DPTrainer(VisuomotorTrainer):
    """Noise-prediction MSE at a uniformly drawn DDPM step; the EMA of the weights is what the
    checkpoint holds (and what Diffusion Policy evaluates)."""

    def __init__(self, model: DiffusionPolicyModel, seed: int, state_names: tuple[str, ...] = ()):
        super().__init__(model, seed, state_names)
        self.ema = EMA(model, model.cfg.ema_power, model.cfg.ema_max_decay)

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
        model = self.model
        cond = self.observe(batch)[0].flatten(1)
        target = self.target(batch)
        b = target.shape[0]
        noise = torch.randn(target.shape, generator=self.generator).to(target.device)
        k = torch.randint(0, model.cfg.train_steps, (b,), generator=self.generator).to(target.device)
        # padded steps repeat the episode's last action: learned as holding, as in the paper
        loss = F.mse_loss(model.noise(model.schedule.add_noise(target, noise, k), k, cond), noise)
        return loss, {"loss/noise": loss.item()}

    def after_step(self) -> None:
        self.ema.update(self.model)

    def export_module(self) -> nn.Module:
        return self.ema.averaged
