"""Named randomisation ranges.

Each task declares the ranges it draws from as constants at the top of its file, with their
units, and its docstring's "Randomization" paragraph quotes them as ``U[low, high]``;
tests/test_randomization.py checks that the paragraph and the constants agree, so the two cannot
drift apart. Choices among a few discrete options (which mat, which order) stay
``rng.integers`` draws beside the code that uses them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Uniform:
    """U[low, high]. ``draw`` is ``rng.uniform(low, high, size)``: the same numbers, from the same
    generator state, as that call written out, so naming a range changes no episode."""

    low: float
    high: float

    def __post_init__(self):
        if not self.low < self.high:
            raise ValueError(f"a uniform range needs low < high, got [{self.low}, {self.high}]")

    def draw(self, rng: np.random.Generator, size: int | None = None):
        """One float (``size`` None) or an array of ``size`` draws."""
        return rng.uniform(self.low, self.high, size)

    def __contains__(self, value: float) -> bool:
        return self.low <= value <= self.high

    def __str__(self) -> str:
        return f"U[{self.low:g}, {self.high:g}]"
