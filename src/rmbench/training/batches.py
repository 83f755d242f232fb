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
    # A dataset with ``batch(indices)`` gathers and collates a batch's items in one call
    # (DemoDataset: one numpy gather instead of an item at a time); the loader then hands it
    # each batch's indices as one index.
    if hasattr(dataset, "batch"):
        loader = DataLoader(Batched(dataset), sampler=_Stream(sampler, start), batch_size=None,
                            num_workers=workers, collate_fn=collated,
                            generator=torch.Generator().manual_seed(0))
    else:
        loader = DataLoader(dataset, batch_sampler=_Stream(sampler, start), num_workers=workers,
                            collate_fn=default_collate, generator=torch.Generator().manual_seed(0))
    return iter(loader)


class Batched(Dataset):
    """A dataset with ``batch(indices)``, indexed by a whole batch's indices at once."""

    def __init__(self, dataset):
        self.dataset = dataset

    def __getitem__(self, indices: list[int]) -> dict[str, torch.Tensor]:
        return self.dataset.batch(indices)


def collated(batch: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The loader's collate function for ``Batched``: its batches come collated."""
    return batch
