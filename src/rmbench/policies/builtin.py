"""The built-in policies: the scripted expert (an upper bound, reading privileged state),
random and no-op lower references, and open-loop replay of a dataset's actions (a determinism check)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from rmbench.experts import make_expert
from rmbench.policies.base import BasePolicy
from rmbench.policies.config import argument_ablations, split_argument
from rmbench.policies.registry import register_policy


class ExpertPolicy(BasePolicy):
    def __init__(self, env):
        self.expert = make_expert(env)

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        self.expert.reset(instruction, task_info)

    def act(self, observation):
        return self.expert.act(observation)


class RandomPolicy(BasePolicy):
    """Uniform targets within the joint limits, from a generator seeded by the episode."""

    def __init__(self, env):
        space = env.unwrapped.action_space
        self.low, self.high = space.low.astype(np.float64), space.high.astype(np.float64)
        self.rng = np.random.default_rng(0)

    def reset(self, instruction, task_info):
        self.rng = np.random.default_rng(task_info.get("seed", 0))

    def act(self, observation):
        return self.rng.uniform(self.low, self.high)


class NoopPolicy(BasePolicy):
    """Holds the arms where they are."""

    def act(self, observation):
        return np.asarray(observation["agent_pos"], np.float64).copy()


class ReplayPolicy(BasePolicy):
    """Replays the recorded actions of the dataset episode with the same seed, open-loop, as
    one chunk. Evaluated on the dataset's own seeds (``seeds``), it must succeed on every one:
    the recorded actions reproduce the recorded episode exactly."""

    def __init__(self, root: str, env):
        from rmbench.data.reader import Dataset

        self.ds = Dataset(root)
        task = type(env.unwrapped.task).name
        if self.ds.task != task:
            raise ValueError(f"replay dataset {root} holds {self.ds.task!r}, not {task!r}")
        # The first episode of each seed: a dataset of layout copies holds each seed several
        # times, the recorded episode first and then its copies (data/layout_copies.py).
        self.by_seed: dict[int, int] = {}
        for e, row in enumerate(self.ds.episodes):
            self.by_seed.setdefault(int(row["rmbench/seed"]), e)
        self.seeds = list(self.by_seed)
        # read now, so that a damaged dataset stops the evaluation (a DatasetError) instead of
        # being recorded as the policy failing its episodes
        self.recorded = {seed: self.ds.episode(e, cameras=[]).action.astype(np.float64)
                         for seed, e in self.by_seed.items()}
        self._actions: np.ndarray | None = None

    def reset(self, instruction, task_info):
        seed = task_info.get("seed")
        if seed not in self.recorded:
            raise ValueError(f"the replay dataset has no episode with seed {seed}")
        self._actions = self.recorded[seed]

    def act(self, observation):
        if self._actions is None:
            raise RuntimeError("the recorded actions are used up")
        chunk, self._actions = self._actions, None
        return chunk


register_policy("expert", "the scripted expert (reads privileged simulator state)",
                cameras=(), reads_simulator=lambda arg: True)(lambda arg, env: ExpertPolicy(env))
register_policy("random", "uniform random joint targets", cameras=())(
    lambda arg, env: RandomPolicy(env))
register_policy("noop", "hold the current joint positions", cameras=())(
    lambda arg, env: NoopPolicy())
register_policy("replay", "replay a dataset's recorded actions on its own seeds",
                needs_argument=True, cameras=())(lambda arg, env: ReplayPolicy(arg, env))


def _checkpoint_describe(arg: str | None) -> dict[str, Any]:
    """A learned policy's checkpoint description (``CKPT[?options]``'s config.json), read
    without importing torch; {} if unreadable: building the policy then says what is wrong."""
    try:
        describe = json.loads((Path(split_argument(arg)[0]) / "config.json").read_text())
    except (OSError, ValueError, TypeError):
        return {}
    return describe if isinstance(describe, dict) else {}


def _checkpoint_config(arg: str | None) -> dict[str, Any] | None:
    """The policy config in a learned policy's checkpoint; None if unreadable."""
    config = _checkpoint_describe(arg).get("config")
    return config if isinstance(config, dict) else None


