"""docs/tasks/<task>.png: the head camera at the first frame and at the aliasing point.

    .venv/bin/python scripts/make_task_pictures.py [--seed 100000] [--out docs/tasks]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image

import rmbench
from rmbench.experts import make_expert

SETTLE = 15  # steps after the aliasing stage is reached, so the arm has moved off


def aliasing_frames(task: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    env = rmbench.make(task, cameras=("head",))
    expert = make_expert(env)
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    first = obs["pixels"]["head"]
    stage = env.unwrapped.task.aliasing_stage
    reached = None
    for step in range(env.unwrapped.step_limit):
        obs, _, terminated, truncated, info = env.step(expert.act(obs))
        if reached is None and info["subtask_step"] >= stage:
            reached = step
        if (reached is not None and step >= reached + SETTLE) or terminated or truncated:
            break
    env.close()
    return first, obs["pixels"]["head"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=100000)
    parser.add_argument("--out", default="docs/tasks")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in sorted(rmbench.TASKS):
        first, alias = aliasing_frames(name, args.seed)
        gap = np.full((first.shape[0], 6, 3), 255, np.uint8)
        Image.fromarray(np.concatenate([first, gap, alias], axis=1)).save(out / f"{name}.png")
        print(f"wrote {out / name}.png")


if __name__ == "__main__":
    main()
