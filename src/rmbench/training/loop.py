"""The training loop every learned policy uses.

A policy's trainable model implements ``forward(batch) -> (loss, logs)``, ``param_groups()``
(named groups with their own learning rates), and optionally ``extra_state()`` /
``load_extra_state()`` for what training carries besides weights (Mem-0's per-episode memory
store) and ``after_step()`` (EMA). AdamW, cosine schedule with linear warm-up per group down to
the group's minimum, gradient-norm clipping.

Resume: ``OUT/training/state.pt`` holds weights, optimiser, RNG and extra state, written
atomically; it is the commit point. A re-run with the same arguments continues from it and,
batches being a function of the step, gives the weights an uninterrupted run gives.
``OUT/model.safetensors`` + ``OUT/config.json`` (the inference checkpoint, written by the
function the policy passes: its format is the policies', and training sits below them) and
``OUT/training/loss.csv`` / ``loss.png`` are derived from it. Each save writes the checkpoint
before the state, so a kill at any instant of a save leaves a state that re-runs the save;
a re-run that finds the training done but its checkpoint missing or torn (``checkpoint_step``
disagrees with the state) writes it again from the state. Under torchrun each rank trains on
its own episode stream and rank 0 writes.

The state also counts the wall time of the steps it holds, over every piece that saved them
and the machines they ran on: a training spread over several runs (each killed, then
resumed) keeps the time of all its saved steps, and loses with a killed piece only the time
of the steps it had not saved, which it loses too.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn
from tqdm import tqdm

from rmbench.files import (
    FileFormatError,
    read_json_object,
    remove_leftovers,
    write_atomic,
    write_json,
)
from rmbench.identity import differences
from rmbench.machine import describe as describe_machine
from rmbench.tasks.registry import recorded_gym_id
from rmbench.training.device import check_device, flush_denormals

log = logging.getLogger(__name__)

STATE = Path("training") / "state.pt"
# the run's identity, written before anything else of a new run: a folder whose first save
# was interrupted (a checkpoint, no state yet) is then known as this run's and begun again
STARTED = Path("training") / "started.json"
CURVE_CSV = Path("training") / "loss.csv"
CURVE_PNG = Path("training") / "loss.png"


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


@dataclass(frozen=True)
class TrainConfig:
    """The optimisation settings shared by every policy (the published Mem-0 values where
    they fit a CPU: AdamW (0.9, 0.999), weight decay 0.005, 5% warm-up, clip 2.5)."""

    steps: int = 3000
    batch_size: int = 32
    weight_decay: float = 0.005
    warmup: float = 0.05  # fraction of the steps
    grad_clip: float = 2.5
    save_every: int = 500
    log_every: int = 10
    seed: int = 0
    device: str = "cpu"

    def __post_init__(self):
        if self.steps < 1 or self.batch_size < 1 or self.save_every < 1 or self.log_every < 1:
            raise ValueError("steps, batch_size, save_every and log_every must be >= 1")
        if not 0 <= self.warmup < 1:
            raise ValueError(f"warmup is a fraction of the steps in [0, 1), got {self.warmup}")
        check_device(self.device)


# Where a run trains is not part of what it is: a run started on a GPU resumes on a CPU (or
# another GPU), and one started on another machine resumes on this one, where the same dataset lives
# in another folder; it draws the batches it would have drawn. The dataset's episodes and
# frames stay part of it.
PLACE_FIELDS = ("device",)


def _run_fields(cfg: TrainConfig) -> dict[str, Any]:
    """The settings a resumed run must share with the saved one."""
    return {k: v for k, v in asdict(cfg).items() if k not in PLACE_FIELDS}


def run_identity(describe: dict[str, Any], cfg: TrainConfig, world: int = 1) -> dict:
    """What a run is, as its saved state records it and a resume must match: the checkpoint's
    description, the training settings and the number of processes; as JSON stores it
    (tuples become lists), so that a resume compares like with like."""
    return json.loads(json.dumps({"describe": describe, "train": _run_fields(cfg),
                                  "world": world}))


def _placeless(identity: dict) -> dict:
    """``identity`` without where the run trained: its device (named by states saved before it
    was left out) and its dataset's folder (kept in the checkpoint's description)."""
    out = json.loads(json.dumps(identity))
    for field in PLACE_FIELDS:
        out.get("train", {}).pop(field, None)
    dataset = out.get("describe", {}).get("dataset")
    if isinstance(dataset, dict):
        dataset.pop("path", None)
    return out


def lr_at(step: int, total: int, warmup: float, base: float, minimum: float) -> float:
    """Linear warm-up over ``warmup * total`` steps, then cosine from ``base`` to ``minimum``."""
    w = int(warmup * total)
    if step < w:
        return base * (step + 1) / w
    progress = (step - w) / max(1, total - w)
    return minimum + (base - minimum) * 0.5 * (1 + math.cos(math.pi * min(1.0, progress)))


@dataclass(frozen=True)
class Dist:
    rank: int = 0
    world: int = 1
    local_rank: int = 0

    @classmethod
    def from_env(cls) -> Dist:
        return cls(int(os.environ.get("RANK", 0)), int(os.environ.get("WORLD_SIZE", 1)),
                   int(os.environ.get("LOCAL_RANK", 0)))


# (first step, rank, world) -> batches for that step onwards
BatchSource = Callable[[int, int, int], Iterator[dict[str, torch.Tensor]]]
# (folder, model to export, describe, step) -> None: writes the inference checkpoint
# (rmbench.policies.checkpoint.save_checkpoint)
CheckpointWriter = Callable[[Path, nn.Module, dict[str, Any], int], None]
# folder -> the step of the complete checkpoint it holds, None if missing or torn
# (rmbench.policies.checkpoint.saved_step)
CheckpointStep = Callable[[Path], "int | None"]


def train(model: nn.Module, batches: BatchSource, cfg: TrainConfig, out: str | Path,
          describe: dict[str, Any], progress: bool = True, *,
          write_checkpoint: CheckpointWriter, checkpoint_step: CheckpointStep | None = None,
          config_defaults: dict[str, Any] | None = None,
          data: str | None = None) -> dict[str, Any]:
    """Train ``model`` for ``cfg.steps`` steps into ``out``; ``describe`` is what the
    inference checkpoint's config.json holds (and what a resume must match), and
    ``write_checkpoint`` writes that checkpoint at each save; ``checkpoint_step`` reads the
    step of the one ``out`` holds, to repair it when the training is done. ``config_defaults``: the
    defaults of the policy config in ``describe["config"]``; a run saved before a field
    existed ran with its default, so it resumes when that default is asked for. ``data``: the
    training data's fingerprint (``Dataset.fingerprint``), kept in the state beside the
    identity (a dataset's folder is no part of it) so that a resume on other data is refused;
    a state saved without one resumes on any."""
    out = Path(out)
    dist = Dist.from_env()
    if dist.world > 1 and not torch.distributed.is_initialized():
        backend = "nccl" if cfg.device.startswith("cuda") else "gloo"
        torch.distributed.init_process_group(backend)
    device = torch.device(f"cuda:{dist.local_rank}" if cfg.device == "cuda" else cfg.device)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise TrainingError("--device cuda, but this torch has no CUDA device")
    flush_denormals()
    torch.manual_seed(cfg.seed + dist.rank)
    model.to(device)
    groups = model.param_groups()
    opt = torch.optim.AdamW([{"params": g["params"], "lr": g["lr"], "name": g["name"],
                              "base_lr": g["lr"], "min_lr": g["min_lr"]} for g in groups],
                            betas=(0.9, 0.999), weight_decay=cfg.weight_decay, foreach=True)
    identity = run_identity(describe, cfg, dist.world)
    defaults = json.loads(json.dumps(config_defaults or {}))
    kept = _resume(out, model, opt, identity, defaults, device, data)
    start = kept.step
    if dist.rank == 0:
        for folder in (out, out / STATE.parent):  # what writers killed before a rename left
            remove_leftovers(folder)
        if start == 0:
            write_json(out / STARTED, identity)
    if start >= cfg.steps:
        log.info("%s: already trained for %d steps", out, start)
        if dist.rank == 0 and checkpoint_step is not None and checkpoint_step(out) != start:
            log.warning("%s: the checkpoint of step %d is missing or torn: written again from "
                        "the training state", out, start)
            _export(out, model, identity, start, write_checkpoint)
        if dist.rank == 0 and _stale(out / CURVE_PNG, out / CURVE_CSV):
            _plot_curve(out)  # (a run stopped between its last state and its plot)
        return {"steps": start, "resumed_from": start, **kept.timing()}
    here = describe_machine()
    if device.type == "cuda":
        here = {**here, "gpu": torch.cuda.get_device_name(device)}
    machines = kept.machines + (() if here in kept.machines else (here,))
    # the clip's norm covers what is optimised: a frozen part (Mem-0's planner) is not in it
    trained = [p for g in opt.param_groups for p in g["params"]]
    trainer = (torch.nn.parallel.DistributedDataParallel(model) if dist.world > 1 else model)
    lead = dist.rank == 0
    rows: list[dict[str, Any]] = []
    stream = batches(start, dist.rank, dist.world)
    bar = tqdm(total=cfg.steps, initial=start, unit="step", disable=not (progress and lead),
               desc=f"train {describe.get('policy', '')}", dynamic_ncols=True)
    # this piece's steps are timed from t0 and added to the saved steps' time once, at each save
    t0, last_save, before = time.perf_counter(), start, kept.wall_s
    model.train()
    for step in range(start, cfg.steps):
        batch = {k: v.to(device, non_blocking=True) if torch.is_tensor(v) else v
                 for k, v in next(stream).items()}
        for g in opt.param_groups:
            g["lr"] = lr_at(step, cfg.steps, cfg.warmup, g["base_lr"], g["min_lr"])
        loss, logs = trainer(batch)
        if not torch.isfinite(loss):
            raise TrainingError(f"step {step}: loss is {loss.item()} (logs {logs})")
        opt.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(trained, cfg.grad_clip, foreach=True)
        opt.step()
        if hasattr(model, "after_step"):
            model.after_step()
        if lead and (step + 1) % cfg.log_every == 0:
            row = {"step": step + 1, "loss": loss.item(), "grad_norm": float(grad_norm),
                   **{f"lr/{g['name']}": g["lr"] for g in opt.param_groups},
                   **{k: float(v) for k, v in logs.items()}}
            rows.append(row)
            bar.set_postfix(loss=f"{row['loss']:.4f}", refresh=False)
        bar.update(1)
        if (step + 1) % cfg.save_every == 0 or step + 1 == cfg.steps:
            # unrounded: a short piece's steps would otherwise count as no time at all
            kept = Kept(step + 1, before + time.perf_counter() - t0, kept.wall_from, machines)
            if lead:
                _save(out, model, opt, identity, kept, rows, write_checkpoint, data)
                rows = []
            last_save = step + 1
    bar.close()
    if dist.world > 1:
        torch.distributed.barrier()
    return {"steps": cfg.steps, "resumed_from": start, "saved": last_save,
            "wall_s": round(time.perf_counter() - t0, 1), **kept.timing()}


def _save(out: Path, model: nn.Module, opt: torch.optim.Optimizer, identity: dict, kept: Kept,
          rows: list[dict], write_checkpoint: CheckpointWriter, data: str | None = None) -> None:
    step = kept.step
    state = {"step": step, "identity": json.dumps(identity, sort_keys=True),
             "wall_s": kept.wall_s, "wall_from": kept.wall_from,
             "machines": json.dumps(kept.machines),
             "model": model.state_dict(), "optimizer": opt.state_dict(),
             "rng": torch.get_rng_state(), "threads": torch.get_num_threads(), "data": data,
             "extra": model.extra_state() if hasattr(model, "extra_state") else {}}
    if torch.cuda.is_available():
        state["cuda_rng"] = torch.cuda.get_rng_state_all()
    buf = io.BytesIO()
    torch.save(state, buf)
    _append_curve(out, rows, step)
    # the checkpoint before the state that says it is written: a kill in between re-runs this
    # save, never leaves a finished training with an older or torn checkpoint
    _export(out, model, identity, step, write_checkpoint)
    write_atomic(out / STATE, buf.getvalue())  # the commit point
    _plot_curve(out)


def _export(out: Path, model: nn.Module, identity: dict, step: int,
            write_checkpoint: CheckpointWriter) -> None:
    export = model.export_module() if hasattr(model, "export_module") else model
    write_checkpoint(out, export, identity["describe"], step)


def _resume(out: Path, model: nn.Module, opt: torch.optim.Optimizer, identity: dict,
            config_defaults: dict, device: torch.device, data: str | None = None) -> Kept:
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
    state = _read_state(out, device)
    what = run_differences(json.loads(state["identity"]), identity, config_defaults)
    if what:
        raise TrainingError(f"{out} holds a training run with other arguments ({what}); "
                            f"use another --out")
    if None not in (state.get("data"), data) and state["data"] != data:
        raise TrainingError(f"{out} holds a training run on other data (fingerprint "
                            f"{state['data']} there, {data} asked): a dataset collected with "
                            f"other arguments or episodes; use another --out")
    model.load_state_dict(state["model"])
    opt.load_state_dict(state["optimizer"])
    torch.set_rng_state(state["rng"].cpu())
    if "cuda_rng" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all([s.cpu() for s in state["cuda_rng"]])
    if hasattr(model, "load_extra_state"):
        model.load_extra_state(state["extra"])
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


def _read_state(out: Path, device: torch.device | str = "cpu") -> dict:
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
    state = _read_state(Path(out))
    return json.loads(state["identity"]), int(state["step"])


def run_differences(saved: dict, identity: dict, config_defaults: dict | None = None) -> str:
    """What a saved run's identity and ``identity`` differ in, aside from where each trained
    ('' when nothing): a config field saved before it existed reads as its default
    (``config_defaults``), a run saved before checkpoints recorded their task version as the
    version of that time."""
    saved = json.loads(json.dumps(saved))
    defaults = json.loads(json.dumps(config_defaults or {}))
    if isinstance(saved.get("describe", {}).get("config"), dict):
        saved["describe"]["config"] = {**defaults, **saved["describe"]["config"]}
        if "gym_id" in identity.get("describe", {}) and "task" in saved["describe"]:
            saved["describe"]["gym_id"] = recorded_gym_id(saved["describe"]["task"],
                                                           saved["describe"])
    return differences(_placeless(saved), _placeless(identity))


def _append_curve(out: Path, rows: list[dict], step: int) -> None:
    """Rows after ``step`` (logged by a run killed before it saved) are replaced."""
    path = out / CURVE_CSV
    old: list[dict] = []
    if path.exists():
        with open(path, newline="") as f:
            first = rows[0]["step"] if rows else step + 1
            old = [r for r in csv.DictReader(f) if int(r["step"]) < first]
    allrows = old + rows
    if not allrows:
        return
    fields = list(dict.fromkeys(k for r in allrows for k in r))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fields)
    writer.writeheader()
    writer.writerows(allrows)
    write_atomic(path, buf.getvalue().encode())


def _stale(made: Path, source: Path) -> bool:
    """Whether ``made`` is missing or older than ``source`` (which exists)."""
    return source.exists() and (not made.exists()
                                or made.stat().st_mtime_ns < source.stat().st_mtime_ns)


def _plot_curve(out: Path) -> None:
    path = out / CURVE_CSV
    if not path.exists():
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return
    keys = [k for k in rows[0] if k == "loss" or k.startswith("loss/")]
    fig, ax = plt.subplots(figsize=(7, 4))
    steps = [int(r["step"]) for r in rows]
    for k in keys:
        ax.plot(steps, [float(r[k]) for r in rows], label=k, lw=1)
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    write_atomic(out / CURVE_PNG, buf.getvalue())