def checkpoint_frame_size(arg: str | None) -> tuple[int, int] | None:
    """The (width, height) a learned policy's camera frames were rendered at in training (its
    dataset's resolution), which its evaluation renders at; None where the checkpoint does
    not say (trained before it was recorded: the env's default, 320x240, as every table's)."""
    dataset = _checkpoint_describe(arg).get("dataset")
    text = dataset.get("resolution") if isinstance(dataset, dict) else None
    try:
        width, height = (int(v) for v in text.split("x"))
    except (AttributeError, ValueError):
        return None
    return width, height


def checkpoint_check(policy: str, config: str, extra: tuple[str, ...] = ()):
    """A learned policy's ``check``: its checkpoint's config.json is there, readable and of
    that policy (``checkpoint.read_config``'s one-line errors), and its options
    (``CKPT?name=value``) are the policy's: ``extra`` and the inference fields of its
    ``config`` class (a module path), with values it reads."""
    def check(arg: str | None) -> None:
        from importlib import import_module

        from rmbench.policies.checkpoint import read_config
        from rmbench.policies.config import parse_argument

        read_config(split_argument(arg)[0], policy)
        module, name = config.rsplit(".", 1)
        parse_argument(arg or "", getattr(import_module(module), name), extra)

    return check


def checkpoint_observation(arg: str | None) -> str | None:
    """What a learned policy's checkpoint (``CKPT[?options]``) reads: "state" or "pixels" (a
    config from before the field existed read pixels); None if its config is unreadable."""
    config = _checkpoint_config(arg)
    return None if config is None else config.get("observation", "pixels")


def checkpoint_obs_type(arg: str | None) -> str:
    """The env observation a learned policy's checkpoint reads: the state observation for one
    trained with observation "state", else pixels (an unreadable checkpoint too)."""
    state = checkpoint_observation(arg) == "state"
    # rmbench.make's obs_type values (rmbench.envs.env.OBS_TYPES)
    return "environment_state_agent_pos" if state else "pixels_agent_pos"


def checkpoint_cameras(arg: str | None) -> tuple[str, ...] | None:
    """The cameras a learned policy's checkpoint reads: none for one trained on the state,
    else those of its config (None, the default three, where it names none or is unreadable:
    the config's own default)."""
    config = _checkpoint_config(arg) or {}
    if config.get("observation") == "state":
        return ()
    cameras = config.get("cameras")
    return tuple(cameras) if isinstance(cameras, list | tuple) and cameras else None


def _mem0(arg, env):
    from rmbench.policies.mem0.agent import Mem0Policy  # torch only when asked for

    return Mem0Policy(arg, env)


def _mem0_reads_simulator(arg: str | None) -> bool:
    """gt_classifier takes the subtask boundary from the simulator, not the observation."""
    return "gt_classifier" in argument_ablations(arg)


register_policy("mem0", ("Mem-0 from a checkpoint: mem0:CKPT[?ablation=A,...&F=V...], F one of execute, "
                 "flow_steps, sample_noise, temporal_ensemble, ensemble_every, event_phases, "
                 "codec_frames"),
                needs_argument=True, obs_type=checkpoint_obs_type, cameras=checkpoint_cameras,
                frame_size=checkpoint_frame_size,
                reads_simulator=_mem0_reads_simulator,
                check=checkpoint_check("mem0", "rmbench.policies.mem0.config.Mem0Config",
                                       ("ablation",)))(_mem0)


def _dp(arg, env):
    from rmbench.policies.dp.agent import DPPolicy

    return DPPolicy(arg, env)


def _act(arg, env):
    from rmbench.policies.act.agent import ACTPolicy

    return ACTPolicy(arg, env)


register_policy("dp", "Diffusion Policy from a checkpoint: dp:CKPT[?execute=N&ddim_steps=N]",
                needs_argument=True, obs_type=checkpoint_obs_type, cameras=checkpoint_cameras,
                frame_size=checkpoint_frame_size,
                check=checkpoint_check("dp", "rmbench.policies.dp.config.DPConfig"))(_dp)
register_policy("act", ("ACT from a checkpoint: "
                "act:CKPT[?temporal_ensemble=M&execute=N&ensemble_window=K]"),
                needs_argument=True, obs_type=checkpoint_obs_type, cameras=checkpoint_cameras,
                frame_size=checkpoint_frame_size,
                check=checkpoint_check("act", "rmbench.policies.act.config.ACTConfig"))(_act)
