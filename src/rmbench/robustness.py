"""How the scripted expert holds up under action noise: success and failure reasons per sigma.

A learned policy is imprecise; a task whose expert fails under small noise fails the learner
for the wrong reason. ``sweep`` runs the expert on consecutive seeds with each noise level
(see :mod:`rmbench.envs.noise`), in parallel, and counts how the episodes end.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from rmbench.envs.noise import NoiseSpec
from rmbench.parallel import in_order, make_executor
from rmbench.rollout import EpisodeResult, run_expert
from rmbench.tasks import get_task

CHUNK = 10  # seeds per job: one env build serves them


@dataclass
class SigmaResult:
    """The expert's episodes at one noise level."""

    noise: NoiseSpec
    episodes: list[EpisodeResult] = field(default_factory=list)

    @property
    def successes(self) -> int:
        return sum(r.success for r in self.episodes)

    @property
    def success_rate(self) -> float:
        return self.successes / max(len(self.episodes), 1)

    @property
    def raised(self) -> int:
        """Episodes where the expert crashed (a defect), as opposed to giving up with a reason."""
        return sum(r.reason.startswith("expert error") for r in self.episodes)

    def reasons(self) -> Counter:
        """Failure reasons, with the varying part (positions, counts) kept."""
        return Counter(r.reason for r in self.episodes if not r.success)

    def to_dict(self) -> dict:
        return {**self.noise.to_dict(), "episodes": len(self.episodes),
                "successes": self.successes, "success_rate": self.success_rate,
                "expert_raised": self.raised, "failures": dict(self.reasons().most_common()),
                "longest_success_steps": max((r.steps for r in self.episodes if r.success),
                                             default=0),
                "step_limit": self.episodes[0].step_limit if self.episodes else 0,
                "failed_seeds": [r.seed for r in self.episodes if not r.success]}


def _run_chunk(task: str, seeds: list[int], noise: NoiseSpec) -> list[EpisodeResult]:
    return run_expert(task, seeds, noise=noise)


def sweep(task: str, sigmas: Sequence[float], *, kind: str = "white", tau: float = 0.5,
          episodes: int = 100, seed: int = 100_000, workers: int = 1, backend: str = "local",
          on_chunk: Callable[[NoiseSpec, list[EpisodeResult]], None] | None = None
          ) -> list[SigmaResult]:
    """The expert on seeds ``seed .. seed + episodes - 1`` at each sigma of one noise kind."""
    task = get_task(task).name
    specs = [NoiseSpec(kind, float(s), tau) for s in sigmas]
    if episodes < 1:
        raise ValueError(f"episodes must be at least 1, got {episodes}")
    results = [SigmaResult(s) for s in specs]
    jobs = [(k, list(range(start, min(start + CHUNK, seed + episodes))))
            for k in range(len(specs)) for start in range(seed, seed + episodes, CHUNK)]
    executor = make_executor(workers, backend)
    try:
        # results in submission order, whatever the worker count
        for k, chunk in in_order(executor, ((k, _run_chunk, (task, seeds, specs[k]))
                                            for k, seeds in jobs)):
            results[k].episodes.extend(chunk)
            if on_chunk:
                on_chunk(specs[k], chunk)
    finally:
        executor.shutdown()
    return results
