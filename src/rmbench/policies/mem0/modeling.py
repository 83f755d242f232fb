"""Mem-0's executor: encoder -> anchor and sliding memory fusion -> c_t -> flow-matching action
head and subtask-end classifier.

    tokens_t = [CNN_cam(o_t^cam) + e_cam]            one token per camera (observation "pixels")
             = MLP(env_state_t, state_t) + e_i        state_tokens tokens (observation "state")
    z_img    = mean(tokens_t)                        z_text = text table[s_t]
    a_t      = Fuse_A(z_img, anchor tokens)          (z_img with no_anchor / no_memory)
    s_t      = Fuse_S(z_img, last K z_img)           (z_img with no_sliding / no_memory)
    c_t      = [a_t; s_t; z_text]
    actions  ~ FlowHead(c_t, state)
    P(end)   = MLP([z_img; event window])            ("event": the last W z_img, kept across
             = MLP(c_t)                               subtasks; "context": as published)
"""

from __future__ import annotations

import json

import torch
import torch.nn.functional as F
from torch import nn

from rmbench.data import layout as L
from rmbench.policies.mem0.action_head import FlowMatchingHead
from rmbench.policies.mem0.config import Mem0Config
from rmbench.policies.mem0.inputs import observation_encoder, step_inputs
from rmbench.policies.mem0.memory import EventWindow, MemoryFusion, MemoryStore
from rmbench.policies.mem0.planner import Planner
from rmbench.policies.nn.ema import EMA
from rmbench.policies.nn.normalize import Normalizer
from rmbench.policies.nn.text import TextTable
from rmbench.policies.observation import (
    add_state_noise,
    exchange_groups,
    joint_noise_scale,
    position_noise_scale,
    state_noise_scale,
)
from rmbench.sim.simulator import ACTION_DIM


