"""The base every learned policy's settings derive from: a frozen dataclass stored as JSON in
each checkpoint. JSON has no tuples, so lists read back from a checkpoint (or given as
``--set field=[...]``) become tuples again here, keeping configs hashable and equal to the
ones that were saved. Also the ``POLICY:CKPT?option=value`` argument every learned policy
takes in ``rmbench eval`` and ``rmbench serve``."""

from __future__ import annotations

import functools
import json
import numbers
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any, ClassVar, get_type_hints
from urllib.parse import parse_qsl

import numpy as np

SCALARS = (bool, int, float, str)


@functools.cache
def _scalar_fields(cls: type) -> dict[str, type]:
    """The fields of ``cls`` declared a plain bool, int, float or str."""
    hints = get_type_hints(cls)
    return {f.name: hints[f.name] for f in fields(cls) if hints.get(f.name) in SCALARS}


def _as_type(value: Any, kind: type) -> Any:
    """``value`` as the built-in ``kind`` where it is one (a numpy number too; an integer for
    a float, as JSON writes 0.0 as 0; never a bool for a number), else None."""
    if kind is bool:
        return bool(value) if isinstance(value, bool | np.bool_) else None
    if isinstance(value, bool | np.bool_):
        return None
    if kind is int:
        return int(value) if isinstance(value, numbers.Integral) else None
    if kind is float:
        return float(value) if isinstance(value, numbers.Real) else None
    return str(value) if isinstance(value, str) else None


@dataclass(frozen=True)
class PolicyConfig:
    # fields an evaluation may change without retraining: POLICY:CKPT?execute=4
    INFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ()
    # what a field means where a config was saved before it existed, if not its default
    ABSENT_MEANS: ClassVar[dict[str, Any]] = {}

    def __post_init__(self):
        for f in fields(self):
            if isinstance(getattr(self, f.name), list):
                object.__setattr__(self, f.name, tuple(getattr(self, f.name)))
        # a value of another type (``--set dim=x``, a config edited by hand) said by name,
        # not as whatever a later division or comparison raises
        for name, kind in _scalar_fields(type(self)).items():
            value = getattr(self, name)
            plain = _as_type(value, kind)
            if plain is None:
                raise ValueError(f"{name} must be {kind.__name__}, got {type(value).__name__} "
                                 f"{value!r:.40}")
            object.__setattr__(self, name, plain)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]):
        """The config from a checkpoint's JSON; a field this version does not know is an
        error rather than silently dropped, since it would change what the weights mean."""
        unknown = set(raw) - {f.name for f in fields(cls)}
        if unknown:
            raise ValueError(f"unknown {cls.__name__} fields {sorted(unknown)}")
        return cls(**{**cls.ABSENT_MEANS, **raw})

    @classmethod
    def saved_defaults(cls) -> dict[str, Any]:
        """Each field's value where a saved config lacks it, as ``from_dict`` reads it: what
        a resume compares a run saved before the field existed with."""
        return {**cls().to_dict(), **cls.ABSENT_MEANS}


def parse_overrides(config_cls: type[PolicyConfig], items: list[str]) -> dict[str, Any]:
    """``--set FIELD=VALUE`` items as config keyword arguments (VALUE as JSON, else a bare
    string); a field ``config_cls`` does not have is a ValueError listing those it has."""
    names = {f.name for f in fields(config_cls)}
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set takes FIELD=VALUE, got {item!r}")
        if key not in names:
            raise ValueError(f"unknown config field {key!r}; fields: {', '.join(sorted(names))}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value  # a bare string
    return out


def split_argument(arg: str | None) -> tuple[str, str]:
    """``CKPT[?option=value&...]`` as its checkpoint folder and its options' query text."""
    path, _, query = (arg or "").partition("?")
    return path, query


def argument_ablations(arg: str | None) -> tuple[str, ...]:
    """The ablations ``CKPT?ablation=A,B`` names, in order (none where it names none)."""
    query = dict(parse_qsl(split_argument(arg)[1]))
    return tuple(a for a in query.get("ablation", "").split(",") if a)


def split_policy(spec: str) -> tuple[str, str, str]:
    """``POLICY[:CKPT[?option=value&...]]`` as the policy's name, its checkpoint folder and its
    options' query text ("" where a part is absent)."""
    name, _, arg = spec.partition(":")
    return (name, *split_argument(arg))


def parse_argument(arg: str, config_cls: type[PolicyConfig], extra: tuple[str, ...] = ()
                   ) -> tuple[Path, dict[str, Any], dict[str, str]]:
    """``CKPT[?option=value&...]``: the checkpoint folder, the config overrides (the class's
    ``INFERENCE_FIELDS``, values as JSON) and the policy's own ``extra`` options (raw text)."""
    path, query = split_argument(arg)
    known = tuple(extra) + tuple(config_cls.INFERENCE_FIELDS)
    overrides: dict[str, Any] = {}
    options: dict[str, str] = {}
    for key, value in parse_qsl(query, keep_blank_values=True):  # ("?execute" said, not dropped)
        if key not in known:
            raise ValueError(f"unknown option {key!r}; options: {', '.join(known)}")
        if key in extra:
            options[key] = value
            continue
        try:
            overrides[key] = json.loads(value)
        except json.JSONDecodeError:
            raise ValueError(f"option {key}={value!r} is not a number or JSON value") from None
    return Path(path), overrides, options
