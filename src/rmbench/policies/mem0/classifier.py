"""The subtask-end rule and the classifier's labels: a subtask ends after L consecutive steps
the classifier calls positive (one noisy positive does not end it). The "context" classifier's
positives are the last L frames of each subtask, so the count reaches L as it finishes; the
"event" classifier's are the frames just after each step ends, so the count reaches L that
many frames after the end it detects."""

from __future__ import annotations

import numpy as np


class Debounce:
    """L consecutive positives declare an end; one unbroken run of positives declares one.

    After an end the run must break (one negative step) before the count starts again, so a
    classifier that stays positive past its span (the policy lingering on a finished push, a
    state the demonstrations never held) cannot declare the same end twice. ``reset`` (a new
    episode) re-arms it."""

    def __init__(self, window: int):
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        self.window = window
        self.count = 0
        self.armed = True

    def reset(self) -> None:
        self.count = 0
        self.armed = True

    def update(self, positive: bool) -> bool:
        """Feed one step; True on the step that completes L consecutive positives of a run
        that has not declared an end yet."""
        if not positive:
            self.count, self.armed = 0, True
            return False
        if not self.armed:
            return False
        self.count += 1
        if self.count >= self.window:
            self.count, self.armed = 0, False
            return True
        return False


def end_labels(subtask_step: np.ndarray, window: int) -> np.ndarray:
    """(T,) bool: frame t is within the last ``window`` frames of its plan step."""
    n = len(subtask_step)
    to_end = np.zeros(n, dtype=np.int64)
    for t in range(n - 2, -1, -1):
        to_end[t] = to_end[t + 1] + 1 if subtask_step[t] == subtask_step[t + 1] else 0
    return to_end < window


def event_labels(subtask_step: np.ndarray, span: int) -> np.ndarray:
    """(T,) bool: frame t is one of the first ``span`` frames after a plan step ended (the
    frames from the next step's first on, whose observations show the end happened)."""
    step = np.asarray(subtask_step)
    since = np.full(len(step), span, dtype=np.int64)  # frames since the last end, capped
    for t in range(1, len(step)):
        since[t] = 0 if step[t] != step[t - 1] else min(since[t - 1] + 1, span)
    return since < span
