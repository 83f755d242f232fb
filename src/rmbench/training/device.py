"""The devices a training can name, checked without importing torch (a table's plan checks
its ``--device`` before any job starts)."""

from __future__ import annotations


def check_device(device: str) -> None:
    """cpu, cuda or cuda:N; anything else is a one-line ValueError."""
    if device not in ("cpu", "cuda") and not device.startswith("cuda:"):
        raise ValueError(f"device must be cpu, cuda or cuda:N, got {device!r}")
