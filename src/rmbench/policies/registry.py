"""Policy specs: ``NAME`` or ``NAME:ARGUMENT`` (``expert``, ``replay:DIR``, ``remote:ws://...``)
mapped to factories. New policies register here and every command that takes ``--policy``
can run them.

The modules that register policies are named in the ``rmbench.policies`` entry-point group
(pyproject.toml: the built-in policies, and the ``remote:`` client in serve/) and imported on
first use. They import this module, never the other way round, so the registry stays below
every policy, wherever it lives; another installed package can add policies the same way.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib.metadata import EntryPoints, entry_points
from typing import Any

from rmbench.policies.base import Policy

# factory(argument or None, env) -> policy
PolicyFactory = Callable[[str | None, object], Policy]
# argument or None -> the env observation the policy reads (rmbench.make's obs_type)
ObsType = Callable[[str | None], str]
PIXELS_OBS_TYPE = "pixels_agent_pos"  # rmbench.make's default


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
    # the observation it reads, from its argument (a checkpoint trained on the state reads
    # "environment_state_agent_pos"); None = pixels_agent_pos
    obs_type: ObsType | None = None
    # from its argument: whether it reads the simulator itself (the expert's privileged state,
    # a Mem-0's ground-truth subtask boundary), which a policy server cannot give it
    reads_simulator: Callable[[str | None], bool] | None = None
    # from its argument: the rmbench.make options, when only the policy can say (a remote
    # policy asks its server); supersedes cameras and obs_type
    env_options: Callable[[str | None], dict[str, Any]] | None = None


POLICIES: dict[str, PolicyEntry] = {}


def register_policy(name: str, help: str, needs_argument: bool = False,
                    cameras: tuple[str, ...] | None = None, obs_type: ObsType | None = None,
                    reads_simulator: Callable[[str | None], bool] | None = None,
                    env_options: Callable[[str | None], dict[str, Any]] | None = None):
    def wrap(factory: PolicyFactory) -> PolicyFactory:
        if name in POLICIES:
            raise ValueError(f"policy {name!r} is already registered")
        POLICIES[name] = PolicyEntry(name, factory, help, needs_argument, cameras, obs_type,
                                     reads_simulator, env_options)
        return factory

    return wrap


def parse_spec(spec: str) -> tuple[PolicyEntry, str | None]:
    _load_plugins()
    name, sep, arg = spec.partition(":")
    if name not in POLICIES:
        hint = "" if _plugins() else (f" (no {ENTRY_POINT_GROUP!r} entry points: rmbench's come "
                                      "with its installation, pip install -e .)")
        if _failed:
            hint += " (plugins that failed to import: " + "; ".join(
                f"{k}: {v}" for k, v in _failed.items()) + ")"
        raise UnknownPolicyError(f"unknown policy {spec!r}; policies: "
                                 + ", ".join(f"{e.name}{':ARG' if e.needs_argument else ''}"
                                             for e in POLICIES.values()) + hint)
    entry = POLICIES[name]
    if entry.needs_argument and not arg:
        raise UnknownPolicyError(f"policy {name!r} needs an argument: {name}:ARG ({entry.help})")
    if not entry.needs_argument and sep:
        raise UnknownPolicyError(f"policy {name!r} takes no argument, got {spec!r}")
    return entry, (arg or None)


def env_options(spec: str) -> dict[str, Any]:
    """``rmbench.make`` options for an env that ``spec`` can act in: the observation it
    declares (``obs_type``) and the cameras it reads; nothing is rendered for a policy that
    reads no camera."""
    entry, arg = parse_spec(spec)
    if entry.env_options is not None:
        return entry.env_options(arg)
    obs_type = entry.obs_type(arg) if entry.obs_type is not None else PIXELS_OBS_TYPE
    if obs_type != PIXELS_OBS_TYPE:
        return {"obs_type": obs_type}
    if entry.cameras == ():
        return {"render": False}
    return {"cameras": entry.cameras} if entry.cameras else {}


def reads_simulator(spec: str) -> bool:
    """Whether the policy ``spec`` names reads the simulator beyond its observation."""
    entry, arg = parse_spec(spec)
    return entry.reads_simulator is not None and entry.reads_simulator(arg)


def make_policy(spec: str, env) -> Policy:
    """The policy named by ``spec``, for episodes of ``env`` (the expert reads its state)."""
    entry, arg = parse_spec(spec)
    return entry.factory(arg, env)


ENTRY_POINT_GROUP = "rmbench.policies"
_loaded = False
_failed: dict[str, str] = {}  # entry-point name -> why its module did not import


def _plugins() -> EntryPoints:
    return entry_points(group=ENTRY_POINT_GROUP)


def _load_plugins() -> None:
    """Imports each module of the entry-point group (registering its policies) once. A module
    that fails to import (another package's broken plugin) is skipped with a warning, so the
    policies of every other one still load; asking for a policy no module registered names
    the ones that failed."""
    global _loaded
    if _loaded:
        return
    for plugin in _plugins():
        try:
            plugin.load()  # an import: a module loaded before is not run (nor registered) again
        except Exception as err:  # noqa: BLE001 - any import-time error of foreign code
            _failed[plugin.name] = f"{plugin.value}: {type(err).__name__}: {err}"
            warnings.warn(f"rmbench policy plugin {plugin.name!r} failed to import "
                          f"({_failed[plugin.name]}); its policies are unavailable",
                          RuntimeWarning, stacklevel=2)
    _loaded = True
