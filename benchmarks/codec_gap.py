"""How far the camera recipe's training features are from the ones its evaluation reads.

A camera policy trains on features cached from the dataset's frames, which are H.264 videos
(the dataset codec: CRF 23, yuv420p), decoded and resized to 96x128; in closed loop it reads
the features of the frames as the env renders them, never encoded. This measures that gap on
an expert episode, camera by camera, against two distances a policy must tell apart: the same
view five steps later (one stride of Mem-0's sliding memory) and the same step of another
layout.

    .venv/bin/python benchmarks/codec_gap.py [--task put_back_block] [--seeds 0 1]
        [--steps 500] [--out benchmarks/results/codec_gap.json]

Distances are relative: ||a - b|| / ||b|| over a frame's stride-16 feature map, averaged over
the episode's frames (of the first seed; the second gives the other layout).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.data.torch_dataset import resize
from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.policies.nn.backbone import backbone_features
from rmbench.video import Mp4Encoder, decode_video

ROOT = Path(__file__).resolve().parents[1]
SIZE, STRIDE, BACKBONE = (96, 128), 16, "efficientnet_lite0"
LAG = 5  # steps: one stride of Mem-0's sliding memory


def expert_frames(task: str, seed: int, steps: int) -> dict[str, np.ndarray]:
    """Each camera's frames (T, 240, 320, 3) of the expert's episode, as the env renders them."""
    env = make(task)
    expert = make_expert(env)
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    frames: dict[str, list[np.ndarray]] = {c: [] for c in obs["pixels"]}
    for _ in range(steps):
        for cam, frame in obs["pixels"].items():
            frames[cam].append(frame.copy())
        obs, _, terminated, truncated, _ = env.step(expert.act(obs))
        if terminated or truncated:
            break
    env.close()
    return {c: np.stack(v) for c, v in frames.items()}


def features(frames: np.ndarray) -> torch.Tensor:
    images = torch.from_numpy(resize(frames, SIZE)).permute(0, 3, 1, 2)
    return torch.cat([backbone_features(BACKBONE, STRIDE, images[i:i + 8])
                      for i in range(0, len(images), 8)]).flatten(1)


def relative(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(((a - b).norm(dim=1) / b.norm(dim=1)).mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--task", default="put_back_block")
    ap.add_argument("--seeds", type=int, nargs=2, default=[0, 1])
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "codec_gap.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    one, other = (expert_frames(args.task, s, args.steps) for s in args.seeds)
    cameras = {}
    for cam, raw in one.items():
        encoder = Mp4Encoder(fps=20)  # the dataset codec, as a collection records
        for frame in raw:
            encoder.add(frame)
        decoded = decode_video(encoder.finish())
        f_raw, f_dec = features(raw), features(decoded)
        n = min(len(raw), len(other[cam]))
        f_other = features(other[cam][:n])
        pixel = np.abs(resize(decoded, SIZE).astype(float) - resize(raw, SIZE).astype(float))
        cameras[cam] = {"pixel_error": round(float(pixel.mean()), 3),
                        "codec": round(relative(f_dec, f_raw), 4),
                        f"{LAG}_steps_later": round(relative(f_raw[LAG:], f_raw[:-LAG]), 4),
                        "other_layout": round(relative(f_other, f_raw[:n]), 4)}
    report = {"task": args.task, "seeds": args.seeds, "frames": int(len(next(iter(one.values())))),
              "size": list(SIZE), "backbone": BACKBONE, "stride": STRIDE, "lag_steps": LAG,
              "cameras": cameras, "machine": describe()}
    write_json(args.out, report, indent=2)
    print(f"{args.task}, seed {args.seeds[0]} ({report['frames']} frames); relative feature "
          f"distance, mean over frames:")
    print(f"| camera | pixel error (0-255) after resize | codec vs raw | raw, {LAG} steps later "
          "| raw, another layout |\n|---|---|---|---|---|")
    for cam, row in cameras.items():
        print(f"| {cam} | {row['pixel_error']:.2f} | {row['codec']:.3f} | "
              f"{row[f'{LAG}_steps_later']:.3f} | {row['other_layout']:.3f} |")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
