"""Output folders that a re-run continues (datasets, evaluations) remember the arguments that
define them; a re-run must ask for the same ones."""

from __future__ import annotations

from typing import Any


def differences(saved: dict[str, Any], asked: dict[str, Any]) -> str:
    """``""`` when the arguments match, else e.g. ``"seed 0 there, 7 asked"``; a nested
    field is named by its path (``"describe.config.ema False there, True asked"``)."""
    return ", ".join(_differences(saved, asked, ""))


def _differences(saved: dict[str, Any], asked: dict[str, Any], prefix: str) -> list[str]:
    out = []
    for k in sorted(set(saved) | set(asked)):
        a, b = saved.get(k), asked.get(k)
        if isinstance(a, dict) and isinstance(b, dict):
            out += _differences(a, b, f"{prefix}{k}.")
        elif a != b:
            out.append(f"{prefix}{k} {a!r} there, {b!r} asked")
    return out
