"""The memory probe: the same episodes with the policy's memory wiped mid-episode.

``--memory-reset aliasing`` calls the policy's ``reset`` once, right after the environment
step at which the task's ground-truth stage first reaches ``Task.aliasing_stage`` (the point
after which only the past tells the right next move apart, ``Task.aliasing_pairs``);
``--memory-reset every:K`` calls it after every K-th step. Whatever the policy carries is
lost there: its own state through ``reset`` (the episode's instruction and task facts are
handed again, as at the start) and the actions of a chunk it returned earlier and had not
been executed yet. Everything else is the episode without the probe: the seed, the layout,
the env, the policy's weights. A policy without memory (its action a function of the
current observation) runs every probed episode exactly as it ran it without the probe; a
policy whose score comes from memory falls towards its memoryless level.

In an evaluation folder each probe is a second arm beside the ordinary one, on the same
seeds: ``<task>/episodes.jsonl`` without it, ``<task>/memory_reset-<name>.jsonl`` with it
(``every:50`` is named ``every-50``); the summary holds both rates and their difference.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

from rmbench.eval.intervals import ci95, paired_difference


@dataclass(frozen=True)
class MemoryReset:
    """When to wipe the policy's memory: at the aliasing moment (``every`` None) or after every
    ``every`` steps."""

    spec: str
    every: int | None = None

    @classmethod
    def parse(cls, spec: str) -> MemoryReset:
        if spec == "aliasing":
            return cls(spec)
        m = re.fullmatch(r"every:(\d+)", spec)
        if not m or int(m.group(1)) < 1:
            raise ValueError(f"memory reset must be 'aliasing' or 'every:K' with K >= 1, got "
                             f"{spec!r}")
        return cls(spec, int(m.group(1)))

    @property
    def name(self) -> str:
        """The arm's name in file names: ``aliasing``, ``every-K``."""
        return self.spec.replace(":", "-")

    def trigger(self, aliasing_stage: int) -> ResetTrigger:
        return ResetTrigger(self.every, aliasing_stage)


class ResetTrigger:
    """One episode's trigger: ``due(step, info)`` after each env step (``step`` steps taken,
    ``info`` that step's), true where the policy is to be reset."""

    def __init__(self, every: int | None, aliasing_stage: int):
        self.every, self.stage, self.fired = every, aliasing_stage, False

    def due(self, step: int, info: dict[str, Any]) -> bool:
        if self.every is not None:
            return step % self.every == 0
        # the stage is monotone within an episode: the first step that reaches it, once
        if not self.fired and info.get("subtask_step", -1) >= self.stage:
            self.fired = True
            return True
        return False


def arm_file(name: str) -> str:
    return f"memory_reset-{name}.jsonl"


def arm_name(filename: str) -> str | None:
    """The probe's name of an arm file, None for any other file."""
    m = re.fullmatch(r"memory_reset-(.+)\.jsonl", filename)
    return m.group(1) if m else None


def compare(plain: list[dict], probed: list[dict]) -> dict[str, Any]:
    """Rates with and without the probe on the seeds both arms ran, with their 95% intervals,
    the difference (without minus with) and its paired interval (each seed runs both ways, so
    the outcomes are pairs: Newcombe's paired interval, narrower than the independent one
    where the probe leaves most outcomes as they were), and how many probed episodes reached
    a reset at all (an episode that ends before the aliasing moment is never probed)."""
    by_seed = {r["seed"]: r for r in plain}
    pairs = [(by_seed[r["seed"]], r) for r in probed if r["seed"] in by_seed]
    n = len(pairs)
    if n == 0:
        return {"episodes": 0}
    k0 = sum(a["success"] for a, _ in pairs)
    k1 = sum(b["success"] for _, b in pairs)
    lost = sum(a["success"] and not b["success"] for a, b in pairs)
    gained = sum(b["success"] and not a["success"] for a, b in pairs)
    d, low, high = paired_difference(k0 - lost, lost, gained, n)
    return {"episodes": n, "reset_episodes": sum(bool(b.get("memory_resets")) for _, b in pairs),
            "without": {"successes": k0, "success_rate": round(k0 / n, 4),
                        "success_ci95": ci95(k0, n)},
            "with": {"successes": k1, "success_rate": round(k1 / n, 4),
                     "success_ci95": ci95(k1, n),
                     "mean_progress": round(sum(b["progress"] for _, b in pairs) / n, 4)},
            "drop": round(d, 4), "drop_ci95": [round(low, 4), round(high, 4)],
            "outside_noise": low > 0 or high < 0,
            # the same seeds on both arms: episodes whose outcome the probe changed
            "changed": {"lost": lost, "gained": gained}}
