"""Temporal ensembling of action chunks (ACT, Zhao et al. 2023): every stored chunk that covers
the current step (or, with a window, every one predicted in its last steps) votes for its
action, the oldest weighted most (exp(-m i), i = 0 the oldest).

Averaging the overlapping predictions smooths the switch from one chunk to the next, where a
policy that runs each chunk open-loop jumps; with m > 0 a fresh chunk moves the action only
gradually, so one poor prediction cannot swing the arm.
"""

from __future__ import annotations

import numpy as np


class TemporalEnsemble:
    """``window``: only the chunks predicted in the last ``window`` steps vote (0: every chunk
    still covering the step, ``horizon`` steps back). How far back the votes reach is how much
    of its own past the policy acts on, a memory of that many steps."""

    def __init__(self, horizon: int, m: float, window: int = 0):
        if horizon < 1 or m < 0 or not 0 <= window <= horizon:
            raise ValueError(f"temporal ensembling needs horizon >= 1, m >= 0 and a window of "
                             f"0 (the horizon) to horizon steps, got {horizon}, {m} and {window}")
        self.horizon, self.m, self.window = horizon, m, window or horizon
        self.chunks: list[tuple[int, np.ndarray]] = []  # (step predicted at, chunk), oldest first

    def reset(self) -> None:
        self.chunks = []

    def add(self, t: int, chunk: np.ndarray) -> None:
        """Store the chunk predicted at step ``t`` (its first action is step t's)."""
        if len(chunk) != self.horizon:
            raise ValueError(f"chunk of {len(chunk)} actions, expected {self.horizon}")
        self.chunks.append((t, chunk))

    def action(self, t: int) -> np.ndarray:
        """The weighted mean of the action for step ``t`` of every stored chunk predicted in
        the window; older chunks are dropped."""
        self.chunks = [(t0, c) for t0, c in self.chunks if 0 <= t - t0 < self.window]
        if not self.chunks:
            raise RuntimeError(f"no stored chunk covers step {t}")
        predictions = np.stack([c[t - t0] for t0, c in self.chunks])
        weights = np.exp(-self.m * np.arange(len(predictions)))
        return (weights / weights.sum()) @ predictions
