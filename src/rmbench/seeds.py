"""Which seeds are for training, which for choosing a recipe and which for reporting.

Evaluation seed ``s`` owns the episodes from ``100000 * (1 + s)`` to ``100000 * (2 + s)``:
its test episodes are the first half, the ones a table reports; its validation episodes the
second half, where recipes are chosen and compared, so no reported number was tuned on its
own episodes. Demonstrations are drawn from ``[0, 100000)``, so no evaluation episode can
appear in a training set.
"""

from __future__ import annotations

EVAL_SEED_STRIDE = 100_000
TRAIN_SEED_END = EVAL_SEED_STRIDE  # training seeds lie in [0, TRAIN_SEED_END)
SPLITS = ("test", "validation")
SPLIT_STRIDE = EVAL_SEED_STRIDE // 2  # candidate seeds per split of an evaluation seed


def eval_seed_start(seed: int, split: str = "test") -> int:
    """First episode seed of evaluation seed ``seed``'s ``split``."""
    if seed < 0:
        raise ValueError(f"evaluation seed must be >= 0, got {seed}")
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; splits: {', '.join(SPLITS)}")
    return EVAL_SEED_STRIDE * (1 + seed) + SPLIT_STRIDE * SPLITS.index(split)


def check_training_seed(seed: int) -> int:
    if not 0 <= seed < TRAIN_SEED_END:
        raise ValueError(f"training seed {seed} is outside [0, {TRAIN_SEED_END}): seeds from "
                         f"{TRAIN_SEED_END} up are evaluation episodes")
    return seed
