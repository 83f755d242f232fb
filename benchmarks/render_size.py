"""What rendering the camera recipe's frames smaller would save, and what it would move.

The camera recipe's layout copies (``rmbench dataset copy-layouts``) render every frame of
every copy at the collection's 320x240, encode it (the dataset codec), and the feature cache
then decodes and resizes it to 96x128 for the frozen backbone; in closed loop the policy reads
the env's 320x240 frames resized the same way, never encoded. Rendering and reading the
pixels back are most of a copy's time (a profile of one put_back_block copy: 69%, encoding
17%). This renders an expert episode's frames at each ``--sizes`` through the renderer the
copies use, and measures per camera:

- CPU ms a camera image to render (scene update, draw, read back) and to encode;
- the training features' distance from what the closed loop reads (||a - b|| / ||b|| over a
  frame's stride-16 EfficientNet-Lite0 map, mean over frames): the frames rendered at the
  size, encoded, decoded and resized, against the 320x240 frames resized without a codec;
- beside it, two distances a policy must tell apart: the same view five steps later (one
  stride of Mem-0's sliding memory) and the same step of another layout.

    .venv/bin/python benchmarks/render_size.py [--task put_back_block] [--seeds 0 1]
        [--steps 400] [--sizes 320x240 160x120 128x96] [--out benchmarks/results/render_size.json]

A size's distance at or below 320x240's (the codec's own gap, what the recipe trains with
now) says its frames would train on features as close to the closed loop's as today's; it
does not say a policy would score the same, which only a trained cell says.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch

# the features and their distance exactly as codec_gap.py measures the codec's gap (run as a
# script, this folder is on the path)
from codec_gap import BACKBONE, LAG, SIZE, STRIDE, features, relative

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.video import Mp4Encoder, decode_video

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = "320x240"  # the collection's resolution: what the env renders in closed loop


def parse(size: str) -> tuple[int, int]:
    w, h = (int(v) for v in size.split("x"))
    return w, h


def episode(task: str, seed: int, steps: int, sizes: list[str]):
    """Each size's frames {camera: (T, h, w, 3)} of the expert's episode and its CPU seconds
    rendering {size: s}, every frame drawn by each size's renderer from the same state."""
    env = make(task)
    expert = make_expert(env)
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    sim = env.unwrapped.sim
    cameras = list(obs["pixels"])
    renderers = {s: sim.renderer(*parse(s)) for s in sizes}
    frames = {s: {c: [] for c in cameras} for s in sizes}
    cpu = dict.fromkeys(sizes, 0.0)
    for _ in range(steps):
        for s, r in renderers.items():
            start = time.process_time()
            for cam in cameras:
                r.update_scene(sim.data, camera=cam)
                frames[s][cam].append(r.render())
            cpu[s] += time.process_time() - start
        obs, _, terminated, truncated, _ = env.step(expert.act(obs))
        if terminated or truncated:
            break
    env.close()
    return {s: {c: np.stack(v) for c, v in per.items()} for s, per in frames.items()}, cpu


def coded(frames: np.ndarray) -> tuple[np.ndarray, float]:
    """The frames through the dataset codec, and the CPU seconds encoding took."""
    encoder = Mp4Encoder(fps=20)
    start = time.process_time()
    for frame in frames:
        encoder.add(frame)
    data = encoder.finish()
    return decode_video(data), time.process_time() - start


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="put_back_block")
    ap.add_argument("--seeds", type=int, nargs=2, default=[0, 1])
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--sizes", nargs="+", default=[REFERENCE, "160x120", "128x96"])
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "render_size.json")
    args = ap.parse_args()
    if REFERENCE not in args.sizes:
        ap.error(f"--sizes must hold {REFERENCE}, the closed loop's resolution")
    torch.set_num_threads(1)
    one, cpu = episode(args.task, args.seeds[0], args.steps, args.sizes)
    other, _ = episode(args.task, args.seeds[1], args.steps, [REFERENCE])
    n_frames = len(next(iter(one[REFERENCE].values())))
    cameras = list(one[REFERENCE])
    loop = {cam: features(one[REFERENCE][cam]) for cam in cameras}  # what the closed loop reads
    apart = {}  # distances a policy must tell apart, from the closed loop's own frames
    for cam, f in loop.items():
        n = min(n_frames, len(other[REFERENCE][cam]))
        apart[cam] = {f"{LAG}_steps_later": round(relative(f[LAG:], f[:-LAG]), 4),
                      "other_layout": round(relative(features(other[REFERENCE][cam][:n]), f[:n]), 4)}
    rows: dict[str, dict] = {}
    for s in args.sizes:
        per_cam, encode_s = {}, 0.0
        for cam in cameras:
            decoded, seconds = coded(one[s][cam])
            encode_s += seconds
            per_cam[cam] = {"training_vs_closed_loop": round(relative(features(decoded), loop[cam]), 4)}
        images = n_frames * len(cameras)
        rows[s] = {"render_ms_per_image": round(cpu[s] / images * 1e3, 3),
                   "encode_ms_per_image": round(encode_s / images * 1e3, 3),
                   "cameras": per_cam}
    base = rows[REFERENCE]
    for row in rows.values():
        row["render_encode_speedup"] = round(
            (base["render_ms_per_image"] + base["encode_ms_per_image"])
            / (row["render_ms_per_image"] + row["encode_ms_per_image"]), 3)
    report = {"task": args.task, "seeds": args.seeds, "frames": n_frames, "cameras": cameras,
              "feature_size": list(SIZE), "backbone": BACKBONE, "stride": STRIDE,
              "lag_steps": LAG, "threads": 1, "gl_backend": os.environ.get("MUJOCO_GL"),
              "reference": REFERENCE, "sizes": rows, "apart": apart, "machine": describe()}
    write_json(args.out, report, indent=2)
    print(f"{args.task}, seed {args.seeds[0]} ({n_frames} frames, {len(cameras)} cameras, "
          f"MUJOCO_GL={report['gl_backend']}); CPU ms "
          f"a camera image, and the training features' relative distance from the closed loop's:")
    print("| rendered at | render | encode | speed-up | " + " | ".join(cameras)
          + " |\n|---|---|---|---|" + "---|" * len(cameras))
    for s, row in rows.items():
        gaps = " | ".join(f"{row['cameras'][c]['training_vs_closed_loop']:.3f}" for c in cameras)
        print(f"| {s} | {row['render_ms_per_image']:.2f} | {row['encode_ms_per_image']:.2f} | "
              f"{row['render_encode_speedup']:.2f}x | {gaps} |")
    for key in (f"{LAG}_steps_later", "other_layout"):
        print(f"| ({key.replace('_', ' ')}) | | | | "
              + " | ".join(f"{apart[c][key]:.3f}" for c in cameras) + " |")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
