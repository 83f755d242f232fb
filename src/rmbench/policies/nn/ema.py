"""Exponential moving average of a model's weights, with Diffusion Policy's warm-up: the decay
grows as 1 - (1 + step)^-power up to ``max_decay``, so early averages are not dominated by
the random initialisation."""

from __future__ import annotations

import copy

import torch
from torch import nn


class EMA(nn.Module):
    def __init__(self, model: nn.Module, power: float = 0.75, max_decay: float = 0.9999):
        super().__init__()
        self.averaged = copy.deepcopy(model).eval().requires_grad_(False)
        self.power, self.max_decay = power, max_decay
        self.register_buffer("step", torch.zeros((), dtype=torch.long))

    def decay(self) -> float:
        step = int(self.step)
        return 0.0 if step == 0 else min(self.max_decay, 1 - (1 + step) ** -self.power)

    @torch.no_grad()
    def update(self, model: nn.Module) -> None:
        d = self.decay()
        for avg, new in zip(self.averaged.parameters(), model.parameters(), strict=True):
            avg.lerp_(new.detach(), 1 - d)
        for avg, new in zip(self.averaged.buffers(), model.buffers(), strict=True):
            avg.copy_(new)  # normalisation and schedules are not averaged
        self.step += 1
