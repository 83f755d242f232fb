"""What the memoryless baselines (Diffusion Policy, ACT) share: a config base, the training
step's plumbing, training on uniformly drawn frames, and the closed loop over a short
observation window.

A model here implements
    ``observe(inputs, state) -> features``   one control step's observation, encoded once:
                                             ``inputs`` the per-camera images (with a
                                             frozen backbone their feature maps), or with
                                             observation "state" [environment_state, state]
    ``predict(window, state, generators) -> (B, H, A)``   normalised action chunk from the
                                      last ``obs_steps`` features, oldest first; row i's noise
                                      (where it samples) from ``generators[i]``
and holds ``encoders`` (its CNNs or backbone heads, or the state MLP) and ``normalizer``; it
is built as ``model_cls(cfg, state_dim)`` (``state_dim`` the environment state's length, 0 for
pixels).
Nothing carries over beyond the window: that is the point of these baselines on a memory
benchmark.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from rmbench.data import layout as L
from rmbench.data.layout_shift import COPIES_SEED, add_layout_copies
from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import DemoDataset, RandomFrameSampler
from rmbench.policies.base import BasePolicy
from rmbench.policies.checkpoint import (
    dataset_record,
    load_policy,
    save_checkpoint,
    saved_step,
)
from rmbench.policies.config import PolicyConfig, parse_argument
from rmbench.policies.feature_cache import (
    features_key,
    features_record,
    with_features,
)
from rmbench.policies.nn.backbone import camera_encoders
from rmbench.policies.nn.inference import inference
from rmbench.policies.nn.normalize import Normalizer
from rmbench.policies.nn.state import StateEncoder
from rmbench.policies.nn.vision import color_jitter
from rmbench.policies.observation import (
    ReadsObservation,
    add_state_noise,
    camera_inputs,
    check_observation,
    choose,
    exchange_groups,
    joint_noise_scale,
    set_state_stats,
    shuffle_groups,
    state_inputs,
    state_noise_scale,
    state_tensor,
)
from rmbench.tasks import get_task
from rmbench.training.batches import batch_stream
from rmbench.training.loop import TrainConfig, rank_seed, train


@dataclass(frozen=True)
class VisuomotorConfig(ReadsObservation, PolicyConfig):
    """Fields every baseline has; subclasses add theirs and may change these defaults."""

    observation: str = "auto"
    """What the policy reads. "pixels": the cameras below, each through its own CNN. "state":
    observation.environment_state (normalised with the dataset's statistics) and the joint
    state through an MLP (``state_tokens`` tokens of width ``dim`` in place of the camera
    features); evaluation then runs the env with obs_type="environment_state_agent_pos".
    "auto" (the default) is settled by training from the dataset: "pixels" if it has camera
    videos, else "state"; ask for the state of a dataset with videos with
    --set observation=state. The checkpoint stores the choice (one from before this field
    reads as pixels)."""
    state_tokens: int = 2
    """With observation "state": tokens per step (as cameras are with pixels)."""
    state_hidden: int = 256
    """With observation "state": hidden width of the state encoder's two layers."""
    cameras: tuple[str, ...] = ("head", "left_wrist", "right_wrist")
    """Cameras read, each through its own CNN (the same encoder Mem-0 uses)."""
    image_size: tuple[int, int] = (96, 128)
    """(height, width) the frames are resized to."""
    encoder_channels: tuple[int, ...] = (32, 64, 128, 128)
    """CNN stage widths; each stage halves the resolution. With a frozen ``backbone`` the last
    is the width of the heads over its features."""
    obs_steps: int = 1
    """Observation window: the model sees this many most recent control steps."""
    horizon: int = 16
    """Actions predicted per chunk."""
    execute: int = 8
    """Actions executed from each chunk before predicting again."""
    relative_actions: bool = True
    """Joint targets as offsets from the current joint positions, grippers absolute, as in
    Mem-0 here, so that the benchmark's comparison isolates memory. False: the published
    absolute targets."""
    lr: float = 1e-3
    """Everything but the CNNs. The published rates (1e-4 DP, 1e-5 ACT) go with pretrained or
    long GPU runs; at CPU scale (batch 32, a few thousand steps) Mem-0's measured 1e-3 is used."""
    min_lr: float = 1e-5
    lr_backbone: float = 1e-3
    """The CNNs, trained from scratch (with a frozen ``backbone``: the heads over its features)."""
    min_lr_backbone: float = 1e-5
    jitter: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """Colour jitter (brightness, contrast, saturation) in training; none with a frozen
    ``backbone`` (its features are cached once per frame)."""

    INFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ("execute",)

    def __post_init__(self):
        super().__post_init__()
        check_observation(self.observation)
        if self.state_tokens < 1 or self.state_hidden < 1:
            raise ValueError("state_tokens and state_hidden must be >= 1")
        if not self.cameras and not self.reads_state:
            raise ValueError("a visuomotor policy needs at least one camera")
        if self.obs_steps < 1 or self.horizon < 1:
            raise ValueError("obs_steps and horizon must be >= 1")
        if not 1 <= self.execute <= self.horizon:
            raise ValueError(f"execute ({self.execute}) must be in [1, horizon={self.horizon}]")


def observation_encoder(cfg: VisuomotorConfig, state_dim: int, keypoints: int,
                        pooled: bool = True) -> nn.Module:
    """The CNNs or backbone heads (one per camera; ``pooled=False``: feature maps) or, with
    observation "state", the state MLP (``cfg.state_tokens`` tokens (B, n, cfg.dim))."""
    if cfg.reads_state:
        return StateEncoder(state_dim, cfg.dim, cfg.state_tokens, cfg.state_hidden,
                            grasp_pose=cfg.grasp_pose_input)
    return camera_encoders(cfg.backbone, cfg.backbone_stride, len(cfg.cameras), cfg.dim,
                           cfg.encoder_channels, keypoints, pooled)


class VisuomotorTrainer(nn.Module):
    """The training step's shared parts: jittered images (or cached backbone features) per
    camera, or the states (with ``state_noise``), flattened over the observation window, the
    two learning-rate groups, and the noise generator carried across a resume. Subclasses
    implement ``forward(batch) -> (loss, logs)``."""

    def __init__(self, model: nn.Module, seed: int, state_names: tuple[str, ...] = ()):
        super().__init__()
        self.model = model
        self.generator = torch.Generator().manual_seed(seed)
        self.noise_scale = state_noise_scale(model.cfg, state_names)
        self.exchange = exchange_groups(model.cfg, state_names)
        self.joint_scale = joint_noise_scale(model.cfg)

    def observe(self, batch: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """The window's features (B, obs_steps, ...) through ``model.observe``, and the joint
        state the policy reads at the window's last step (B, 14): noisy with joint_noise,
        which every head that reads the joints must see (``target`` keeps the exact one)."""
        cfg = self.model.cfg
        state = add_state_noise(batch[L.STATE], self.joint_scale, self.generator)
        if cfg.obs_steps == 1:
            state = state[:, None]
        b, n = state.shape[:2]
        if cfg.reads_state:
            env_state = shuffle_groups(batch[L.ENV_STATE], self.exchange, self.generator)
            env_state = add_state_noise(env_state, self.noise_scale, self.generator)
            inputs = [env_state.reshape(b * n, -1), state.reshape(b * n, -1)]
        elif cfg.reads_features:  # no jitter on cached features (feature_cache.py)
            inputs = [batch[features_key(cam)].flatten(0, -4) for cam in cfg.cameras]
        else:
            inputs = []
            for cam in cfg.cameras:
                img = batch[L.image_key(cam)].reshape(b * n, *batch[L.image_key(cam)].shape[-3:])
                inputs.append(color_jitter(img, self.generator, *cfg.jitter) if any(cfg.jitter)
                              else img)
        features = self.model.observe(inputs, state.reshape(b * n, -1))
        return features.reshape(b, n, *features.shape[1:]), state[:, -1]

    def target(self, batch: dict[str, torch.Tensor]) -> torch.Tensor:
        """Normalised action chunk, relative to the window's last state."""
        state = batch[L.STATE] if self.model.cfg.obs_steps == 1 else batch[L.STATE][:, -1]
        return self.model.normalizer.action(batch[L.ACTION], state)

    def param_groups(self) -> list[dict]:
        cfg = self.model.cfg
        backbone = list(self.model.encoders.parameters())
        ids = {id(p) for p in backbone}
        return [{"name": "backbone", "params": backbone, "lr": cfg.lr_backbone,
                 "min_lr": cfg.min_lr_backbone},
                {"name": "heads", "params": [p for p in self.model.parameters() if id(p) not in ids],
                 "lr": cfg.lr, "min_lr": cfg.min_lr}]

    def extra_state(self) -> dict:
        return {"generator": self.generator.get_state()}

    def load_extra_state(self, state: dict) -> None:
        self.generator.set_state(state["generator"].cpu())

    def export_module(self) -> nn.Module:
        return self.model


def train_visuomotor(policy: str, cfg: VisuomotorConfig, model_cls: type[nn.Module],
                     trainer_cls: type[VisuomotorTrainer], dataset: str | Path, out: str | Path,
                     train_cfg: TrainConfig, progress: bool = True, workers: int = 0
                     ) -> dict[str, Any]:
    """Train a baseline on uniformly drawn frames of one task's dataset (their camera frames
    or their state, ``cfg.observation``): the model is built from ``cfg`` under the run's seed,
    its normalisers set from the dataset, then wrapped by the trainer (an EMA copy then starts
    from the right statistics)."""
    ds = Dataset(dataset)
    task = get_task(ds.task)
    cfg = replace(cfg, observation=choose(cfg.observation, ds))
    describe = {"policy": policy, "config": cfg.to_dict(), "task": task.name, "tmc": task.tmc,
                "gym_id": ds.gym_id,
                "dataset": dataset_record(ds, dataset), **features_record(cfg)}
    if cfg.reads_state:
        describe["state_names"] = ds.state_names
    missing = [] if cfg.reads_state else sorted(set(cfg.cameras) - set(ds.cameras))
    if missing:
        raise ValueError(f"{dataset} has no {missing} camera(s) (has {list(ds.cameras)}); "
                         f"train with --set 'cameras={json.dumps(list(ds.cameras))}'")
    torch.manual_seed(train_cfg.seed)
    model = model_cls(cfg, len(ds.state_names or ()) if cfg.reads_state else 0)
    frames = DemoDataset(ds, chunk=cfg.horizon,
                         cameras=[] if cfg.reads_state or cfg.reads_features else list(cfg.cameras),
                         image_size=cfg.image_size, history=cfg.obs_steps,
                         environment_state=cfg.reads_state)
    # the joint targets' range is the recorded demonstrations' (measured before any copies),
    # as Mem-0's
    norm = Normalizer.for_demonstrations(ds.stats, frames.low_dim, cfg.horizon,
                                         cfg.relative_actions)
    model.normalizer.load_state_dict(norm.state_dict())
    if cfg.layout_copies:
        describe["layout_copies_kept"] = add_layout_copies(
            frames, cfg.layout_copies, cfg.layout_shift, COPIES_SEED)
    if cfg.reads_state:
        set_state_stats((model.encoders,), ds.stats, frames.low_dim)
    trainer = trainer_cls(model, rank_seed(train_cfg.seed), tuple(ds.state_names or ()))
    frames = with_features(frames, ds, cfg)

    def batches(start: int, rank: int, world: int):
        sampler = RandomFrameSampler(frames, train_cfg.batch_size,
                                     seed=rank_seed(train_cfg.seed, rank))
        return batch_stream(frames, sampler, start, workers)

    return train(trainer, batches, train_cfg, out, describe, progress,
                 write_checkpoint=save_checkpoint, checkpoint_step=saved_step,
                 config_defaults=type(cfg).saved_defaults(), data=ds.fingerprint)


class _Slot:
    """One episode's state: its sampling generator (seeded from the task seed), its window of
    encoded steps, the chunk being executed, its step count and what the subclass adds."""

    def __init__(self, seed: int = 0):
        self.generator = torch.Generator().manual_seed(seed)
        self.window: list[torch.Tensor] = []
        self.queue: list[np.ndarray] = []
        self.t = 0


class VisuomotorPolicy(BasePolicy):
    """The closed loop: encode each step's observation once, keep the last ``obs_steps``
    (the first repeated at an episode's start, as in training), predict a chunk when the last
    one's ``execute`` actions are used up. Subclasses set ``name``, ``config_cls`` and
    ``model_cls``, and may override ``due`` and ``take`` (ACT's temporal ensembling).

    Several episodes side by side through ``reset_batch``/``act_batch`` (policies/base.py):
    each step encodes every slot's observation in one call and predicts the chunks the slots
    need in one call, always over all B rows (idle rows copy a live one), each slot's noise
    from its own generator, so an episode's actions do not depend on the others in its batch.
    One episode alone (``reset``/``act``) is a batch of one."""

    name: ClassVar[str]
    config_cls: ClassVar[type]
    model_cls: ClassVar[type]

    def __init__(self, arg: str, env=None):
        path, overrides, _ = parse_argument(arg, self.config_cls)
        model, _, describe = load_policy(
            path, self.name, self.config_cls,
            lambda cfg, describe: self.model_cls(cfg, len(describe.get("state_names") or ())),
            overrides, env=env)
        self._setup(model, describe)

    @classmethod
    def from_model(cls, model: nn.Module, describe: dict[str, Any] | None = None):
        """A policy around an in-memory model (benchmarks, tests)."""
        policy = cls.__new__(cls)
        policy._setup(model, describe or {})
        return policy

    def _setup(self, model: nn.Module, describe: dict[str, Any]) -> None:
        self.model, self.cfg, self.describe = model.eval(), model.cfg, describe
        self.slots: list[_Slot] = []
        self.reset("", {})

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        """One episode: a batch of one slot."""
        self.slots = []
        self.reset_batch(0, instruction, task_info)

    def reset_batch(self, slot: int, instruction: str, task_info: dict[str, Any],
                    env=None) -> None:
        """A new episode in ``slot``."""
        self.slots += [self.new_slot() for _ in range(slot + 1 - len(self.slots))]
        self.slots[slot] = self.new_slot(int(task_info.get("seed", 0)))

    def new_slot(self, seed: int = 0) -> _Slot:
        return _Slot(seed)

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """One control step: the observation in, the next 14-d joint target out."""
        return self.act_batch([observation])[0]

    @inference
    def act_batch(self, observations: list[dict[str, Any] | None]) -> list[np.ndarray | None]:
        """One control step of every slot whose observation is given (``act``'s, per slot),
        the network run over ``len(observations)`` rows."""
        n = len(observations)
        live = [i for i, o in enumerate(observations) if o is not None]
        if not live:
            return [None] * n
        self.slots += [self.new_slot() for _ in range(n - len(self.slots))]
        # idle rows copy a live one: its inputs, converted once
        converted = {i: (self.inputs(observations[i]), state_tensor(observations[i])) for i in live}
        per_row = [converted.get(i, converted[live[0]]) for i in range(n)]
        state = torch.cat([s for _, s in per_row])
        features = self.model.observe(
            [torch.cat(x) for x in zip(*(inputs for inputs, _ in per_row), strict=True)], state)
        for i in live:
            s = self.slots[i]
            s.window = (s.window or [features[i:i + 1]] * self.cfg.obs_steps)[1:] + [features[i:i + 1]]
        due = [i for i in live if self.due(self.slots[i])]
        chunks = self.chunks(state, due) if due else {}
        actions: list[np.ndarray | None] = [None] * n
        for i in live:
            actions[i] = self.take(self.slots[i], chunks.get(i))
            self.slots[i].t += 1
        return actions

    def chunks(self, state: torch.Tensor, due: list[int]) -> dict[int, np.ndarray]:
        """A new chunk (H, 14) of absolute joint targets from each ``due`` slot's window, every
        row through the model at once (a row not due reads the first due slot's window and
        draws no noise)."""
        windows = [self.slots[i].window if i in due else self.slots[due[0]].window
                   for i in range(len(state))]
        window = [torch.cat(step) for step in zip(*windows, strict=True)]
        generators = [self.slots[i].generator if i in due else None for i in range(len(state))]
        normalised = self.model.predict(window, state, generators)
        actions = self.model.normalizer.unaction(normalised, state)
        return {i: actions[i].double().numpy() for i in due}

    def due(self, slot: _Slot) -> bool:
        """Whether ``slot`` needs a new chunk at this step."""
        return not slot.queue

    def take(self, slot: _Slot, chunk: np.ndarray | None) -> np.ndarray:
        """The step's action for ``slot``, given the chunk predicted for it now (None if
        none was due)."""
        if chunk is not None:
            slot.queue = list(chunk[:self.cfg.execute])
        return slot.queue.pop(0)

    def inputs(self, observation: dict[str, Any]) -> list[torch.Tensor]:
        """What ``model.observe`` encodes: one image (or its frozen backbone's feature map)
        per camera, or [environment_state, agent_pos] (a one-line ValueError if the
        observation lacks what the policy reads)."""
        if self.cfg.reads_state:
            return state_inputs(observation, self.model.encoders.state_dim)
        return camera_inputs(observation, self.cfg)
