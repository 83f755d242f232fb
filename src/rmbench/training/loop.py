"""The training loop every learned policy uses.

A policy's trainable model implements ``forward(batch) -> (loss, logs)``, ``param_groups()``
(named groups with their own learning rates), and optionally ``extra_state()`` /
``load_extra_state()`` for what training carries besides weights (Mem-0's per-episode memory
store) and ``after_step()`` (EMA). AdamW, cosine schedule with linear warm-up per group down to
the group's minimum, gradient-norm clipping.

Resume: ``OUT/training/state.pt`` (``rmbench.training.state``) is the commit point. A re-run
with the same arguments continues from it and, batches being a function of the step, gives the
weights an uninterrupted run gives. ``OUT/model.safetensors`` + ``OUT/config.json`` (the
inference checkpoint, written by the function the policy passes: its format is the policies',
and training sits below them) and the loss curve (``rmbench.training.curve``) are derived from
it. Each save writes the checkpoint before the state, so a kill at any instant of a save leaves
a state that re-runs the save; a re-run that finds the training done but its checkpoint missing
or torn (``checkpoint_step`` disagrees with the state) writes it again from the state. Under
torchrun each rank trains on its own episode stream and rank 0 writes; what is each rank's own
(its RNG, the trainer's extra state: Mem-0's memories of the episodes it walks) is gathered at
each save and each rank resumes from its own. The wrapper keeps each rank's buffers its own
(a DDP default would copy rank 0's memories over the others' at every step) and allows
parameters a run leaves unused (an M(1) task's end classifier, an ablation's fusion).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn
from tqdm import tqdm

from rmbench.files import remove_leftovers, write_atomic, write_json
from rmbench.machine import describe as describe_machine
from rmbench.training.curve import CURVE_CSV, CURVE_PNG, append_curve, plot_curve, stale
from rmbench.training.device import check_device, flush_denormals
from rmbench.training.state import (
    STARTED,
    STATE,
    Kept,
    TrainingError,
    rank_state,
    resume,
    run_identity,
    state_bytes,
)

log = logging.getLogger(__name__)


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


def rank_seed(seed: int, rank: int | None = None) -> int:
    """A rank's own seed from a run's ``seed`` (its batches, its trainer's noise), so that no two
    ranks draw alike; rank 0's (a one-process run's) is the run's seed."""
    return seed + 1000 * (Dist.from_env().rank if rank is None else rank)


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
    if device.type == "cuda":
        torch.cuda.set_device(device)  # (the device NCCL's object collectives use)
    flush_denormals()
    torch.manual_seed(rank_seed(cfg.seed, dist.rank))
    model.to(device)
    groups = model.param_groups()
    opt = torch.optim.AdamW([{"params": g["params"], "lr": g["lr"], "name": g["name"],
                              "base_lr": g["lr"], "min_lr": g["min_lr"]} for g in groups],
                            betas=(0.9, 0.999), weight_decay=cfg.weight_decay, foreach=True)
    identity = run_identity(describe, cfg, dist.world)
    defaults = json.loads(json.dumps(config_defaults or {}))
    kept = resume(out, model, opt, identity, defaults, device, data, dist.rank)
    start = kept.step
    if dist.world > 1:
        # every rank has read the folder before rank 0 writes into it: a rank still reading it
        # would otherwise see rank 0's STARTED (or its temporary file) and refuse the folder
        torch.distributed.barrier()
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
        if dist.rank == 0 and stale(out / CURVE_PNG, out / CURVE_CSV):
            plot_curve(out)  # (a run stopped between its last state and its plot)
        return {"steps": start, "resumed_from": start, **kept.timing()}
    here = describe_machine()
    if device.type == "cuda":
        here = {**here, "gpu": torch.cuda.get_device_name(device)}
    machines = kept.machines + (() if here in kept.machines else (here,))
    # the clip's norm covers what is optimised: a frozen part (Mem-0's planner) is not in it
    trained = [p for g in opt.param_groups for p in g["params"]]
    trainer = (torch.nn.parallel.DistributedDataParallel(
        model, broadcast_buffers=False, find_unused_parameters=True) if dist.world > 1 else model)
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
            ranks = _gathered(rank_state(model), dist.world)  # (every rank takes part)
            if lead:
                _save(out, model, opt, identity, kept, rows, write_checkpoint, data, ranks)
                rows = []
            last_save = step + 1
    bar.close()
    if dist.world > 1:
        torch.distributed.barrier()
    return {"steps": cfg.steps, "resumed_from": start, "saved": last_save,
            "wall_s": round(time.perf_counter() - t0, 1), **kept.timing()}


def _gathered(mine: dict, world: int) -> list[dict]:
    """Every rank's own state, in rank order, on every rank."""
    if world == 1:
        return [mine]
    states: list[Any] = [None] * world
    torch.distributed.all_gather_object(states, mine)
    return states


def _save(out: Path, model: nn.Module, opt: torch.optim.Optimizer, identity: dict, kept: Kept,
          rows: list[dict], write_checkpoint: CheckpointWriter, data: str | None = None,
          ranks: list[dict] | None = None) -> None:
    state = state_bytes(model, opt, identity, kept, data, ranks)
    append_curve(out, rows, kept.step)
    # the checkpoint before the state that says it is written: a kill in between re-runs this
    # save, never leaves a finished training with an older or torn checkpoint
    _export(out, model, identity, kept.step, write_checkpoint)
    write_atomic(out / STATE, state)  # the commit point
    plot_curve(out)


def _export(out: Path, model: nn.Module, identity: dict, step: int,
            write_checkpoint: CheckpointWriter) -> None:
    export = model.export_module() if hasattr(model, "export_module") else model
    write_checkpoint(out, export, identity["describe"], step)
