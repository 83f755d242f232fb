"""Mem-0's planner: which subtask comes next, from the first frame o_0, the goal, and the key
memory (each finished subtask's text with the frame at its end). Called only when a subtask
ends. With ``no_key`` it sees the current frame alone. A frame is its embedding by the
planner's own encoder: the planner cameras' CNNs, or with observation "state" its own state
MLP over that step's environment and joint states.

The default is small enough to train on a CPU: a transformer over
``[goal; o_0; (text_i + frame_i + position_i)...]`` whose goal token, read out, is scored
against the embeddings of the task's subtask texts and "done". A vision-language backend is the
upgrade path (planner_vlm.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from rmbench.policies.mem0.inputs import observation_encoder
from rmbench.policies.nn.text import TextTable

DONE = "done"
MAX_KEYS = 32  # positions beyond this share the last embedding


class Planner(nn.Module):
    def __init__(self, cfg, texts: list[str], text_vectors: torch.Tensor | None,
                 state_dim: int = 0):
        super().__init__()
        d = cfg.dim
        self.use_key = cfg.use_key
        self.encoders = observation_encoder(cfg, len(cfg.planner_cameras), state_dim)
        self.text = TextTable(texts, d, text_vectors)  # candidates: subtasks, then "done"
        self.goal = nn.Parameter(torch.randn(d) * 0.02)
        self.kind = nn.Parameter(torch.randn(2, d) * 0.02)  # o_0 / key entry
        self.pos = nn.Parameter(torch.randn(MAX_KEYS, d) * 0.02)
        layer = nn.TransformerEncoderLayer(d, cfg.heads, 4 * d, dropout=0.0, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, cfg.planner_layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(d)
        self.query = nn.Linear(d, d)

    def embed(self, inputs: list[torch.Tensor]) -> torch.Tensor:
        """Per-planner-camera uint8 (N, 3, H, W) (with a frozen backbone, their feature maps),
        or [environment state (N, D), joint state (N, 14)], -> (N, d)."""
        return self.encoders(inputs).mean(1)

    def forward(self, first: torch.Tensor, keys: torch.Tensor, key_text: torch.Tensor,
                key_valid: torch.Tensor) -> torch.Tensor:
        """Logits over the candidate texts (B, N).

        first (B, d): o_0's embedding (with no_key: the current frame's); keys (B, M, d) the key
        frames' embeddings, key_text (B, M) their subtask indices, key_valid (B, M) which exist.
        """
        b, m = key_text.shape
        goal = self.goal.expand(b, 1, -1)
        tokens = [goal, (first + self.kind[0])[:, None]]
        mask = [torch.zeros(b, 2, dtype=torch.bool, device=first.device)]
        if self.use_key and m:
            pos = self.pos[torch.clamp(torch.arange(m, device=first.device), max=MAX_KEYS - 1)]
            tokens.append(keys + self.text(key_text) + self.kind[1] + pos)
            mask.append(~key_valid)
        h = self.blocks(torch.cat(tokens, 1), src_key_padding_mask=torch.cat(mask, 1))
        q = self.query(self.norm(h[:, 0]))
        cand = self.text(torch.arange(len(self.text.texts), device=q.device))
        return q @ cand.T / math.sqrt(q.shape[-1])


@dataclass(frozen=True)
class PlannerExample:
    """One decision: after ``len(keys)`` finished subtasks of ``episode``, ``target`` is next.
    Frames are indices into the episode; ``current`` is the frame the decision is made at."""

    episode: int
    keys: tuple[tuple[int, int], ...]  # (subtask text index, end frame)
    current: int
    target: int


def runs(subtask_index: np.ndarray, subtask_step: np.ndarray) -> list[tuple[int, int]]:
    """The plan's steps as (subtask index, last frame): one entry per step, so two pushes of
    one button are two keys the planner can count."""
    ends = np.flatnonzero(np.diff(subtask_step) != 0).tolist() + [len(subtask_step) - 1]
    return [(int(subtask_index[e]), int(e)) for e in ends]


def planner_examples(episode: int, subtask_index: np.ndarray, subtask_step: np.ndarray,
                     done_index: int) -> list[PlannerExample]:
    """Every decision of one demonstration: the first subtask, each next one, then done."""
    rs = runs(subtask_index, subtask_step)
    out = []
    for k in range(len(rs) + 1):
        keys = tuple(rs[:k])
        out.append(PlannerExample(episode, keys, keys[-1][1] if keys else 0,
                                  rs[k][0] if k < len(rs) else done_index))
    return out


def planner_loss(planner: Planner, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    logits = planner(batch["first"], batch["keys"], batch["key_text"], batch["key_valid"])
    loss = F.cross_entropy(logits, batch["target"])
    return loss, (logits.argmax(-1) == batch["target"]).float().mean()
