"""The openpi adapter: rmbench observations in the ALOHA layout openpi's policies read, and
their action chunks back.

openpi's ALOHA policies (pi0, pi0.5 fine-tuned on ALOHA data) take
``{"state": (14,), "images": {"cam_high" | "cam_left_wrist" | "cam_right_wrist": uint8 (3, H, W)},
"prompt": str}`` and answer ``{"actions": (horizon, 14), ...}``. The 14-d layout is the same as
rmbench's (per arm: 6 joints, then the gripper in [0, 1], left arm first), so state and actions
pass through unchanged; converting to pi's internal joint signs and gripper angles is the
server's ``adapt_to_pi`` transform, not the client's. Images go from HWC to CHW; resizing to the
model's input is left to the server's transforms, as on the real robot.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rmbench.sim.simulator import ACTION_DIM

# rmbench camera -> openpi ALOHA image key
CAMERA_KEYS = {"head": "cam_high", "left_wrist": "cam_left_wrist", "right_wrist": "cam_right_wrist"}


def observation_to_openpi(observation: dict[str, Any], prompt: str) -> dict[str, Any]:
    pixels = observation.get("pixels") or {}
    missing = [cam for cam in CAMERA_KEYS if cam not in pixels]
    if missing:
        raise ValueError(f"the openpi ALOHA layout needs cameras {list(CAMERA_KEYS)}; "
                         f"missing {missing}")
    return {
        "state": np.asarray(observation["agent_pos"], dtype=np.float32),
        "images": {key: np.ascontiguousarray(np.asarray(pixels[cam], np.uint8).transpose(2, 0, 1))
                   for cam, key in CAMERA_KEYS.items()},
        "prompt": prompt,
    }


def actions_from_openpi(reply: Any, steps: int | None) -> np.ndarray:
    """The first ``steps`` actions of the chunk (all when None), as float64 (k, 14)."""
    if isinstance(reply, str):  # openpi's server sends a traceback as text, then closes
        lines = reply.strip().splitlines()
        raise RuntimeError(f"openpi server error: {lines[-1] if lines else '(empty message)'}")
    if not isinstance(reply, dict) or "actions" not in reply:
        raise RuntimeError(f"openpi reply has no 'actions': {type(reply).__name__}")
    actions = np.asarray(reply["actions"], dtype=np.float64)
    if actions.ndim == 1:
        actions = actions[None]
    if actions.ndim != 2 or actions.shape[1] < ACTION_DIM:
        raise RuntimeError(f"openpi actions of shape {actions.shape}, "
                           f"expected (horizon, >={ACTION_DIM})")
    # models padded to a larger action dim return the ALOHA dims first
    return actions[: steps or None, :ACTION_DIM]
