"""What the feature cache does to a recorded camera before the backbone: decode the episode's
MP4 and resize its frames to the camera recipe's 96x128. Side by side in one run, the way it
is done now (``decode_video`` filling one array, ``resize`` 32 frames a pass) against the way
it was done before (a list of frames stacked at the end, the whole episode resized in one
float pass): CPU time per frame, one thread, and whether both give the same bytes.

    .venv/bin/python benchmarks/frame_prep.py [--task battery_try] [--rounds 3]
        [--out benchmarks/results/frame_prep.json]

The episode is one expert demonstration recorded as a collection records it (320x240, the
dataset codec). The two sides alternate round after round; each figure is its least disturbed
round.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import av
import numpy as np
import torch
import torch.nn.functional as F

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.data import CollectConfig, collect
from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import resize
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.video import decode_video

ROOT = Path(__file__).resolve().parents[1]
SIZE = (96, 128)


def decode_stacked(path: Path) -> np.ndarray:
    """Before: every frame into a list, then one np.stack."""
    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(stream)]
    return np.stack(frames)


def resize_whole(frames: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Before: the episode as one float tensor, resized in one pass."""
    x = torch.from_numpy(np.ascontiguousarray(frames)).permute(0, 3, 1, 2).float()
    y = F.interpolate(x, size=size, mode="bilinear", antialias=True, align_corners=False)
    return y.round().clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()


def cpu_ms(fn, *args) -> tuple[float, np.ndarray]:
    start = time.process_time()
    out = fn(*args)
    return (time.process_time() - start) * 1e3, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="battery_try")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "frame_prep.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as d:
        root = Path(d) / "demo"
        collect(CollectConfig(args.task, root, episodes=1, seed=0, cameras=("head",),
                              width=320, height=240, progress=False))
        ds = Dataset(root)
        video = ds.video_path("head", 0)
        sides = {"before": (decode_stacked, resize_whole), "now": (decode_video, resize)}
        ms = {s: {"decode": [], "resize": []} for s in sides}
        made: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for _ in range(args.rounds):
            for side, (decode, shrink) in sides.items():
                t_dec, frames = cpu_ms(decode, video)
                t_res, small = cpu_ms(shrink, frames, SIZE)
                ms[side]["decode"].append(t_dec / len(frames))
                ms[side]["resize"].append(t_res / len(frames))
                made[side] = (frames, small)
    best = {s: {k: min(v) for k, v in per.items()} for s, per in ms.items()}
    for per in best.values():
        per["both"] = per["decode"] + per["resize"]
    same = {k: bool(np.array_equal(made["before"][i], made["now"][i]))
            for i, k in enumerate(("decode", "resize"))}
    report = {"task": args.task, "frames": int(len(made["now"][0])),
              "source": "320x240", "size": list(SIZE), "rounds": args.rounds, "threads": 1,
              "cpu_ms_per_frame": {s: {k: round(v, 3) for k, v in per.items()}
                                   for s, per in best.items()},
              "speedup": {k: round(best["before"][k] / best["now"][k], 3)
                          for k in ("decode", "resize", "both")},
              "identical": same, "machine": describe()}
    write_json(args.out, report, indent=2)
    print(f"{report['frames']} frames, CPU ms a frame (one thread):")
    print("| step | before | now | speed-up | same bytes |\n|---|---|---|---|---|")
    for k in ("decode", "resize", "both"):
        print(f"| {k} | {best['before'][k]:.2f} | {best['now'][k]:.2f} | "
              f"{report['speedup'][k]:.2f}x | {same.get(k, all(same.values()))} |")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
