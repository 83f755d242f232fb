"""The base every learned policy's settings derive from: a frozen dataclass stored as JSON in
each checkpoint. JSON has no tuples, so lists read back from a checkpoint (or given as
``--set field=[...]``) become tuples again here, keeping configs hashable and equal to the
ones that were saved."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any


@dataclass(frozen=True)
class PolicyConfig:
    def __post_init__(self):
        for f in fields(self):
            if isinstance(getattr(self, f.name), list):
                object.__setattr__(self, f.name, tuple(getattr(self, f.name)))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]):
        """The config from a checkpoint's JSON; a field this version does not know is an
        error rather than silently dropped, since it would change what the weights mean."""
        unknown = set(raw) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"unknown {cls.__name__} fields {sorted(unknown)}")
        return cls(**raw)