class Executor(nn.Module):
    """Mem-0's executor: each 20 Hz step's observation, the subtask's text and the memories in,
    c_t out; from c_t the logit that the subtask has ended, and with the joint state a
    normalised chunk of ``horizon`` actions (flow matching) whenever the policy needs one."""

    def __init__(self, cfg: Mem0Config, texts: list[str], text_vectors: torch.Tensor | None,
                 state_dim: int = 0):
        super().__init__()
        self.cfg = cfg
        d = cfg.dim
        self.encoders = observation_encoder(cfg, len(cfg.cameras), state_dim)
        self.camera_embed = nn.Parameter(torch.randn(cfg.step_tokens, d) * 0.02)
        self.text = TextTable(texts, d, text_vectors)
        self.anchor_fusion = MemoryFusion(d, cfg.heads, cfg.step_tokens)
        self.sliding_fusion = MemoryFusion(d, cfg.heads, cfg.sliding_window)
        self.state_proj = nn.Linear(ACTION_DIM, d)
        self.head = FlowMatchingHead(d, cfg.horizon, cfg.action_dim, cfg.head_layers, cfg.heads,
                                     cfg.action_patch)
        reads = cfg.event_window + 1 if cfg.end_classifier == "event" else 3
        self.classifier = nn.Sequential(nn.Linear(reads * d, d), nn.GELU(), nn.Linear(d, 1))
        self.normalizer = Normalizer(ACTION_DIM, cfg.action_dim)

    def encode(self, inputs: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-camera uint8 (B, 3, H, W), or [environment state (B, D), joint state (B, 14)],
        -> tokens (B, C, d) and z_img (B, d)."""
        tokens = self.encoders(inputs) + self.camera_embed
        return tokens, tokens.mean(1)

    def context(self, z: torch.Tensor, memory: MemoryStore, text: torch.Tensor) -> torch.Tensor:
        """c_t as three tokens (B, 3, d): anchor-fused, sliding-fused, z_text."""
        a = self.anchor_fusion(z, memory.anchor) if self.cfg.use_anchor else z
        s = self.sliding_fusion(z, memory.sliding, memory.valid) if self.cfg.use_sliding else z
        return torch.stack([a, s, self.text(text)], 1)

    def condition(self, c: torch.Tensor, state: torch.Tensor) -> torch.Tensor:
        return torch.cat([c, self.state_proj(self.normalizer.state(state))[:, None]], 1)

    def end_logit(self, c: torch.Tensor, z: torch.Tensor, events: EventWindow) -> torch.Tensor:
        """P(the subtask has ended) as a logit (B,): from z_img and the event window
        (end_classifier "event") or from c_t ("context"); read detached unless
        ``classifier_trains_encoder``, so its loss trains the classifier alone."""
        x = (torch.cat([z[:, None], events.entries], 1) if self.cfg.end_classifier == "event"
             else c)
        if not self.cfg.classifier_trains_encoder:
            x = x.detach()
        return self.classifier(x.flatten(1))[:, 0]

    def backbone_parameters(self) -> list[nn.Parameter]:
        return list(self.encoders.parameters())


class Mem0Model(nn.Module):
    """What a checkpoint holds: the executor and the planner."""

    def __init__(self, cfg: Mem0Config, executor_texts: list[str], planner_texts: list[str],
                 text_vectors: dict[str, torch.Tensor] | None, state_dim: int = 0):
        super().__init__()
        self.cfg = cfg
        vec = text_vectors or {}
        self.executor = Executor(cfg, executor_texts, vec.get("executor"), state_dim)
        if cfg.planner_backend == "vlm":
            from rmbench.policies.mem0.planner_vlm import VLMPlanner

            self.planner = VLMPlanner(cfg, planner_texts, state_dim=state_dim)
        else:
            self.planner = Planner(cfg, planner_texts, vec.get("planner"), state_dim)


class Mem0Trainer(nn.Module):
    """The executor's training step over episode-ordered batches: one memory slot per batch
    slot, reset at episode starts and (for M(n) tasks) where the plan's step changes."""

    def __init__(self, model: Mem0Model, batch_size: int, decompose: bool, seed: int,
                 state_names: list[str] | tuple[str, ...] = ()):
        super().__init__()
        self.model = model
        self.decompose = decompose
        cfg = model.cfg
        self.noise_scale = state_noise_scale(cfg, state_names)
        self.exchange = exchange_groups(cfg, state_names)
        self.memory_scale = position_noise_scale(cfg.memory_noise, cfg.memory_noise_on,
                                                 state_names)
        self.joint_scale = joint_noise_scale(cfg)
        self.memory = MemoryStore(batch_size, cfg.step_tokens, cfg.sliding_window, cfg.dim)
        self.events = EventWindow(batch_size, cfg.event_window, cfg.dim)
        self.register_buffer("last_step", torch.full((batch_size,), -1, dtype=torch.long),
                             persistent=False)
        self.generator = torch.Generator().manual_seed(seed)
        self.planner_report: dict | None = None  # the planner's fit (train.py), saved with the state
        for p in model.planner.parameters():
            p.requires_grad_(False)
        # built after the planner is fitted: its weights are copied as they are and stay
        self.ema = EMA(model, cfg.ema_power, cfg.ema_max_decay) if cfg.ema else None

    def param_groups(self) -> list[dict]:
        ex, cfg = self.model.executor, self.model.cfg
        backbone = {id(p) for p in ex.backbone_parameters()}
        return [{"name": "backbone", "params": ex.backbone_parameters(), "lr": cfg.lr_backbone,
                 "min_lr": cfg.min_lr_backbone},
                {"name": "heads", "params": [p for p in ex.parameters() if id(p) not in backbone],
                 "lr": cfg.lr_head, "min_lr": cfg.min_lr_head}]

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
        ex, cfg = self.model.executor, self.model.cfg
        # the joint state the policy reads (noisy with joint_noise); targets use the exact one
        state = add_state_noise(batch[L.STATE], self.joint_scale, self.generator)
        inputs = step_inputs(batch, cfg, cfg.cameras, self.generator, self.noise_scale, state,
                             self.exchange)
        tokens, z = ex.encode(inputs)
        # what the memories store: the same step, blurred further with memory_noise
        memory_tokens, memory_z = tokens, z
        if self.memory_scale is not None:
            blurred = add_state_noise(inputs[0], self.memory_scale, self.generator)
            memory_tokens, memory_z = ex.encode([blurred, *inputs[1:]])
        step = batch[L.SUBTASK_STEP]
        reset = batch["episode_start"].bool()
        self.events.reset(reset, z)
        if self.decompose:
            reset = reset | (step != self.last_step)
        self.memory.reset(reset, memory_tokens)
        self.last_step.copy_(step)
        c = ex.context(z, self.memory, batch["text_index"])
        self.memory.push(memory_z)
        target = ex.normalizer.action(batch[L.ACTION], batch[L.STATE])
        action_loss = ex.head.loss(ex.condition(c, state), target,
                                   batch["action_is_pad"], self.generator)
        logs = {"loss/action": action_loss.item()}
        loss = action_loss
        if self.decompose:
            label = batch["end_label"].float()
            pos = label.sum().clamp(min=1)
            end_loss = F.binary_cross_entropy_with_logits(
                ex.end_logit(c, z, self.events), label,
                pos_weight=((len(label) - pos) / pos).clamp(max=50))
            loss = loss + cfg.classifier_weight * end_loss
            logs["loss/end"] = end_loss.item()
        self.events.push(z)
        return loss, logs

    def extra_state(self) -> dict:
        return {"memory": self.memory.state(), "events": self.events.state(),
                "last_step": self.last_step, "generator": self.generator.get_state(),
                "planner_report": json.dumps(self.planner_report)}

    def load_extra_state(self, state: dict) -> None:
        self.memory.load_state(state["memory"])
        self.events.load_state(state["events"])
        self.last_step.copy_(state["last_step"])
        self.generator.set_state(state["generator"].cpu())
        self.planner_report = json.loads(state.get("planner_report", "null"))

    def after_step(self) -> None:
        if self.ema is not None:
            self.ema.update(self.model)

    def export_module(self) -> Mem0Model:
        return self.model if self.ema is None else self.ema.averaged
