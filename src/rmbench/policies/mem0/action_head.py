"""The action head: a transformer that denoises a chunk of H actions by flow matching
(rectified flow), conditioned on context tokens (Mem-0's c_t and the state).

Training draws t ~ U(0, 1) and noise e, forms x_t = t a + (1 - t) e and regresses the velocity
a - e. Sampling integrates dx/dt from noise at t = 0 to t = 1 in ``steps`` Euler steps; the
noise comes from the caller's generator, so a seeded episode samples the same chunks.

With ``patch`` p > 1 each token carries p consecutive actions (H / p action tokens): the
transformer's cost falls with its token count, so on a CPU p buys training samples; p = 1 is
one token per action.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from rmbench.policies.nn.embeddings import time_embedding


class FlowMatchingHead(nn.Module):
    """Context tokens in, a chunk (B, H, A) of normalised actions out, sampled from noise in
    ``steps`` Euler steps; trained on the velocity (see the module docstring)."""

    def __init__(self, dim: int, horizon: int, action_dim: int, layers: int, heads: int,
                 patch: int = 1):
        super().__init__()
        self.dim, self.horizon, self.action_dim, self.patch = dim, horizon, action_dim, patch
        self.tokens = horizon // patch
        self.inp = nn.Linear(patch * action_dim, dim)
        self.pos = nn.Parameter(torch.randn(self.tokens, dim) * 0.02)
        self.time = nn.Sequential(nn.Linear(dim, dim), nn.SiLU(), nn.Linear(dim, dim))
        layer = nn.TransformerEncoderLayer(dim, heads, 4 * dim, dropout=0.0, activation="gelu",
                                           batch_first=True, norm_first=True)
        self.blocks = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.norm = nn.LayerNorm(dim)
        self.out = nn.Linear(dim, patch * action_dim)

    def velocity(self, x: torch.Tensor, t: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """x (B, H, A) at times t (B,), context tokens cond (B, N, d) -> (B, H, A)."""
        # the noise level goes into every action token: each needs it to scale its velocity
        b = x.shape[0]
        time = self.time(time_embedding(t, self.dim))[:, None]
        patches = x.reshape(b, self.tokens, self.patch * self.action_dim)
        tokens = torch.cat([cond, self.inp(patches) + self.pos + time], 1)
        out = self.out(self.norm(self.blocks(tokens)[:, -self.tokens:]))
        return out.reshape(b, self.horizon, self.action_dim)

    def loss(self, cond: torch.Tensor, actions: torch.Tensor, is_pad: torch.Tensor,
             generator: torch.Generator | None = None) -> torch.Tensor:
        """Mean squared velocity error over the chunk's real (not padded) steps."""
        b = actions.shape[0]
        noise = torch.randn(actions.shape, generator=generator, device="cpu").to(actions.device)
        t = torch.rand(b, generator=generator, device="cpu").to(actions.device)
        x = t[:, None, None] * actions + (1 - t[:, None, None]) * noise
        err = F.mse_loss(self.velocity(x, t, cond), actions - noise, reduction="none").mean(-1)
        keep = (~is_pad).float()
        return (err * keep).sum() / keep.sum().clamp(min=1)

    @torch.no_grad()
    def sample(self, cond: torch.Tensor, steps: int,
               generator: torch.Generator | None = None, noise: float = 1.0,
               start: torch.Tensor | None = None) -> torch.Tensor:
        """A chunk (B, H, A) integrated from ``noise`` times standard normal noise: drawn
        from ``generator``, or ``start`` (B, H, A) drawn by the caller (a generator per row,
        so that a row's chunk does not depend on the rows beside it)."""
        b = cond.shape[0]
        if start is None:
            start = torch.randn(b, self.horizon, self.action_dim, generator=generator,
                                device="cpu")
        x = start.to(cond.device)
        if noise != 1.0:
            x = x * noise
        for i in range(steps):
            t = torch.full((b,), i / steps, device=cond.device)
            x = x + self.velocity(x, t, cond) / steps
        return x
