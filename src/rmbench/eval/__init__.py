"""The evaluation harness: expert-verified seeds, policy episodes, records, resume."""

from rmbench.eval.harness import EvalConfig, EvalError, evaluate

__all__ = ["EvalConfig", "EvalError", "evaluate"]
