"""Environment observations as the tensors the learned policies read, resized as in training
(the dataset's frame cache uses the same antialiased resize)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from rmbench.data.torch_dataset import resize


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
        if frame.shape[:2] != tuple(size):
            frame = resize(frame[None], tuple(size))[0]
        out.append(torch.from_numpy(np.ascontiguousarray(frame)).permute(2, 0, 1)[None])
    return out


def state_tensor(observation: dict[str, Any]) -> torch.Tensor:
    """The joint state (1, 14) float32."""
    return torch.as_tensor(np.asarray(observation["agent_pos"]), dtype=torch.float32)[None]
