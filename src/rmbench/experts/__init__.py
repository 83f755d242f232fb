"""Scripted experts, one per task, on shared motion primitives."""

from rmbench.experts import (  # noqa: F401  (registers)
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
from rmbench.experts.base import EXPERTS, ScriptedExpert, make_expert

__all__ = ["EXPERTS", "ScriptedExpert", "make_expert"]
