"""Policy specs: ``NAME`` or ``NAME:ARGUMENT`` (``expert``, ``replay:DIR``, ``remote:ws://...``)
mapped to factories. New policies register here and every command that takes ``--policy``
can run them.

A registration is the one place that says what a policy reads: ``obs_type`` (the observation)
and ``cameras`` (the images; ``()``: none, so its env renders nothing), each fixed or computed
from the argument (a checkpoint's config.json). The env is built from them before the policy
(``env_options``), and a policy server announces them to its clients; the policy object
carries no camera list of its own (``make_policy`` refuses one that disagrees).

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
# the cameras whose images the policy reads: None = the station's default set, () = none
Cameras = tuple[str, ...] | None
PIXELS_OBS_TYPE = "pixels_agent_pos"  # rmbench.make's default


class UnknownPolicyError(ValueError):
    pass


@dataclass(frozen=True)
class PolicyEntry:
    name: str
    factory: PolicyFactory
    help: str
    needs_argument: bool = False
    # the cameras it reads (None: the station's default set, (): none, nothing is rendered),
    # or a function of its argument giving them (a checkpoint names the ones it was trained on)
    cameras: Cameras | Callable[[str | None], Cameras] = None
    # the observation it reads, from its argument (a checkpoint trained on the state reads
    # "environment_state_agent_pos"); None = pixels_agent_pos
    obs_type: ObsType | None = None
    # from its argument: whether it reads the simulator itself (the expert's privileged state,
    # a Mem-0's ground-truth subtask boundary), which a policy server cannot give it
    reads_simulator: Callable[[str | None], bool] | None = None
    # from its argument: the rmbench.make options, when only the policy can say (a remote
    # policy asks its server); supersedes cameras and obs_type
    env_options: Callable[[str | None], dict[str, Any]] | None = None
    # from its argument: raise a one-line error where the policy cannot be built from it (a
    # checkpoint that is not there), cheaply and before anything runs
    check: Callable[[str | None], None] | None = None
    # from its argument: the (width, height) its cameras must render at (a checkpoint's, the
    # resolution of the frames it trained on), or None for the env's default
    frame_size: Callable[[str | None], tuple[int, int] | None] | None = None


POLICIES: dict[str, PolicyEntry] = {}


def register_policy(name: str, help: str, needs_argument: bool = False,
                    cameras: Cameras | Callable[[str | None], Cameras] = None,
                    obs_type: ObsType | None = None,
                    reads_simulator: Callable[[str | None], bool] | None = None,
                    env_options: Callable[[str | None], dict[str, Any]] | None = None,
                    check: Callable[[str | None], None] | None = None,
                    frame_size: Callable[[str | None], tuple[int, int] | None] | None = None):
    def wrap(factory: PolicyFactory) -> PolicyFactory:
        if name in POLICIES:
            raise ValueError(f"policy {name!r} is already registered")
        fixed = tuple(cameras) if cameras is not None and not callable(cameras) else cameras
        POLICIES[name] = PolicyEntry(name, factory, help, needs_argument, fixed, obs_type,
                                     reads_simulator, env_options, check, frame_size)
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


def check_policy(spec: str) -> None:
    """A one-line error for a spec no policy can be built from: an unknown name, a missing
    argument, or an argument its registration's ``check`` refuses; nothing is built."""
    entry, arg = parse_spec(spec)
    if entry.check is not None:
        entry.check(arg)


def env_options(spec: str) -> dict[str, Any]:
    """``rmbench.make`` options for an env that ``spec`` can act in: the observation it
    declares (``obs_type``) and the cameras it reads; nothing is rendered for a policy that
    reads no camera."""
    entry, arg = parse_spec(spec)
    return _env_options(entry, arg)


def _env_options(entry: PolicyEntry, arg: str | None) -> dict[str, Any]:
    if entry.env_options is not None:
        return entry.env_options(arg)
    obs_type = entry.obs_type(arg) if entry.obs_type is not None else PIXELS_OBS_TYPE
    options: dict[str, Any] = {} if obs_type == PIXELS_OBS_TYPE else {"obs_type": obs_type}
    if not obs_type.startswith("pixels"):
        return options
    cameras = entry.cameras(arg) if callable(entry.cameras) else entry.cameras
    if cameras is not None and not cameras:
        return {**options, "render": False}
    size = entry.frame_size(arg) if entry.frame_size is not None else None
    if size is not None:
        options = {**options, "width": size[0], "height": size[1]}
    return {**options, "cameras": tuple(cameras)} if cameras else options


def _cameras_of(options: dict[str, Any]) -> tuple[str, ...]:
    """The cameras an env made with ``options`` renders into its observations."""
    if options.get("render") is False or not options.get("obs_type", PIXELS_OBS_TYPE).startswith(
            "pixels"):
        return ()
    if options.get("cameras") is not None:
        return tuple(options["cameras"])
    from rmbench.sim.station import DEFAULT_CAMERAS  # the env's default; mujoco on demand

    return tuple(DEFAULT_CAMERAS)


def policy_cameras(spec: str) -> tuple[str, ...]:
    """The cameras whose images the policy ``spec`` reads, as its env renders them (``()``:
    none)."""
    return _cameras_of(env_options(spec))


def registered_policies() -> list[PolicyEntry]:
    """Every registered policy, those of the entry-point group's plugins included."""
    _load_plugins()
    return list(POLICIES.values())


def reads_simulator(spec: str) -> bool:
    """Whether the policy ``spec`` names reads the simulator beyond its observation."""
    entry, arg = parse_spec(spec)
    return entry.reads_simulator is not None and entry.reads_simulator(arg)


def make_policy(spec: str, env) -> Policy:
    """The policy named by ``spec``, for episodes of ``env`` (the expert reads its state).

    What a policy reads is its registration's to say, since the env is built before the
    policy: an object that still carries a ``cameras`` attribute disagreeing with it (a
    class attribute ``cameras = ()`` beside a registration that renders the default cameras)
    is refused rather than left to render what it never reads."""
    entry, arg = parse_spec(spec)
    policy = entry.factory(arg, env)
    carried = getattr(policy, "cameras", None)
    if carried is not None:
        registered = _cameras_of(_env_options(entry, arg))
        if set(carried) != set(registered):
            getattr(policy, "close", lambda: None)()
            raise ValueError(
                f"policy {entry.name!r} carries cameras={tuple(carried)!r} but is registered to "
                f"read {registered!r}: say what it reads in register_policy({entry.name!r}, "
                f"cameras=...) and drop the attribute")
    return policy


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
