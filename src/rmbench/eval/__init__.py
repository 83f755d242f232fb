"""The evaluation harness: expert-verified seeds, policy episodes, records, resume."""

from rmbench.eval.harness import EvalConfig, evaluate
from rmbench.eval.records import EvalError

__all__ = ["EvalConfig", "EvalError", "evaluate"]
