"""Policy inference that gives the same numbers in every process: one intra-op thread, no
autograd.

A float reduction split over N threads sums in an order that depends on N, and a closed loop
amplifies the last bit into a different episode: the same put_back_block checkpoint on the
same seed succeeded with two torch threads and timed out with one. Evaluation runs episodes
in parallel across processes, so one thread per episode costs it nothing; the thread count
of the calling process (a training run's, say) is restored on return.
"""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Callable, Iterator
from typing import TypeVar

import torch

from rmbench.training.device import flush_denormals

INFERENCE_THREADS = 1

F = TypeVar("F", bound=Callable)


@contextlib.contextmanager
def intra_op_threads(n: int) -> Iterator[None]:
    """torch's intra-op threads set to ``n`` inside, the caller's restored on exit."""
    threads = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def inference(fn: F) -> F:
    """Run ``fn`` under ``torch.no_grad`` with ``INFERENCE_THREADS`` intra-op threads and
    subnormals read as zero (``training.device.flush_denormals``: as in training, and several
    times faster where activations reach them)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        flush_denormals()  # (left on: torch has no getter for the setting to restore)
        with intra_op_threads(INFERENCE_THREADS), torch.no_grad():
            return fn(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
