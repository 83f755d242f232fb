"""Sinusoidal embedding of a continuous time t in [0, 1] (a flow's time, a diffusion step over
the number of steps), shared by the action heads."""

from __future__ import annotations

import math

import torch


def time_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    half = dim // 2
    freqs = torch.exp(-math.log(1000.0) * torch.arange(half, device=t.device) / half)
    angles = t[:, None].float() * 1000.0 * freqs[None]
    return torch.cat([angles.sin(), angles.cos()], -1)


def sincos_1d(n: int, dim: int) -> torch.Tensor:
    """Fixed sinusoidal positions (n, dim) of a sequence (Vaswani et al.)."""
    pos = torch.arange(n, dtype=torch.float32)[:, None]
    freqs = torch.exp(-math.log(10000.0) * torch.arange(0, dim, 2, dtype=torch.float32) / dim)
    out = torch.zeros(n, dim)
    out[:, 0::2] = torch.sin(pos * freqs)
    out[:, 1::2] = torch.cos(pos * freqs[: dim // 2])
    return out


def sincos_2d(h: int, w: int, dim: int) -> torch.Tensor:
    """Fixed sinusoidal positions (h * w, dim) of a feature map, row-major: half the channels
    encode the row, half the column (DETR's image positions, which ACT uses)."""
    rows = sincos_1d(h, dim // 2)[:, None].expand(h, w, dim // 2)
    cols = sincos_1d(w, dim - dim // 2)[None].expand(h, w, dim - dim // 2)
    return torch.cat([rows, cols], -1).reshape(h * w, dim)
