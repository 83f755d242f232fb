"""Normalisation from a dataset's meta/stats.json, stored in the policy (so a checkpoint
carries it): state to zero mean and unit variance, actions to [-1, 1] by their min and max
(the range a diffusion head samples in)."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from rmbench.data import layout as L


class Normalizer(nn.Module):
    def __init__(self, dim: int = 14):
        super().__init__()
        self.register_buffer("state_mean", torch.zeros(dim))
        self.register_buffer("state_std", torch.ones(dim))
        self.register_buffer("action_min", -torch.ones(dim))
        self.register_buffer("action_max", torch.ones(dim))

    @classmethod
    def from_stats(cls, stats: dict[str, dict[str, np.ndarray]]) -> Normalizer:
        norm = cls(len(np.asarray(stats[L.ACTION]["min"])))
        with torch.no_grad():
            norm.state_mean.copy_(torch.as_tensor(np.asarray(stats[L.STATE]["mean"]), dtype=torch.float32))
            # joints that never move (std 0) would divide by zero
            norm.state_std.copy_(torch.as_tensor(np.maximum(stats[L.STATE]["std"], 1e-3),
                                                 dtype=torch.float32))
            lo = np.asarray(stats[L.ACTION]["min"], np.float64)
            hi = np.asarray(stats[L.ACTION]["max"], np.float64)
            # an action dim that never changes still gets a range to divide by
            mid, half = (hi + lo) / 2, np.maximum(hi - lo, 1e-3) / 2
            norm.action_min.copy_(torch.as_tensor(mid - half, dtype=torch.float32))
            norm.action_max.copy_(torch.as_tensor(mid + half, dtype=torch.float32))
        return norm

    def state(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.state_mean) / self.state_std

    def action(self, x: torch.Tensor) -> torch.Tensor:
        return 2 * (x - self.action_min) / (self.action_max - self.action_min) - 1

    def unaction(self, x: torch.Tensor) -> torch.Tensor:
        return (x.clamp(-1, 1) + 1) / 2 * (self.action_max - self.action_min) + self.action_min
