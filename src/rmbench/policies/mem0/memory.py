"""Mem-0's working memory: the anchor (the subtask's first frame) and the sliding window (the
last K frames), and the residual cross-attention that reads them.

``MemoryStore`` holds one memory per batch slot. Inference uses one per episode played side
by side (an episode alone: one slot); training uses one per slot of the episode-ordered
sampler, so every training frame is paired with the memory the policy would hold at that
point of the episode. Stored entries are detached: the encoder
learns from the current frame, and memory carries its past outputs.
"""

from __future__ import annotations

import torch
from torch import nn


class MemoryStore(nn.Module):
    """Per slot: the anchor tokens (C, d), the sliding window (K, d) and which of its entries
    are filled. Buffers, so the store follows its owner's ``.to()``; not persistent, since a
    checkpoint holds weights and the training state saves the store itself (``state()``)."""

    def __init__(self, slots: int, cameras: int, window: int, dim: int):
        super().__init__()
        self.window = window
        self.register_buffer("anchor", torch.zeros(slots, cameras, dim), persistent=False)
        self.register_buffer("sliding", torch.zeros(slots, window, dim), persistent=False)
        self.register_buffer("valid", torch.zeros(slots, window, dtype=torch.bool),
                             persistent=False)

    def reset(self, which: torch.Tensor, tokens: torch.Tensor) -> None:
        """Start a subtask in the slots where ``which`` (B,) is set: the anchor becomes this
        frame's per-camera ``tokens`` (B, C, d) and the sliding window empties."""
        which = which.to(self.anchor.device)
        if which.any():
            self.anchor[which] = tokens.detach()[which]
            self.valid[which] = False

    def push(self, z: torch.Tensor, which: torch.Tensor | None = None) -> None:
        """Append ``z`` (B, d) as the newest sliding entry (of the slots in ``which``); the
        oldest of a full window drops out."""
        which = torch.ones(len(z), dtype=torch.bool, device=z.device) if which is None else which
        if which.any():
            self.sliding[which] = torch.cat([self.sliding[which, 1:], z.detach()[which, None]], 1)
            self.valid[which] = torch.cat(
                [self.valid[which, 1:], torch.ones_like(self.valid[which, :1])], 1)

    def state(self) -> dict[str, torch.Tensor]:
        return {"anchor": self.anchor, "sliding": self.sliding, "valid": self.valid}

    def load_state(self, state: dict[str, torch.Tensor]) -> None:
        for k, v in state.items():
            getattr(self, k).copy_(v)


class EventWindow(nn.Module):
    """Per slot, the last W z_img at the memory stride, kept across subtask ends: what the
    "event" end classifier compares the current frame with. An episode's start fills it with
    its first frame, as if the scene had stood still before it. Buffers, like MemoryStore."""

    def __init__(self, slots: int, window: int, dim: int):
        super().__init__()
        self.register_buffer("entries", torch.zeros(slots, window, dim), persistent=False)

    def reset(self, which: torch.Tensor, z: torch.Tensor) -> None:
        """Start an episode in the slots where ``which`` (B,) is set: every entry is ``z``."""
        which = which.to(self.entries.device)
        if which.any():
            self.entries[which] = z.detach()[which, None].expand(-1, self.entries.shape[1], -1)

    def push(self, z: torch.Tensor, which: torch.Tensor | None = None) -> None:
        """Append ``z`` (B, d) as the newest entry (of the slots in ``which``); the oldest
        drops out."""
        pushed = torch.cat([self.entries[:, 1:], z.detach()[:, None]], 1)
        if which is None:
            self.entries.copy_(pushed)
        else:
            self.entries[which] = pushed[which.to(self.entries.device)]

    def state(self) -> dict[str, torch.Tensor]:
        return {"entries": self.entries}

    def load_state(self, state: dict[str, torch.Tensor]) -> None:
        self.entries.copy_(state["entries"])


class MemoryFusion(nn.Module):
    """z' = z + Attn(z, [z; memory]) followed by a feed-forward residual (pre-norm).

    The current frame is always one of the keys: with an empty memory (the first step of a
    subtask) the attention stays defined and the fusion reduces to a self-update."""

    def __init__(self, dim: int, heads: int, slots: int):
        super().__init__()
        self.norm_q = nn.LayerNorm(dim)
        self.norm_kv = nn.LayerNorm(dim)
        self.attn = nn.MultiheadAttention(dim, heads, batch_first=True)
        self.pos = nn.Parameter(torch.zeros(slots + 1, dim))  # which slot (age / camera)
        self.ff = nn.Sequential(nn.LayerNorm(dim), nn.Linear(dim, 2 * dim), nn.GELU(),
                                nn.Linear(2 * dim, dim))
        nn.init.normal_(self.pos, std=0.02)

    def forward(self, z: torch.Tensor, memory: torch.Tensor,
                valid: torch.Tensor | None = None) -> torch.Tensor:
        kv = torch.cat([z[:, None], memory], 1) + self.pos
        mask = None
        if valid is not None:  # key_padding_mask: True = ignore
            mask = torch.cat([torch.zeros_like(valid[:, :1]), ~valid], 1)
        q = self.norm_q(z)[:, None]
        kv = self.norm_kv(kv)
        y = z + self.attn(q, kv, kv, key_padding_mask=mask, need_weights=False)[0][:, 0]
        return y + self.ff(y)
