"""rmbench: memory-dependent dual-arm manipulation tasks on MuJoCo."""

from rmbench import sim as _sim  # noqa: F401  (selects the OpenGL backend before mujoco loads)

__version__ = "0.1.0"
