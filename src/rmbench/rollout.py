"""Running the scripted expert through the env: one episode, or a sweep over seeds."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from rmbench.envs.noise import NoiseSpec, perturber
from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.video import VideoWriter


@dataclass
class EpisodeResult:
    task: str
    seed: int
    success: bool
    steps: int
    progress: float
    reason: str  # "success", the task's failure reason, "timeout", or the error
    wall_s: float
    step_limit: int
    subtask_ends: list[tuple[int, str]] = field(default_factory=list)
    video: str | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def run_episode(env, expert, seed: int, video: str | Path | None = None,
                noise: NoiseSpec | None = None) -> EpisodeResult:
    """One expert episode on ``env`` from ``seed``; optionally a third-person video. With
    ``noise``, the env executes the expert's action plus that noise (the expert is not told)."""
    task = type(env.unwrapped.task)
    t0 = time.perf_counter()
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    perturb = perturber(noise, seed, env)
    writer = VideoWriter(video) if video else None
    ends: list[tuple[int, str]] = []
    steps, progress, reason, success = 0, 0.0, "timeout", False
    try:
        if writer:
            writer.add(env.render())
        subtask = info["subtask"]
        while True:
            try:
                action = expert.act(obs)
            except Exception as err:  # an expert that cannot plan is a result, not a crash
                reason = f"expert error: {err}"
                break
            if expert.gave_up:
                reason = f"expert gave up: {expert.gave_up}"
                break
            if perturb is not None:
                action = perturb(action)
            obs, _, terminated, truncated, info = env.step(action)
            steps += 1
            if writer:
                writer.add(env.render())
            if info.get("subtask_end"):
                ends.append((steps, subtask))
            subtask = info.get("subtask", subtask)
            progress = info.get("progress", progress)
            if terminated or truncated:
                success = bool(info.get("is_success"))
                if success:
                    reason = "success"
                elif info.get("sim_error"):
                    reason = f"sim error: {info['sim_error']}"
                else:
                    reason = info.get("failure_reason") or "timeout"
                break
    finally:
        if writer:
            writer.close()
    return EpisodeResult(task.name, seed, success, steps, progress, reason,
                         round(time.perf_counter() - t0, 3), env.unwrapped.step_limit, ends,
                         str(video) if video else None)


def run_expert(task: str, seeds, *, render: bool = False, video_dir: str | Path | None = None,
               videos: int = 1, on_result=None, noise: NoiseSpec | None = None
               ) -> list[EpisodeResult]:
    """The expert on ``task`` for each seed (under ``noise``, if given); videos of the first
    ``videos`` seeds."""
    env = make(task, render=render)  # videos use the third-person camera either way
    expert = make_expert(env)
    results = []
    try:
        for i, seed in enumerate(seeds):
            video = (Path(video_dir) / f"{task}_seed{seed}.mp4"
                     if video_dir is not None and i < videos else None)
            result = run_episode(env, expert, seed, video, noise)
            results.append(result)
            if on_result:
                on_result(result)
    finally:
        env.close()
    return results
