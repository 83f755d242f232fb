"""The policy interface, shared by the scripted experts, the built-in policies and learned ones.

A policy is reset with the episode's instruction and task facts, then asked for actions:
``act(observation)`` returns one 14-d action or a chunk (k, 14) that the caller executes in
order before asking again. A policy may also report ``status()``, a dict of what it
currently believes (a Mem-0's subtask), which evaluation records whenever it changes.

The batched form, optional: a policy that can play several episodes side by side has
``act_batch``, and evaluation then asks it once per step for all of them
(``eval/episode.py``), which spreads a network's per-call cost over the batch. Episodes live
in numbered slots 0..B-1:

- ``reset_batch(slot, instruction, task_info, env)``: a new episode in ``slot`` (as
  ``reset``); ``env`` is that slot's environment, for a policy that reads the simulator.
- ``act_batch(observations)``: a list of B entries, slot i's observation or None where slot
  i has nothing to ask (its episode is over, or its last chunk is not used up); returns a
  list of B answers, each as ``act``'s (None for a None). The list always has B entries, so
  a policy can run its network on a fixed number of rows whatever is asked. An exception
  ends every episode that was asked; a bad answer (NaN, a wrong shape) only its own.
- ``status_batch(slot)``, optional: ``status()`` of that slot's episode.
- ``max_batch``, optional: the most slots ``act_batch`` takes (a policy server's announced
  slots); an evaluation asking more stops with a one-line error before its first episode.

A policy that cannot be reached (``PolicyUnavailable``: its server is down, or not a policy
server) stops the evaluation instead of ending episodes it never played: a re-run resumes there.

A slot's episode must not depend on the other slots' (what the evaluation records of a seed
would otherwise depend on its neighbours). A policy without ``act_batch`` is played one
episode at a time through ``reset`` and ``act``; one with it still answers those.

What it reads (the observation type, the camera images) is not said here but where it is
registered, ``register_policy(..., cameras=..., obs_type=...)``: its env is built from that
before the policy exists, and ``cameras=()`` renders nothing (policies/registry.py).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


class PolicyUnavailable(ConnectionError):
    """The policy cannot be reached at all (its server refused or is not one): nothing about
    the episode, which evaluation therefore does not record."""


@runtime_checkable
class Policy(Protocol):
    """What evaluation calls: ``reset`` once per episode, then ``act`` at each 20 Hz control
    step, or after the chunk it returned last has been executed."""

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        """A new episode: its instruction and the task's facts (name, TMC, subtasks, seed)."""

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """The env's observation in; one 14-d action, or a chunk (k, 14) executed in order."""


@runtime_checkable
class BatchPolicy(Policy, Protocol):
    """The batched form (the module's docstring): several episodes side by side, in slots."""

    def reset_batch(self, slot: int, instruction: str, task_info: dict[str, Any],
                    env: Any = None) -> None:
        """A new episode in ``slot``: as ``reset``, with the slot's environment."""

    def act_batch(self, observations: list[dict[str, Any] | None]) -> list[np.ndarray | None]:
        """One entry per slot: its observation or None; one answer per slot (None for None)."""


class BasePolicy:
    """Convenience base: nothing to reset or close, no status."""

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        pass

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        raise NotImplementedError

    def status(self) -> dict[str, Any]:
        return {}

    def close(self) -> None:
        pass
