"""The policy interface, shared by the scripted experts, the built-in policies and learned ones.

A policy is reset with the episode's instruction and task facts, then asked for actions:
``act(observation)`` returns one 14-d action or a chunk (k, 14) that the caller executes in
order before asking again. ``cameras`` says which camera images it reads (none: the
environment may skip rendering). A policy may also report ``status()``, a dict of what it
currently believes (a Mem-0's subtask), which evaluation records whenever it changes.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Policy(Protocol):
    """What evaluation calls: ``reset`` once per episode, then ``act`` at each 20 Hz control
    step, or after the chunk it returned last has been executed."""

    cameras: tuple[str, ...]

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        """A new episode: its instruction and the task's facts (name, TMC, subtasks, seed)."""

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """The env's observation in; one 14-d action, or a chunk (k, 14) executed in order."""


class BasePolicy:
    """Convenience base: no cameras, nothing to reset or close."""

    cameras: ClassVar[tuple[str, ...]] = ()

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        pass

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        raise NotImplementedError

    def status(self) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        pass
