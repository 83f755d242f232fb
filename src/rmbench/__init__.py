"""rmbench: memory-dependent dual-arm manipulation tasks on MuJoCo."""

from rmbench import sim as _sim  # noqa: F401  (selects the OpenGL backend before mujoco loads)
from rmbench import source as _source  # noqa: F401  (the source as imported, for workers' check)
from rmbench.envs import RMBenchEnv, make, register_envs
from rmbench.tasks import TASKS, get_task

register_envs()

__version__ = "0.1.0"
__all__ = ["TASKS", "RMBenchEnv", "get_task", "make", "register_envs"]
