"""An episode's events: the steps at which the task's discrete facts and the policy's own
status changed, kept in the episode's record.

An ending says how an episode failed; its events say where the failure began. On
blocks_ranking_try, a Mem-0 whose subtask turns to a swap with no press recorded before it
has trusted a false subtask end. Only discrete values are followed (a float such as a lift
height changes every step), and an episode keeps at most ``LIMIT`` events; past it, each
value's last change is still kept (so the stage an episode ended in stays known), then the
number of changes left out as the last entry.
"""

from __future__ import annotations

from typing import Any

import numpy as np

LIMIT = 400


def plain(value: Any) -> Any:
    """``value`` as JSON writes it: numpy scalars and arrays, tuples and nested lists made plain;
    TypeError for anything JSON has no value for (a set, a tensor, a path), here, where the
    value is reported, rather than when the episode's record is written."""
    if isinstance(value, np.ndarray):
        return plain(value.tolist())
    if isinstance(value, np.generic):
        return plain(value.item())
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise TypeError(f"{type(value).__name__} is not a JSON value: {value!r:.80}")


class Events:
    """``[step, source, key, value]`` for each change of a followed value; ``step`` is the
    number of environment steps taken when the change was seen."""

    def __init__(self, limit: int = LIMIT):
        self.limit = limit
        self.items: list[list] = []
        self.left_out = 0
        self._last: dict[tuple[str, str], list] = {}  # each value's last change, kept or not
        self._kept: dict[tuple[str, str], Any] = {}

    def update(self, step: int, source: str, values: dict[str, Any]) -> None:
        for key, value in values.items():
            value = plain(value)
            if isinstance(value, float):
                continue
            if (source, key) in self._last and self._last[source, key][3] == value:
                continue
            self._last[source, key] = [step, source, key, value]
            if len(self.items) < self.limit:
                self.items.append([step, source, key, value])
                self._kept[source, key] = value
            else:
                self.left_out += 1

    def to_list(self) -> list[list]:
        if not self.left_out:
            return list(self.items)
        last = [event for k, event in self._last.items()
                if k not in self._kept or self._kept[k] != event[3]]
        return self.items + sorted(last, key=lambda e: e[0]) + [
            [None, "events", "left_out", self.left_out]]


def capped(record: dict[str, Any]) -> bool:
    """Whether an episode's events passed ``LIMIT``: the changes between the limit and each
    fact's last value are not kept, so counts read from its events have gaps."""
    return any(e[1:3] == ["events", "left_out"] for e in record.get("events", []))
