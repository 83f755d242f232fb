"""Diffusion Policy's noise-prediction network: a 1-D temporal U-Net over the action sequence,
conditioned by FiLM on the diffusion step and the observation features (Chi et al. 2023,
the CNN variant)."""

from __future__ import annotations

import torch
from torch import nn

from rmbench.policies.nn.embeddings import time_embedding


class Conv1dBlock(nn.Sequential):
    def __init__(self, c_in: int, c_out: int, kernel: int, groups: int):
        super().__init__(nn.Conv1d(c_in, c_out, kernel, padding=kernel // 2),
                         nn.GroupNorm(groups, c_out), nn.Mish())


class ConditionalResBlock(nn.Module):
    """Two conv blocks; the condition scales and shifts the first one's output per channel."""

    def __init__(self, c_in: int, c_out: int, cond_dim: int, kernel: int, groups: int):
        super().__init__()
        self.block1 = Conv1dBlock(c_in, c_out, kernel, groups)
        self.block2 = Conv1dBlock(c_out, c_out, kernel, groups)
        self.film = nn.Sequential(nn.Mish(), nn.Linear(cond_dim, 2 * c_out))
        self.skip = nn.Conv1d(c_in, c_out, 1) if c_in != c_out else nn.Identity()

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        scale, shift = self.film(cond)[:, :, None].chunk(2, 1)
        y = self.block1(x) * scale + shift
        return self.block2(y) + self.skip(x)


class ConditionalUnet1D(nn.Module):
    """(B, T, A) noisy actions, (B,) diffusion times in [0, 1], (B, G) global condition ->
    (B, T, A) predicted noise.

    ``down_dims`` are the widths per level; every level but the last halves T, so T must be
    divisible by 2^(levels - 1)."""

    def __init__(self, action_dim: int, global_dim: int, down_dims: tuple[int, ...] = (64, 128, 256),
                 kernel: int = 5, groups: int = 8, step_dim: int = 128):
        super().__init__()
        self.step_dim = step_dim
        self.step_encoder = nn.Sequential(nn.Linear(step_dim, 4 * step_dim), nn.Mish(),
                                          nn.Linear(4 * step_dim, step_dim))
        cond = step_dim + global_dim
        dims = [action_dim, *down_dims]
        self.down = nn.ModuleList()
        for i, (a, b) in enumerate(zip(dims[:-1], dims[1:], strict=True)):
            last = i == len(down_dims) - 1
            self.down.append(nn.ModuleList([
                ConditionalResBlock(a, b, cond, kernel, groups),
                ConditionalResBlock(b, b, cond, kernel, groups),
                nn.Conv1d(b, b, 3, 2, 1) if not last else nn.Identity()]))
        mid = down_dims[-1]
        self.mid = nn.ModuleList([ConditionalResBlock(mid, mid, cond, kernel, groups),
                                  ConditionalResBlock(mid, mid, cond, kernel, groups)])
        self.up = nn.ModuleList()
        for a, b in zip(reversed(down_dims[1:]), reversed(down_dims[:-1]), strict=True):
            self.up.append(nn.ModuleList([
                ConditionalResBlock(2 * a, b, cond, kernel, groups),
                ConditionalResBlock(b, b, cond, kernel, groups),
                nn.ConvTranspose1d(b, b, 4, 2, 1)]))
        self.final = nn.Sequential(Conv1dBlock(down_dims[0], down_dims[0], kernel, groups),
                                   nn.Conv1d(down_dims[0], action_dim, 1))
        self.levels = len(down_dims)

    def forward(self, x: torch.Tensor, t: torch.Tensor, global_cond: torch.Tensor) -> torch.Tensor:
        if x.shape[1] % 2 ** (self.levels - 1):
            raise ValueError(f"sequence length {x.shape[1]} is not divisible by "
                             f"{2 ** (self.levels - 1)} ({self.levels} U-Net levels)")
        cond = torch.cat([self.step_encoder(time_embedding(t, self.step_dim)), global_cond], -1)
        h = x.transpose(1, 2)  # (B, A, T): convolve over time
        skips = []
        for res1, res2, down in self.down:
            h = res2(res1(h, cond), cond)
            skips.append(h)
            h = down(h)
        for block in self.mid:
            h = block(h, cond)
        for res1, res2, up in self.up:
            h = res2(res1(torch.cat([h, skips.pop()], 1), cond), cond)
            h = up(h)
        return self.final(h).transpose(1, 2)
