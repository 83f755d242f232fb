"""Normalisation stored in the policy (so a checkpoint carries it): state to zero mean and
unit variance, actions to [-1, 1] by their min and max (the range a diffusion head samples in).

Actions can be relative: the dims in ``relative`` (the joints) are predicted as offsets from
the current joint positions and the others (the grippers) as absolute targets, as openpi does
for ALOHA. Holding still is then the zero prediction, which a small model trained on a few
demonstrations otherwise has to learn from the state token.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from rmbench.data import layout as L
from rmbench.sim.simulator import ACTION_DIM

# 6 joints, gripper, 6 joints, gripper
JOINTS = np.array([True] * 6 + [False] + [True] * 6 + [False])


class Normalizer(nn.Module):
    def __init__(self, dim: int = ACTION_DIM, action_dim: int | None = None):
        super().__init__()
        action_dim = dim if action_dim is None else action_dim
        self.register_buffer("state_mean", torch.zeros(dim))
        self.register_buffer("state_std", torch.ones(dim))
        self.register_buffer("action_min", -torch.ones(action_dim))
        self.register_buffer("action_max", torch.ones(action_dim))
        self.register_buffer("relative", torch.zeros(action_dim))  # 1 where actions are offsets

    @classmethod
    def from_stats(cls, stats: dict[str, dict[str, np.ndarray]]) -> Normalizer:
        """Absolute actions, ranges from meta/stats.json."""
        norm = cls(len(np.asarray(stats[L.STATE]["mean"])), len(np.asarray(stats[L.ACTION]["min"])))
        norm._set_state(stats)
        norm._set_range(np.asarray(stats[L.ACTION]["min"]), np.asarray(stats[L.ACTION]["max"]))
        return norm

    @classmethod
    def from_episodes(cls, stats: dict[str, dict[str, np.ndarray]], states: list[np.ndarray],
                      actions: list[np.ndarray], horizon: int,
                      relative: np.ndarray = JOINTS) -> Normalizer:
        """Relative actions: the range of ``action[t + k] - state[t]`` over every frame t and
        chunk offset k < horizon (the last action repeats past an episode's end, as in the
        training chunks). ``actions`` may be in another space than the joints (``relative``
        all False then, one entry per action dimension)."""
        norm = cls(len(np.asarray(stats[L.STATE]["mean"])), len(relative))
        norm._set_state(stats)
        lo, hi = np.full(len(relative), np.inf), np.full(len(relative), -np.inf)
        for s, a in zip(states, actions, strict=True):
            n = len(a)
            for k in range(horizon):
                target = a[np.minimum(np.arange(n) + k, n - 1)]
                x = np.where(relative, target - s, target) if relative.any() else target
                lo, hi = np.minimum(lo, x.min(0)), np.maximum(hi, x.max(0))
        norm._set_range(lo, hi)
        with torch.no_grad():
            norm.relative.copy_(torch.as_tensor(relative, dtype=torch.float32))
        return norm

    @classmethod
    def for_demonstrations(cls, stats, episodes, horizon: int, relative: bool) -> Normalizer:
        """From a dataset's meta/stats.json (``stats``), and for relative actions the offsets'
        range measured over its ``episodes`` (``rmbench.data.reader.Episode``, already read
        by the caller's training examples)."""
        if not relative:
            return cls.from_stats(stats)
        return cls.from_episodes(stats, [ep.state for ep in episodes],
                                 [ep.action for ep in episodes], horizon)

    def _set_state(self, stats) -> None:
        with torch.no_grad():
            self.state_mean.copy_(torch.as_tensor(np.asarray(stats[L.STATE]["mean"]), dtype=torch.float32))
            # joints that never move (std 0) would divide by zero
            self.state_std.copy_(torch.as_tensor(np.maximum(stats[L.STATE]["std"], 1e-3),
                                                 dtype=torch.float32))

    def _set_range(self, lo: np.ndarray, hi: np.ndarray) -> None:
        # an action dim that never changes still gets a range to divide by
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        mid, half = (hi + lo) / 2, np.maximum(hi - lo, 1e-3) / 2
        with torch.no_grad():
            self.action_min.copy_(torch.as_tensor(mid - half, dtype=torch.float32))
            self.action_max.copy_(torch.as_tensor(mid + half, dtype=torch.float32))

    def state(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.state_mean) / self.state_std

    def action(self, x: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        """Actions (B, H, A) taken from ``state`` (B, S) -> normalised (B, H, A)."""
        if self.relative.any():  # (then A == S: offsets from the joints)
            x = x - self.relative * state[:, None]
        return 2 * (x - self.action_min) / (self.action_max - self.action_min) - 1

    def unaction(self, x: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        y = (x.clamp(-1, 1) + 1) / 2 * (self.action_max - self.action_min) + self.action_min
        return y + self.relative * state[:, None] if self.relative.any() else y
