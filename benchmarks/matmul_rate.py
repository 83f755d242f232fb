"""This machine's float32 matrix-multiply rate, per torch thread count: the yardstick of every
training wall in the tables (a training step is mostly matmuls), so walls measured on two
machines can be set side by side.

    .venv/bin/python benchmarks/matmul_rate.py [--size 1024] [--rounds 5]
        [--out benchmarks/results/matmul_rate.json]

A (size x size) @ (size x size) product, timed over 20 products a round; each thread count's
figure is its best round, in GFLOP/s (2 size^3 per product). A second thread that adds
little means the cores share what a training uses (hyperthreads, or a shared host core):
two jobs side by side then each run at about half speed.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import torch

from rmbench.files import write_json
from rmbench.machine import describe, usable_cores

ROOT = Path(__file__).resolve().parents[1]
PRODUCTS = 20


def rate(size: int, threads: int, rounds: int) -> float:
    torch.set_num_threads(threads)
    a, b = torch.randn(size, size), torch.randn(size, size)
    for _ in range(3):
        a @ b
    best = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        for _ in range(PRODUCTS):
            a @ b
        best = min(best, (time.perf_counter() - start) / PRODUCTS)
    return 2 * size ** 3 / best / 1e9


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "matmul_rate.json")
    args = ap.parse_args()
    threads = list(range(1, usable_cores() + 1))
    gflops = {n: round(rate(args.size, n, args.rounds), 1) for n in threads}
    report = {"size": args.size, "rounds": args.rounds, "products_per_round": PRODUCTS,
              "gflops": {str(n): g for n, g in gflops.items()},
              "scaling": round(gflops[threads[-1]] / gflops[1], 2), "torch": torch.__version__,
              "machine": describe()}
    write_json(args.out, report, indent=2)
    print(f"float32 matmul, {args.size}x{args.size}:\n| torch threads | GFLOP/s |\n|---|---|")
    for n, g in gflops.items():
        print(f"| {n} | {g:.1f} |")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
