"""Action noise on the arm-joint targets: how a learner's imprecision is simulated.

Three kinds, all in radians on the 12 arm-joint targets (grippers untouched):

- ``white``: an independent N(0, sigma) draw every control step (shaky, rough).
- ``smooth``: an Ornstein-Uhlenbeck process with stationary std ``sigma`` and time constant
  ``tau`` seconds (a drift that lasts a while: what a learned policy's error mostly looks
  like).
- ``offset``: one N(0, sigma) draw per episode, held (a constant calibration error).

The noise draws from its own generator seeded by the episode seed, so a noisy episode is as
reproducible as a clean one and adding noise does not shift the scene's randomisation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rmbench.sim.simulator import ACTION_DIM, ARM_ENTRIES

NOISE_KINDS = ("white", "smooth", "offset")
_STREAM = 0x6E6F6973  # separates the noise generator from the scene's, for the same seed


@dataclass(frozen=True)
class NoiseSpec:
    """What noise is added to executed actions.

    kind: one of NOISE_KINDS.
    sigma: standard deviation in radians (0 means no noise).
    tau: time constant of the smooth kind, in seconds.
    """

    kind: str = "white"
    sigma: float = 0.0
    tau: float = 0.5

    def __post_init__(self):
        if self.kind not in NOISE_KINDS:
            raise ValueError(f"noise kind must be one of {NOISE_KINDS}, got {self.kind!r}")
        if not (np.isfinite(self.sigma) and self.sigma >= 0):
            raise ValueError(f"noise sigma must be a finite number >= 0, got {self.sigma}")
        if not (np.isfinite(self.tau) and self.tau > 0):
            raise ValueError(f"noise tau must be a finite number > 0, got {self.tau}")

    @property
    def active(self) -> bool:
        return self.sigma > 0

    def to_dict(self) -> dict:
        return {"kind": self.kind, "sigma": self.sigma, "tau": self.tau}

    def process(self, seed: int, dt: float) -> ActionNoise:
        """The noise of the episode with scene seed ``seed``, at control period ``dt``."""
        return ActionNoise(self, np.random.default_rng([_STREAM, seed]), dt)


def perturber(noise: NoiseSpec | None, seed: int, env):
    """``action -> action + noise`` for the episode ``seed`` of ``env``, or None without
    noise (callers then execute the action as it is)."""
    if noise is None or not noise.active:
        return None
    return noise.process(seed, 1.0 / env.unwrapped.config.control_hz).perturb


class ActionNoise:
    """One episode's noise sequence: ``next()`` gives the (14,) offset for the next step."""

    def __init__(self, spec: NoiseSpec, rng: np.random.Generator, dt: float):
        self.spec, self.rng = spec, rng
        self.decay = float(np.exp(-dt / spec.tau))
        # Start in the stationary distribution, so the first steps are as noisy as the rest.
        self.state = rng.normal(0.0, spec.sigma, len(ARM_ENTRIES))

    def next(self) -> np.ndarray:
        s, out = self.spec, np.zeros(ACTION_DIM)
        if s.kind == "white":
            out[ARM_ENTRIES] = self.rng.normal(0.0, s.sigma, len(ARM_ENTRIES))
            return out
        if s.kind == "smooth":
            innovation = self.rng.normal(0.0, s.sigma * np.sqrt(1 - self.decay ** 2),
                                         len(ARM_ENTRIES))
            self.state = self.decay * self.state + innovation
        out[ARM_ENTRIES] = self.state  # offset: the first draw, held
        return out

    def perturb(self, action: np.ndarray) -> np.ndarray:
        """``action`` plus the next noise step (a new array)."""
        return np.asarray(action, float) + self.next()
