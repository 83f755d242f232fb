"""Policy specs: ``NAME`` or ``NAME:ARGUMENT`` (``expert``, ``replay:DIR``, ``remote:ws://...``)
mapped to factories. New policies register here and every command that takes ``--policy``
can run them."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from rmbench.policies.base import Policy

# factory(argument or None, env) -> policy
PolicyFactory = Callable[[str | None, object], Policy]


class UnknownPolicyError(ValueError):
    pass


@dataclass(frozen=True)
class PolicyEntry:
    name: str
    factory: PolicyFactory
    help: str
    needs_argument: bool = False
    # cameras the policy reads: None = the station's default set, () = none (no rendering)
    cameras: tuple[str, ...] | None = None


POLICIES: dict[str, PolicyEntry] = {}


def register_policy(name: str, help: str, needs_argument: bool = False,
                    cameras: tuple[str, ...] | None = None):
    def wrap(factory: PolicyFactory) -> PolicyFactory:
        if name in POLICIES:
            raise ValueError(f"policy {name!r} is already registered")
        POLICIES[name] = PolicyEntry(name, factory, help, needs_argument, cameras)
        return factory

    return wrap


def parse_spec(spec: str) -> tuple[PolicyEntry, str | None]:
    _load_builtin()
    name, sep, arg = spec.partition(":")
    if name not in POLICIES:
        raise UnknownPolicyError(f"unknown policy {spec!r}; policies: "
                                 + ", ".join(f"{e.name}{':ARG' if e.needs_argument else ''}"
                                             for e in POLICIES.values()))
    entry = POLICIES[name]
    if entry.needs_argument and not arg:
        raise UnknownPolicyError(f"policy {name!r} needs an argument: {name}:ARG ({entry.help})")
    if not entry.needs_argument and sep:
        raise UnknownPolicyError(f"policy {name!r} takes no argument, got {spec!r}")
    return entry, (arg or None)


def make_policy(spec: str, env) -> Policy:
    """The policy named by ``spec``, for episodes of ``env`` (the expert reads its state)."""
    entry, arg = parse_spec(spec)
    return entry.factory(arg, env)


def _load_builtin() -> None:
    from rmbench.policies import builtin  # noqa: F401  (registers)
    from rmbench.serve import client  # noqa: F401  (registers remote:)
