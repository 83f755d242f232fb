"""Output folders that a re-run continues (datasets, evaluations) remember the arguments that
define them; a re-run must ask for the same ones."""

from __future__ import annotations

from typing import Any


def differences(saved: dict[str, Any], asked: dict[str, Any]) -> str:
    """``""`` when the arguments match, else e.g. ``"seed 0 there, 7 asked"``."""
    keys = [k for k in sorted(set(saved) | set(asked)) if saved.get(k) != asked.get(k)]
    return ", ".join(f"{k} {saved.get(k)!r} there, {asked.get(k)!r} asked" for k in keys)
