"""docs/tasks/<task>.png: the head camera at the first frame, then the task's two aliasing
moments (``Task.aliasing_pairs[0]``): alike to the camera, different next actions.

    .venv/bin/python scripts/make_task_pictures.py [--seed 100000] [--out docs/tasks]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image

import rmbench
from rmbench.aliasing import capture


def first_frame(task: str, seed: int) -> np.ndarray:
    env = rmbench.make(task, cameras=("head",))
    obs, _ = env.reset(seed=seed)
    env.close()
    return obs["pixels"]["head"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=100000)
    parser.add_argument("--out", default="docs/tasks")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, cls in sorted(rmbench.TASKS.items()):
        frames = [first_frame(name, args.seed)]
        frames += [capture(name, args.seed, *m).frame for m in cls.aliasing_pairs[0]]
        gap = np.full((frames[0].shape[0], 6, 3), 255, np.uint8)
        row = [frames[0], gap, frames[1], gap, frames[2]]
        Image.fromarray(np.concatenate(row, axis=1)).save(out / f"{name}.png")
        print(f"wrote {out / name}.png")


if __name__ == "__main__":
    main()
