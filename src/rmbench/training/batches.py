"""Batch streams for the training loop, as functions of the step so that a resumed run sees
the batches an uninterrupted one would."""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch.utils.data import DataLoader, Dataset
from torch.utils.data._utils.collate import default_collate


class _Stream:
    """A batch sampler's endless ``stream(start)`` as a DataLoader batch sampler."""

    def __init__(self, sampler, start: int):
        self.sampler, self.start = sampler, start

    def __iter__(self):
        return self.sampler.stream(self.start)


def batch_stream(dataset: Dataset, sampler, start: int, workers: int = 0
                 ) -> Iterator[dict[str, torch.Tensor]]:
    """Batches of ``sampler`` (anything with ``stream(start)``) from global batch ``start``."""
    # A DataLoader draws its workers' base seed from the global RNG unless given a generator.
    # A resumed run builds its loader after restoring that RNG, so the draw would shift every
    # later global draw (dropout) against an uninterrupted run: the loader gets its own.
    loader = DataLoader(dataset, batch_sampler=_Stream(sampler, start), num_workers=workers,
                        collate_fn=default_collate, generator=torch.Generator().manual_seed(0))
    return iter(loader)
