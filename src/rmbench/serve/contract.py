"""What a served policy reads, announced in the server's greeting, and each client message
checked against it before any work is done.

An observation may hold exactly the entries the policy reads: ``agent_pos`` float (14,);
``pixels`` with exactly the policy's cameras, each uint8 (H, W, 3) no larger than
``frame_max``; ``environment_state`` float (D,) with D the task's state length. The largest
such message sizes the websocket's message cap. A reset may hold an instruction and the
task's facts, of the types the environment gives them.

A policy with the batched form (policies/base.py) is served ``batch`` slots per connection:
a batch message holds up to ``batch`` observations, each checked as a single one, so the cap
is the largest observation times the slots. The slots announced are at most ``MAX_SLOTS`` and
fewer where that product would pass ``MAX_BATCH_BYTES`` (large ``frame_max``), so the cap a
client can make the server read stays bounded whatever the frames.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rmbench.serve.wire import Limits, WireError
from rmbench.sim.simulator import ACTION_DIM
from rmbench.tasks import get_task

FRAME_MAX = (480, 640)  # (H, W): VGA, twice the env's default 240x320
MAX_TEXT = 4096  # an instruction, a subtask's name
ENVELOPE_BYTES = 64 * 2**10  # keys, headers and a reset's task facts around the arrays
MAX_SLOTS = 64  # episodes side by side on one connection of a batched policy
MAX_BATCH_BYTES = 256 * 2**20  # a batch message's cap never passes this
ENTRY_BYTES = 2 * 2**10  # an observation's keys and array headers inside a batch
ENTRY_ITEMS = 256  # values one observation of a batch may hold (a full one holds ~80)
# the task facts a reset may carry (run_policy_episode's task_info) and their types
TASK_INFO = {"task": str, "gym_id": str, "tmc": str, "step_limit": int, "subtasks": list,
             "seed": int, "instruction": str}


@dataclass(frozen=True)
class Contract:
    task: str
    obs_type: str
    cameras: tuple[str, ...]
    state_dim: int | None  # None: the policy reads no environment_state
    frame_max: tuple[int, int] = FRAME_MAX
    batch: int = 0  # slots per connection; 0: the policy plays one episode at a time
    # (W, H) the policy's frames are rendered at (its training data's), None: the env's default
    frame_size: tuple[int, int] | None = None

    def __post_init__(self):
        if len(self.frame_max) != 2 or min(self.frame_max) < 1:
            raise ValueError(f"frame_max must be (H, W) >= 1, got {self.frame_max}")
        if self.frame_size is not None and (self.frame_size[1] > self.frame_max[0]
                                            or self.frame_size[0] > self.frame_max[1]):
            w, h = self.frame_size
            raise ValueError(f"the policy reads {w}x{h} frames, larger than frame_max "
                             f"{self.frame_max[1]}x{self.frame_max[0]} (WxH)")
        if not 0 <= self.batch <= MAX_SLOTS:
            raise ValueError(f"batch must be in [0, {MAX_SLOTS}], got {self.batch}")

    @property
    def observation_bytes(self) -> int:
        """The arrays of the largest legal observation: every camera's frame at
        ``frame_max`` and the states as float64."""
        h, w = self.frame_max
        return len(self.cameras) * h * w * 3 + 8 * (ACTION_DIM + (self.state_dim or 0))

    @property
    def max_message_bytes(self) -> int:
        """The largest legal message: one observation and room for the keys, headers and a
        reset's facts; for a batched policy, ``batch`` observations with their headers."""
        if self.batch:
            return self.batch * (self.observation_bytes + ENTRY_BYTES) + ENVELOPE_BYTES
        return self.observation_bytes + ENVELOPE_BYTES

    @property
    def limits(self) -> Limits:
        if self.batch:  # one more level: the batch's list
            return Limits(bytes=self.max_message_bytes, items=1024 + ENTRY_ITEMS * self.batch,
                          depth=7, text=MAX_TEXT)
        return Limits(bytes=self.max_message_bytes, items=1024, depth=6, text=MAX_TEXT)

    def greeting(self) -> dict[str, Any]:
        return {"obs_type": self.obs_type, "cameras": list(self.cameras),
                "frame_max": list(self.frame_max), "state_dim": self.state_dim,
                "max_message_bytes": self.max_message_bytes, "batch": self.batch,
                "frame_size": list(self.frame_size) if self.frame_size else None}

    def slots_for(self, wanted: int = MAX_SLOTS) -> int:
        """The slots to announce for a batched policy: ``wanted``, fewer where a batch of
        the largest observations would pass ``MAX_BATCH_BYTES``, and at least one."""
        each = self.observation_bytes + ENTRY_BYTES
        return max(1, min(wanted, MAX_SLOTS, (MAX_BATCH_BYTES - ENVELOPE_BYTES) // each))

    def check_slot(self, slot) -> int:
        """A slot index of this connection, or a WireError."""
        if type(slot) is not int or not 0 <= slot < self.batch:
            raise WireError(f"slot must be an integer in [0, {self.batch}), got {slot!r:.40}")
        return slot

    def check_batch(self, batch) -> list[dict[str, Any] | None]:
        """A batch message's list: 1 to ``batch`` entries, each None or an observation that
        ``check_observation`` accepts; else a WireError naming the entry."""
        if not isinstance(batch, list) or not 1 <= len(batch) <= self.batch:
            what = f"{len(batch)} entries" if isinstance(batch, list) else type(batch).__name__
            raise WireError(f"batch must be a list of 1 to {self.batch} entries, got {what}")
        for i, obs in enumerate(batch):
            if obs is None:
                continue
            if not isinstance(obs, dict):
                raise WireError(f"batch entry {i}: an observation must be a map or nil, got "
                                f"{type(obs).__name__}")
            try:
                self.check_observation(obs)
            except WireError as err:
                raise WireError(f"batch entry {i}: {err}") from None
        return batch

    def check_observation(self, msg: dict) -> dict[str, Any]:
        """``msg`` if it holds what the policy reads and nothing else, else a WireError."""
        allowed = {"agent_pos"} | ({"pixels"} if self.cameras else set()) | (
            {"environment_state"} if self.state_dim is not None else set())
        extra = [k for k in msg if k not in allowed]
        if extra:
            raise WireError(f"unexpected entries {sorted(map(str, extra))[:4]}; this policy "
                            f"reads {sorted(allowed)}")
        missing = sorted(allowed - set(msg))
        if missing:
            raise WireError(f"the observation lacks {missing}")
        _vector(msg["agent_pos"], "agent_pos", ACTION_DIM)
        if self.state_dim is not None:
            _vector(msg["environment_state"], "environment_state", self.state_dim)
        if self.cameras:
            pixels = msg["pixels"]
            if not isinstance(pixels, dict) or set(pixels) != set(self.cameras):
                got = sorted(map(str, pixels)) if isinstance(pixels, dict) else type(pixels).__name__
                raise WireError(f"pixels must hold exactly the cameras {list(self.cameras)}, "
                                f"got {got}")
            for cam, frame in pixels.items():
                self._frame(cam, frame)
        return msg

    def _frame(self, cam: str, frame) -> None:
        h, w = self.frame_max
        if (not isinstance(frame, np.ndarray) or frame.dtype != np.uint8 or frame.ndim != 3
                or frame.shape[2] != 3 or not 1 <= frame.shape[0] <= h
                or not 1 <= frame.shape[1] <= w):
            what = (f"{frame.dtype} {frame.shape}" if isinstance(frame, np.ndarray)
                    else type(frame).__name__)
            raise WireError(f"camera {cam!r}: a frame must be uint8 (H, W, 3) within "
                            f"{h}x{w}, got {what}")

    def check_reset(self, msg: dict) -> tuple[str, dict[str, Any]]:
        """(instruction, task facts) of a reset message (its ``reset`` and ``slot`` taken out),
        or a WireError."""
        extra = sorted(str(k)[:40] for k in msg if k not in ("instruction", "task_info"))
        if extra:
            raise WireError(f"unexpected entries {extra[:4]} in a reset; entries: reset, "
                            f"slot, instruction, task_info")
        instruction = msg.get("instruction", "")
        if not isinstance(instruction, str):
            raise WireError("a reset's instruction must be a string")
        info = msg.get("task_info")
        info = {} if info is None else info  # (null, as before, is none)
        if not isinstance(info, dict):
            raise WireError("a reset's task_info must be a map")
        for key, value in info.items():
            kind = TASK_INFO.get(key)
            if kind is None:
                raise WireError(f"unknown task_info entry {str(key)[:40]!r}; entries: "
                                f"{', '.join(TASK_INFO)}")
            if type(value) is not kind:
                raise WireError(f"task_info {key} must be {kind.__name__}, got "
                                f"{type(value).__name__}")
        if "task" in info and info["task"] != self.task:
            raise WireError(f"this server serves {self.task!r}, not {info['task'][:40]!r}")
        gym_id = get_task(self.task).gym_id
        if "gym_id" in info and info["gym_id"] != gym_id:  # (a task version its policy is not for)
            raise WireError(f"this server serves {gym_id}, not {info['gym_id'][:40]}")
        if "seed" in info and not 0 <= info["seed"] < 2**63:
            raise WireError(f"task_info seed must be in [0, 2**63), got {info['seed']}")
        if not all(isinstance(s, str) for s in info.get("subtasks", ())):
            raise WireError("task_info subtasks must be strings")
        return instruction, info


def _vector(value, name: str, length: int) -> None:
    if (not isinstance(value, np.ndarray) or value.dtype.kind != "f" or value.shape != (length,)
            or not np.isfinite(value).all()):
        what = (f"{value.dtype} {value.shape}" if isinstance(value, np.ndarray)
                else type(value).__name__)
        raise WireError(f"{name} must be finite float ({length},), got {what}")
