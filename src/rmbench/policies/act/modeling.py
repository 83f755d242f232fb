"""ACT: a conditional VAE whose decoder is a transformer encoder-decoder.

    CVAE encoder (training only):  [CLS; state; a_1..a_k] -> mu, log sigma^2 -> z
    observation tokens:            every cell of every camera's CNN feature map, with 2-D
                                   sinusoidal positions and a camera embedding (observation
                                   "pixels"); or the state MLP's state_tokens tokens, each with
                                   its own embedding (observation "state")
    encoder:                       [z; state; observation tokens]
    decoder:                       k learned queries cross-attend -> k actions
    loss:                          L1 over real (not padded) steps + beta KL(q(z) || N(0, I))

At inference z = 0 (the prior's mean). Positions are added once at the input rather than at
every attention layer as in DETR; the layers are pre-norm, which trains stably at the
CPU-scale learning rate.
"""

from __future__ import annotations

import torch
from torch import nn

from rmbench.policies.act.config import ACTConfig
from rmbench.policies.nn.embeddings import sincos_1d, sincos_2d
from rmbench.policies.nn.normalize import Normalizer
from rmbench.policies.visuomotor import VisuomotorTrainer, observation_encoder
from rmbench.sim.simulator import ACTION_DIM


def _encoder(cfg: ACTConfig) -> nn.TransformerEncoder:
    layer = nn.TransformerEncoderLayer(cfg.dim, cfg.heads, cfg.feedforward, cfg.dropout,
                                       activation="relu", batch_first=True, norm_first=True)
    return nn.TransformerEncoder(layer, cfg.encoder_layers, norm=nn.LayerNorm(cfg.dim),
                                 enable_nested_tensor=False)


class ACTModel(nn.Module):
    """ACT's network: one control step's observation (camera images, or the environment state)
    and the joint state in, a normalised chunk of ``horizon`` joint targets (B, k, 14) out. The
    CVAE encoder that draws the style variable z runs in training only."""

    def __init__(self, cfg: ACTConfig, state_dim: int = 0):
        super().__init__()
        self.cfg = cfg
        d = cfg.dim
        self.encoders = observation_encoder(cfg, state_dim, 0, pooled=False)
        self.camera_embed = nn.Parameter(torch.randn(cfg.step_tokens, d) * 0.02)
        self.normalizer = Normalizer(ACTION_DIM)
        # the CVAE encoder
        self.cls = nn.Parameter(torch.randn(d) * 0.02)
        self.vae_state = nn.Linear(ACTION_DIM, d)
        self.vae_action = nn.Linear(ACTION_DIM, d)
        self.register_buffer("vae_pos", sincos_1d(cfg.horizon + 2, d), persistent=False)
        self.vae_encoder = _encoder(cfg)
        self.latent_out = nn.Linear(d, 2 * cfg.latent_dim)
        # the policy
        self.latent_in = nn.Linear(cfg.latent_dim, d)
        self.state_in = nn.Linear(ACTION_DIM, d)
        self.extra_pos = nn.Parameter(torch.randn(2, d) * 0.02)
        self.encoder = _encoder(cfg)
        layer = nn.TransformerDecoderLayer(d, cfg.heads, cfg.feedforward, cfg.dropout,
                                           activation="relu", batch_first=True, norm_first=True)
        self.decoder = nn.TransformerDecoder(layer, cfg.decoder_layers, norm=nn.LayerNorm(d))
        self.queries = nn.Parameter(torch.randn(cfg.horizon, d) * 0.02)
        self.action_out = nn.Linear(d, ACTION_DIM)

    def observe(self, inputs: list[torch.Tensor], state: torch.Tensor) -> torch.Tensor:
        """One step's observation tokens (B, cameras * h * w, dim), or (B, state_tokens, dim)."""
        if self.cfg.reads_state:
            return self.encoders(inputs) + self.camera_embed
        maps = self.encoders(inputs)  # (B, C, d, h, w)
        _, _, d, h, w = maps.shape
        tokens = maps.flatten(3).transpose(2, 3)  # (B, C, h * w, d)
        tokens = tokens + sincos_2d(h, w, d).to(tokens) + self.camera_embed[:, None]
        return tokens.flatten(1, 2)

    def latent(self, state: torch.Tensor, target: torch.Tensor, is_pad: torch.Tensor,
               generator: torch.Generator | None) -> tuple[torch.Tensor, ...]:
        """z ~ q(z | state, normalised chunk), reparameterised; and its mu, log variance."""
        b = target.shape[0]
        x = torch.cat([self.cls.expand(b, 1, -1), self.vae_state(self.normalizer.state(state))[:, None],
                       self.vae_action(target)], 1) + self.vae_pos
        mask = torch.cat([torch.zeros(b, 2, dtype=torch.bool, device=is_pad.device), is_pad], 1)
        mu, logvar = self.latent_out(self.vae_encoder(x, src_key_padding_mask=mask)[:, 0]).chunk(2, -1)
        eps = torch.randn(mu.shape, generator=generator).to(mu.device)
        return mu + (0.5 * logvar).exp() * eps, mu, logvar

    def decode(self, tokens: torch.Tensor, state: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Normalised chunk (B, k, 14) from observation tokens, the raw state and z."""
        extra = torch.stack([self.latent_in(z), self.state_in(self.normalizer.state(state))], 1)
        memory = self.encoder(torch.cat([extra + self.extra_pos, tokens], 1))
        queries = self.queries.expand(tokens.shape[0], -1, -1)
        return self.action_out(self.decoder(queries, memory))

    def predict(self, window: list[torch.Tensor], state: torch.Tensor,
                generators: list[torch.Generator | None]) -> torch.Tensor:
        """The normalised chunk (B, k, 14) from the window's last step (ACT sees one) and the
        raw joint state, with z = 0: deterministic, ``generators`` are not drawn from."""
        tokens = window[-1]
        z = torch.zeros(tokens.shape[0], self.cfg.latent_dim, device=tokens.device)
        return self.decode(tokens, state, z)


class ACTTrainer(VisuomotorTrainer):
    """ACT's training step on a batch of frames and their chunks: L1 over the chunk's real
    steps plus ``kl_weight`` times the KL of z's posterior from N(0, I)."""

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
        model = self.model
        tokens, state = self.observe(batch)
        tokens = tokens[:, -1]
        target, is_pad = self.target(batch), batch["action_is_pad"]
        z, mu, logvar = model.latent(state, target, is_pad, self.generator)
        keep = (~is_pad).float()[..., None]
        l1 = ((model.decode(tokens, state, z) - target).abs() * keep).sum() / (keep.sum() * ACTION_DIM)
        kl = (-0.5 * (1 + logvar - mu.pow(2) - logvar.exp())).sum(-1).mean()
        return l1 + model.cfg.kl_weight * kl, {"loss/l1": l1.item(), "loss/kl": kl.item()}
