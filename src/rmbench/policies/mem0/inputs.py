"""What Mem-0's executor and planner read at one step, by the config's ``observation``: the
cameras' frames through one CNN each (or, with a frozen ``backbone``, their feature maps
through one head each), or the environment and joint states through the state MLP. Either
encoder maps a step's inputs to tokens (B, n, dim)."""

from __future__ import annotations

import torch
from torch import nn

from rmbench.data import layout as L
from rmbench.policies.feature_cache import features_key
from rmbench.policies.mem0.config import Mem0Config
from rmbench.policies.nn.backbone import camera_encoders
from rmbench.policies.nn.state import StateEncoder
from rmbench.policies.nn.vision import color_jitter
from rmbench.policies.observation import add_state_noise, shuffle_groups


def observation_encoder(cfg: Mem0Config, cameras: int, state_dim: int) -> nn.Module:
    """The CNNs or backbone heads (one per camera) or, with observation "state", the state
    MLP; either maps the step's inputs (``Mem0Policy.inputs``) to tokens (B, n, dim)."""
    if cfg.reads_state:
        return StateEncoder(state_dim, cfg.dim, cfg.state_tokens, cfg.state_hidden,
                            grasp_pose=cfg.grasp_pose_input, reach=len(cfg.reach_input))
    return camera_encoders(cfg.backbone, cfg.backbone_stride, cameras, cfg.dim,
                           cfg.encoder_channels, cfg.keypoints)


def step_inputs(batch: dict[str, torch.Tensor], cfg: Mem0Config, cameras: tuple[str, ...],
                generator: torch.Generator | None, noise_scale: torch.Tensor | None = None,
                state: torch.Tensor | None = None,
                exchange: list[torch.Tensor] | None = None) -> list[torch.Tensor]:
    """A training batch's inputs to ``observation_encoder``: the frames of ``cameras``
    (jittered when ``generator`` is given), their cached backbone features, or the
    environment state (its ``exchange`` groups traded, then ``state_noise`` added, per entry
    ``noise_scale``, when a generator is given) and the joint state (``state``, default the
    batch's)."""
    if cfg.reads_state:
        env_state = batch[L.ENV_STATE]
        if generator is not None:
            env_state = shuffle_groups(env_state, exchange, generator)
            env_state = add_state_noise(env_state, noise_scale, generator)
        return [env_state, batch[L.STATE] if state is None else state]
    if cfg.reads_features:
        return [batch[features_key(cam)] for cam in cameras]
    images = [batch[L.image_key(cam)] for cam in cameras]
    if generator is not None and any(cfg.jitter):
        images = [color_jitter(img, generator, *cfg.jitter) for img in images]
    return images
