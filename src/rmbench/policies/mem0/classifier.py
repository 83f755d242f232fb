"""The subtask-end rule: a subtask ends after L consecutive steps the classifier calls
positive (one noisy positive does not end it); training labels the last L frames of each
subtask positive, so at run time the count reaches L as the subtask finishes."""

from __future__ import annotations

import numpy as np


class Debounce:
    def __init__(self, window: int):
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        self.window = window
        self.count = 0

    def reset(self) -> None:
        self.count = 0

    def update(self, positive: bool) -> bool:
        """Feed one step; True on the step that completes L consecutive positives."""
        self.count = self.count + 1 if positive else 0
        if self.count >= self.window:
            self.count = 0
            return True
        return False


def end_labels(subtask_step: np.ndarray, window: int) -> np.ndarray:
    """(T,) bool: frame t is within the last ``window`` frames of its plan step."""
    n = len(subtask_step)
    to_end = np.zeros(n, dtype=np.int64)
    for t in range(n - 2, -1, -1):
        to_end[t] = to_end[t + 1] + 1 if subtask_step[t] == subtask_step[t + 1] else 0
    return to_end < window
