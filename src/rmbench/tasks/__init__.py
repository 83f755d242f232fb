"""Tasks: one file per task, registered by name and gym id."""

from rmbench.tasks import (  # noqa: F401  (registers)
    battery_try,
    blocks_ranking_try,
    cover_blocks,
    observe_and_pickup,
    press_button,
    put_back_block,
    rearrange_blocks,
    swap_blocks,
    swap_t,
)
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.registry import TASKS, UnknownTaskError, get_task

__all__ = ["TASKS", "Evaluation", "Task", "UnknownTaskError", "get_task"]
