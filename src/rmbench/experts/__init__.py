"""Scripted experts, one per task, on shared motion primitives."""

from rmbench.experts import press_button, put_back_block  # noqa: F401  (registers)
from rmbench.experts.base import EXPERTS, ScriptedExpert, make_expert

__all__ = ["EXPERTS", "ScriptedExpert", "make_expert"]
