"""DDPM training and DDIM sampling (Ho et al. 2020; Song et al. 2021), as Diffusion Policy uses
them: the squared-cosine noise schedule, epsilon prediction, samples clipped to [-1, 1] (the
normalised action range). Written here; diffusers is not a dependency."""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import nn


def cosine_betas(steps: int, max_beta: float = 0.999) -> torch.Tensor:
    """The squared-cosine schedule (Nichol & Dhariwal 2021; diffusers' squaredcos_cap_v2)."""
    def alpha_bar(t: float) -> float:
        return math.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2

    return torch.tensor([min(1 - alpha_bar((i + 1) / steps) / alpha_bar(i / steps), max_beta)
                         for i in range(steps)], dtype=torch.float64)


class DDPMSchedule(nn.Module):
    def __init__(self, train_steps: int = 100):
        super().__init__()
        self.train_steps = train_steps
        alphas_cumprod = torch.cumprod(1 - cosine_betas(train_steps), 0)
        # float64 for the schedule's arithmetic; a buffer, so it follows the model's device
        self.register_buffer("alphas_cumprod", alphas_cumprod, persistent=False)

    def add_noise(self, x0: torch.Tensor, noise: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        """q(x_t | x_0) for integer timesteps t (B,)."""
        a = self.alphas_cumprod[t].to(x0.dtype).view(-1, *[1] * (x0.dim() - 1))
        return a.sqrt() * x0 + (1 - a).sqrt() * noise

    @torch.no_grad()
    def ddim_sample(self, eps_model: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
                    shape: tuple[int, ...], steps: int, generator: torch.Generator | None,
                    device: torch.device, start: torch.Tensor | None = None) -> torch.Tensor:
        """Deterministic DDIM (eta = 0) in ``steps`` evenly spaced steps from pure noise; the
        noise comes from the caller's generator, so a seeded episode samples the same chunks,
        or is ``start`` (``shape``), drawn by the caller (a generator per row, so that a row's
        chunk does not depend on the rows beside it)."""
        if not 1 <= steps <= self.train_steps:
            raise ValueError(f"DDIM steps must be in [1, {self.train_steps}], got {steps}")
        if start is None:
            start = torch.randn(shape, generator=generator, device="cpu")
        x = start.to(device)
        # floor(i T / steps), from the top: i * stride where steps divides T (diffusers'
        # "leading" spacing), and still down to t = 0 where it does not
        times = [i * self.train_steps // steps for i in range(steps)][::-1]
        acp = self.alphas_cumprod.cpu().tolist()
        for i, t in enumerate(times):
            eps = eps_model(x, torch.full((shape[0],), t, device=device, dtype=torch.long))
            a_t, a_prev = acp[t], (acp[times[i + 1]] if i + 1 < steps else 1.0)
            x0 = ((x - math.sqrt(1 - a_t) * eps) / math.sqrt(a_t)).clamp(-1, 1)
            eps = (x - math.sqrt(a_t) * x0) / math.sqrt(1 - a_t)  # consistent with the clipped x0
            x = math.sqrt(a_prev) * x0 + math.sqrt(1 - a_prev) * eps
        return x
