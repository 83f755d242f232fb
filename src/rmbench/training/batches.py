"""Batch streams for the training loop, as functions of the step so that a resumed run sees
the batches an uninterrupted one would."""

from __future__ import annotations

from collections.abc import Iterator

import torch
from torch.utils.data import DataLoader, Dataset, Sampler
from torch.utils.data._utils.collate import default_collate


class _From(Sampler[list[int]]):
    """A batch sampler's epoch ``epoch``, from its ``skip``-th batch."""

    def __init__(self, sampler, epoch: int, skip: int):
        self.sampler, self.epoch, self.skip = sampler, epoch, skip

    def __iter__(self):
        self.sampler.set_epoch(self.epoch)
        for i, batch in enumerate(self.sampler):
            if i >= self.skip:
                yield batch

    def __len__(self) -> int:
        return len(self.sampler) - self.skip


def batch_stream(dataset: Dataset, sampler, start: int, workers: int = 0
                 ) -> Iterator[dict[str, torch.Tensor]]:
    """Batches of ``sampler`` (a batch sampler with ``set_epoch``) epoch after epoch, starting
    at global batch ``start``."""
    per_epoch = len(sampler)
    if per_epoch == 0:
        raise ValueError("the dataset is smaller than one batch")
    epoch, skip = divmod(start, per_epoch)
    while True:
        loader = DataLoader(dataset, batch_sampler=_From(sampler, epoch, skip), num_workers=workers,
                            collate_fn=default_collate, persistent_workers=False)
        yield from loader
        epoch, skip = epoch + 1, 0
