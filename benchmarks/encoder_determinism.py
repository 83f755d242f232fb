"""Encoder determinism: the same frames, encoded again and again in one process, must give the
same MP4 bytes whatever the process did in between. Compares x264's MB-tree rate control (on,
x264's default) with the dataset codec (off), and MB-tree with x264's AVX-512 code switched off.

    .venv/bin/python benchmarks/encoder_determinism.py [--reps 400]

The frames are a small dataset's (observe_and_pickup seeds 0-2, head and left_wrist at 64x48),
encoded as collection does: both cameras' encoders open side by side, frames added alternately,
with the heap stirred between episodes. Prints, per setting, how many distinct MP4s each video
gave. Measured on 2 cores of an AVX-512 Xeon, 400 repetitions (about a minute): MB-tree with
AVX-512 gave 4 distinct MP4s for seed 0's head video and 2 for seed 1's; without AVX-512, or with
MB-tree off, one for every video.
"""

from __future__ import annotations

import argparse
import hashlib
from collections import Counter, defaultdict
from dataclasses import replace

import numpy as np

import rmbench  # noqa: F401  (before anything imports mujoco: it picks the OpenGL backend)
import rmbench.data.record as record
from rmbench.data.layout import Spec
from rmbench.video import DATASET_CODEC, Mp4Encoder, VideoCodec

CAMERAS = ("head", "left_wrist")
# x264's CPU flags on an AVX-512 machine less AVX-512 (an explicit list overrides detection;
# on a CPU without some of these, x264 would use instructions it lacks).
NO_AVX512 = "MMX2,SSE,SSE2,SSE2Fast,SSSE3,SSE4.1,SSE4.2,LZCNT,AVX,FMA3,BMI1,BMI2,AVX2"


class Encoder(Mp4Encoder):
    """The dataset encoder, optionally with x264's CPU flags set, keeping its frames."""

    def __init__(self, *args, asm: str = "", **kw):
        super().__init__(*args, **kw)
        self.asm, self.raw = asm, []

    def options(self) -> dict[str, str]:
        opts = super().options()
        if self.asm:
            opts["x264-params"] += f":asm={self.asm}"
        return opts

    def add(self, frame: np.ndarray) -> None:
        self.raw.append(frame)
        super().add(frame)


def recorded_frames(seeds: range) -> dict[tuple[int, str], np.ndarray]:
    """The frames ``rmbench collect`` encodes for ``seeds``, from its own Recorder."""
    made: list[Encoder] = []

    def keep(*args, **kw) -> Encoder:
        made.append(Encoder(*args, **kw))
        return made[-1]

    record.Mp4Encoder = keep
    try:
        rec = record.Recorder("observe_and_pickup", Spec(CAMERAS, 64, 48))
        out = {}
        for seed in seeds:
            made.clear()
            if not rec.record(seed).success:
                raise RuntimeError(f"the expert failed seed {seed}")
            out.update({(seed, cam): np.stack(enc.raw) for cam, enc in zip(CAMERAS, made, strict=True)})
        rec.close()
        return out
    finally:
        record.Mp4Encoder = Mp4Encoder


def encode_episode(frames: dict, seed: int, codec: VideoCodec, asm: str) -> dict[str, str]:
    encoders = {cam: Encoder(codec=codec, asm=asm) for cam in CAMERAS}
    for k in range(len(frames[(seed, CAMERAS[0])])):
        for cam, enc in encoders.items():
            enc.add(frames[(seed, cam)][k])
    return {cam: hashlib.sha1(enc.finish()).hexdigest()[:10] for cam, enc in encoders.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=400)
    args = ap.parse_args()
    frames = recorded_frames(range(3))
    settings = {"MB-tree on, AVX-512": (replace(DATASET_CODEC, mbtree=True), ""),
                "MB-tree on, no AVX-512": (replace(DATASET_CODEC, mbtree=True), NO_AVX512),
                "MB-tree off (dataset codec)": (DATASET_CODEC, "")}
    rng = np.random.default_rng(0)
    print(f"{args.reps} repetitions of 6 videos per setting")
    for name, (codec, asm) in settings.items():
        seen: dict[str, Counter] = defaultdict(Counter)
        for _ in range(args.reps):
            for seed in range(3):
                stir = [rng.random(int(n)) for n in rng.integers(10, 20000, 40)]
                del stir[::2]  # leave holes of many sizes in the heap
                for cam, digest in encode_episode(frames, seed, codec, asm).items():
                    seen[f"{seed}/{cam}"][digest] += 1
        print(f"{name:28s} distinct MP4s per video: {dict(sorted((k, len(v)) for k, v in seen.items()))}")


if __name__ == "__main__":
    main()
