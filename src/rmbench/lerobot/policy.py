"""``lerobot:PATH``: a LeRobot checkpoint (``lerobot-train``'s ``pretrained_model`` folder)
evaluated by ``rmbench eval``, in a LeRobot environment with rmbench installed.

Each step runs what ``lerobot-eval`` runs: the observation in LeRobot's names (its own
``preprocess_observation``: rmbench's layout is gym-aloha's), the instruction as the task
text, the checkpoint's saved pre-processor, ``select_action`` (ACT's and Diffusion Policy's
own action queues included) and its post-processor. Camera frames of another size than the
checkpoint was trained on are resized to it. ``reset`` clears the policy's queues, so the
memory probe (``--memory-reset``) reaches it too.

Registering the spec imports nothing of LeRobot; building the policy does.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import numpy as np

from rmbench.policies.base import BasePolicy
from rmbench.policies.registry import register_policy

STATE_KEY, IMAGE_PREFIX = "observation.environment_state", "observation.images."


def checkpoint_inputs(path: str | Path) -> dict[str, Any]:
    """The checkpoint's input features (``config.json``), or a one-line error naming it."""
    config = Path(path) / "config.json"
    if not config.is_file():
        raise ValueError(f"{path}: no config.json (a LeRobot checkpoint folder: "
                         f"OUTPUT/checkpoints/last/pretrained_model)")
    try:
        saved = json.loads(config.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ValueError(f"{config}: unreadable ({err})") from None
    if not (isinstance(saved, dict) and isinstance(saved.get("type"), str)
            and isinstance(saved.get("input_features"), dict)):
        raise ValueError(f"{config}: not a LeRobot policy config (its 'type' and "
                         f"'input_features'); an rmbench checkpoint is evaluated as "
                         f"mem0:, dp: or act:")
    return saved["input_features"]


def check(path: str | None) -> None:
    """The spec's check, before an evaluation writes anything: a LeRobot checkpoint folder,
    and LeRobot installed to build it."""
    checkpoint_inputs(path or "")
    import importlib.util

    if importlib.util.find_spec("lerobot") is None:
        raise RuntimeError("lerobot: LeRobot is not installed here: evaluate LeRobot "
                           "checkpoints in LeRobot's environment (docs/guides/lerobot.md)")


def obs_type(path: str | None) -> str:
    """The rmbench observation a checkpoint reads: its images, its state vector, or both."""
    inputs = checkpoint_inputs(path or "")
    pixels = any(k.startswith(IMAGE_PREFIX) for k in inputs)
    if STATE_KEY in inputs:
        return "pixels_environment_state_agent_pos" if pixels else "environment_state_agent_pos"
    return "pixels_agent_pos"


def checkpoint_cameras(path: str | None) -> tuple[str, ...]:
    """The cameras whose images a checkpoint reads (none: its env renders nothing)."""
    return tuple(k[len(IMAGE_PREFIX):] for k in checkpoint_inputs(path or "")
                 if k.startswith(IMAGE_PREFIX))


class LeRobotPolicy(BasePolicy):
    def __init__(self, path: str, device: str = "cpu"):
        import torch
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.envs.utils import preprocess_observation
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        self.torch, self.preprocess = torch, preprocess_observation
        # a local folder with its config.json (a one-line error otherwise): LeRobot's
        # from_pretrained then loads from disk and never looks a name up on a hub
        inputs = checkpoint_inputs(path)
        cfg = PreTrainedConfig.from_pretrained(path)
        cfg.pretrained_path, cfg.device = path, device
        self.policy = get_policy_class(cfg.type).from_pretrained(path, config=cfg)
        self.policy.eval()
        self.pre, self.post = make_pre_post_processors(
            cfg, pretrained_path=path,
            preprocessor_overrides={"device_processor": {"device": device}})
        # (C, H, W) of each camera the checkpoint reads
        self.images = {k[len(IMAGE_PREFIX):]: tuple(v["shape"]) for k, v in inputs.items()
                       if k.startswith(IMAGE_PREFIX)}
        self.instruction = ""

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        self.instruction = instruction
        self.policy.reset()

    def fork(self) -> LeRobotPolicy:
        """A copy for another connection of the policy server: the same weights, its own
        episode state. LeRobot keeps a policy's action queues on the policy module, and its
        ``reset`` binds new ones, so a shallow copy of the module holds its own queues; ACT's
        temporal ensembler, when configured, is cleared in place by ``reset``, so each copy
        gets its own."""
        other = copy.copy(self)
        other.policy = copy.copy(self.policy)
        ensembler = getattr(self.policy, "temporal_ensembler", None)
        if ensembler is not None:
            other.policy.temporal_ensembler = copy.deepcopy(ensembler)
        return other

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        torch = self.torch
        obs = {k: v for k, v in observation.items() if k != "pixels"}
        if self.images:
            obs["pixels"] = {c: observation["pixels"][c] for c in self.images}
        batch = self.preprocess(obs)
        for cam, (_, h, w) in self.images.items():
            key = IMAGE_PREFIX + cam
            if tuple(batch[key].shape[-2:]) != (h, w):
                batch[key] = torch.nn.functional.interpolate(
                    batch[key], size=(h, w), mode="bilinear", antialias=True, align_corners=False)
        batch["task"] = [self.instruction]
        with torch.inference_mode():
            action = self.post(self.policy.select_action(self.pre(batch)))
        return action.to("cpu").numpy().reshape(-1)


register_policy("lerobot", "a LeRobot checkpoint (lerobot-train's pretrained_model folder; "
                "needs LeRobot installed): lerobot:PATH", needs_argument=True,
                obs_type=obs_type, cameras=checkpoint_cameras,
                check=check)(lambda arg, env: LeRobotPolicy(arg))
