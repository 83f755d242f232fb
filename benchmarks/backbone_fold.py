"""The frozen EfficientNet-Lite0 as the policies run it (``FoldedLite0``: batch norms folded,
1x1 convolutions as matrix products) against the network as written (``EfficientNetLite0``),
side by side in one run: CPU time per frame to the stride-16 feature map of 96x128 frames (the
camera recipe's), one thread, at the feature cache's batch of 8 and a closed loop's batch of
1, and the largest difference between their features.

    .venv/bin/python benchmarks/backbone_fold.py [--frames 64] [--rounds 3]
        [--out benchmarks/results/backbone_fold.json]

The frames are random pictures (the network's cost does not depend on what they show). The
two sides alternate round after round; each side's figure is its least disturbed round.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.policies.nn.efficientnet import FoldedLite0, load_pretrained

ROOT = Path(__file__).resolve().parents[1]
STRIDE, SIZE = 16, (96, 128)


def per_frame_ms(encode, images: torch.Tensor, batch: int) -> float:
    encode(images[:batch])  # warm
    start = time.process_time()
    for i in range(0, len(images), batch):
        encode(images[i:i + batch])
    return (time.process_time() - start) / len(images) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=64)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "backbone_fold.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = load_pretrained()
    folded = FoldedLite0(model)
    g = torch.Generator().manual_seed(0)
    images = torch.randint(0, 256, (args.frames, 3, *SIZE), dtype=torch.uint8, generator=g)
    sides = {"network": lambda x: model.features(x, STRIDE),
             "folded": lambda x: folded.features(x, STRIDE)}
    ms: dict[str, dict[int, list[float]]] = {s: {8: [], 1: []} for s in sides}
    with torch.no_grad():
        for _ in range(args.rounds):
            for side, encode in sides.items():
                for batch in (8, 1):
                    ms[side][batch].append(per_frame_ms(encode, images, batch))
        gap = float((sides["network"](images[:8]) - sides["folded"](images[:8])).abs().max())
        scale = float(sides["network"](images[:8]).abs().max())
    best = {s: {b: min(v) for b, v in per.items()} for s, per in ms.items()}
    report = {"stride": STRIDE, "image_size": list(SIZE), "frames": args.frames,
              "rounds": args.rounds, "threads": 1,
              "cpu_ms_per_frame": {s: {f"batch{b}": round(v, 3) for b, v in per.items()}
                                   for s, per in best.items()},
              "speedup": {f"batch{b}": round(best["network"][b] / best["folded"][b], 3)
                          for b in (8, 1)},
              "max_abs_difference": gap, "max_abs_feature": scale, "machine": describe()}
    write_json(args.out, report, indent=2)
    for b in (8, 1):
        print(f"batch {b}: network {best['network'][b]:.2f} ms/frame, folded "
              f"{best['folded'][b]:.2f} ({report['speedup'][f'batch{b}']:.2f}x)")
    print(f"largest difference {gap:.2e} (features up to {scale:.1f}); wrote {args.out}")


if __name__ == "__main__":
    main()
