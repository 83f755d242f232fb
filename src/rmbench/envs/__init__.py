"""Gymnasium environments and their registration."""

from rmbench.envs.env import RMBenchEnv
from rmbench.envs.registration import make, register_envs

__all__ = ["RMBenchEnv", "make", "register_envs"]
