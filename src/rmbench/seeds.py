"""Which seeds are for training and which for evaluation.

Evaluation seed ``s`` uses episodes from ``100000 * (1 + s)`` upward; demonstrations are drawn
from ``[0, 100000)``, so no evaluation episode can appear in a training set.
"""

from __future__ import annotations

EVAL_SEED_STRIDE = 100_000
TRAIN_SEED_END = EVAL_SEED_STRIDE  # training seeds lie in [0, TRAIN_SEED_END)


def eval_seed_start(seed: int) -> int:
    """First episode seed of evaluation seed ``seed``."""
    if seed < 0:
        raise ValueError(f"evaluation seed must be >= 0, got {seed}")
    return EVAL_SEED_STRIDE * (1 + seed)


def check_training_seed(seed: int) -> int:
    if not 0 <= seed < TRAIN_SEED_END:
        raise ValueError(f"training seed {seed} is outside [0, {TRAIN_SEED_END}): seeds from "
                         f"{TRAIN_SEED_END} up are evaluation episodes")
    return seed
