"""Environment observations as the tensors the learned policies read, and the choice between
the two observations a learned policy can be trained on.

``observation`` in Mem-0's, DP's and ACT's configs:

- ``"pixels"``: the cameras, each through its own CNN (frames resized as in training: the
  dataset's frame cache uses the same antialiased resize);
- ``"state"``: ``observation.environment_state`` (the task's vector of what the head camera
  shows, docs/state_observation.md) with the joint state, through a small MLP
  (``nn/state.py``); no frame is decoded in training, nothing is rendered in evaluation;
- ``"auto"`` (the default): chosen by ``rmbench train`` from the dataset (``choose``):
  ``"pixels"`` when it has camera videos, ``"state"`` when it has none. State from a dataset
  with videos is asked for with ``--set observation=state``. The checkpoint stores the choice.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from rmbench.data import layout as L
from rmbench.data.torch_dataset import resize

PIXELS, STATE, AUTO = "pixels", "state", "auto"
OBSERVATIONS = (AUTO, PIXELS, STATE)
# the env observation a state policy reads (rmbench.make(task, obs_type=...))
STATE_OBS_TYPE = "environment_state_agent_pos"


class ReadsObservation:
    """What a policy config derives from its ``observation``, ``state_tokens`` and ``cameras``
    fields (Mem-0's and the baselines' configs both have them)."""

    observation: str
    state_tokens: int
    cameras: tuple[str, ...]

    @property
    def reads_state(self) -> bool:
        """Reads the state observation ("auto", unsettled, reads pixels)."""
        return self.observation == STATE

    @property
    def step_tokens(self) -> int:
        """Tokens one step's observation becomes: one per camera, or ``state_tokens``."""
        return self.state_tokens if self.reads_state else len(self.cameras)


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
