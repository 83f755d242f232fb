"""``rmbench train mem0``: the planner on (key memory -> next subtask) decisions, then the
executor on episode-ordered batches, from one dataset of one task, on its camera frames (or
their cached features by a frozen ``backbone``) or on its state observation
(``Mem0Config.observation``)."""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rmbench.data import layout as L
from rmbench.data.layout_shift import COPIES_SEED, add_layout_copies
from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import DemoDataset, EpisodeOrderSampler, FrameCache
from rmbench.files import write_json
from rmbench.machine import describe as describe_machine
from rmbench.policies.action_space import EE_DIM, EEActions
from rmbench.policies.checkpoint import (
    CheckpointError,
    dataset_record,
    read_config,
    read_weights,
    save_checkpoint,
    saved_step,
)
from rmbench.policies.feature_cache import FeatureCache, features_record, with_features
from rmbench.policies.mem0.classifier import end_labels, event_labels
from rmbench.policies.mem0.config import PLANNER_ABLATIONS, Mem0Config
from rmbench.policies.mem0.modeling import Mem0Model, Mem0Trainer
from rmbench.policies.mem0.planner import DONE, PlannerExample, planner_examples, planner_loss
from rmbench.policies.nn.normalize import Normalizer
from rmbench.policies.nn.text import MINILM_DIM, sentence_embeddings
from rmbench.policies.nn.vision import color_jitter
from rmbench.policies.observation import choose, set_state_stats
from rmbench.tasks import get_task
from rmbench.training.batches import batch_stream
from rmbench.training.loop import TrainConfig, lr_at, rank_seed, train
from rmbench.training.state import (
    STATE,
    TrainingError,
    run_differences,
    run_identity,
    saved_run,
)

log = logging.getLogger(__name__)


def goal_text(task: str) -> str:
    """M(1) tasks run as one subtask, the goal: the task's first seen instruction."""
    return get_task(task).instructions_seen[0]


class Mem0Frames(DemoDataset):
    """DemoDataset items plus what the executor trains on: the text of the frame's subtask
    (the goal for M(1) tasks) and the end classifier's label. With observation "state" the
    environment state instead of frames: no video is decoded; with a frozen backbone no frames
    either (``with_features`` adds their cached features)."""

    def __init__(self, ds: Dataset, cfg: Mem0Config, decompose: bool, goal_index: int, **kw):
        super().__init__(ds, chunk=cfg.horizon,
                         cameras=[] if cfg.reads_state or cfg.reads_features else list(cfg.cameras),
                         image_size=cfg.image_size, stride=cfg.memory_every,
                         environment_state=cfg.reads_state, **kw)
        self.decompose, self.goal_index = decompose, goal_index
        self.cfg = cfg
        self.labels = [self.end_label(ep) for ep in self.low_dim]

    def end_label(self, ep) -> np.ndarray:
        """The end classifier's (T,) targets for one episode, as its config reads them."""
        if self.cfg.end_classifier == "event":
            return event_labels(ep.subtask_step, self.cfg.end_span)
        return end_labels(ep.subtask_step, self.cfg.end_window)

    def add_episodes(self, episodes: list) -> None:
        super().add_episodes(episodes)
        self.labels += [self.end_label(ep) for ep in episodes]

    def columns(self) -> dict[str, np.ndarray]:
        if self._columns is None:
            super().columns()["end_label"] = np.concatenate(self.labels)
        return self._columns

    def batch(self, indices: list[int]) -> dict[str, torch.Tensor]:
        batch = super().batch(indices)
        k, t = self.locate_many(indices)
        batch["text_index"] = (batch[L.SUBTASK_INDEX].clone() if self.decompose
                               else torch.full((len(k),), self.goal_index, dtype=torch.int64))
        batch["end_label"] = torch.from_numpy(
            self.columns()["end_label"][self.starts[k] + t].astype(bool))
        return batch


def build_model(cfg: Mem0Config, describe: dict[str, Any], text_vectors=None) -> Mem0Model:
    if text_vectors is None and describe["text_encoder"] == "minilm":  # filled by the weights
        text_vectors = {k: torch.zeros(len(describe[f"{k}_texts"]), MINILM_DIM)
                        for k in ("executor", "planner")}
    return Mem0Model(cfg, describe["executor_texts"], describe["planner_texts"], text_vectors,
                     state_dim=len(describe.get("state_names") or ()))


def train_mem0(dataset: str | Path, out: str | Path, cfg: Mem0Config, train_cfg: TrainConfig,
               progress: bool = True, workers: int = 0,
               executor_from: str | Path | None = None) -> dict[str, Any]:
    """Fit the planner (M(n) tasks), then train the executor; or, with ``executor_from`` (a
    finished run of ``cfg.executor_config()``, for a planner-only ablation such as no_key),
    fit the planner alone and take that run's executor: the checkpoint a full run would
    write, for the planner's cost."""
    t0 = time.perf_counter()
    ds = Dataset(dataset)
    task = get_task(ds.task)
    cfg = replace(cfg, observation=choose(cfg.observation, ds))
    decompose = task.tmc == "M(n)"
    if executor_from is not None and (not decompose or cfg.executor_config() == cfg):
        raise ValueError(f"an executor is taken from another run only for a planner-only "
                         f"ablation ({', '.join(PLANNER_ABLATIONS)}) on an M(n) task; "
                         f"{task.name} with ablations {list(cfg.ablations)} trains its own")
    goal = goal_text(task.name)
    executor_texts = list(ds.subtasks) + [goal]
    planner_texts = list(ds.subtasks) + [DONE]
    vectors = sentence_embeddings(executor_texts + planner_texts)
    describe = {
        "policy": "mem0", "config": cfg.to_dict(), "task": task.name, "tmc": task.tmc,
        "gym_id": ds.gym_id,
        "executor_texts": executor_texts, "planner_texts": planner_texts,
        "text_encoder": "learned" if vectors is None else "minilm",
        "dataset": dataset_record(ds, dataset),
        **features_record(cfg),
    }
    if cfg.reads_state:
        describe["state_names"] = ds.state_names
    if vectors is not None:
        vectors = {"executor": vectors[:len(executor_texts)],
                   "planner": vectors[len(executor_texts):]}
    torch.manual_seed(train_cfg.seed)
    model = build_model(cfg, describe, vectors)
    examples = Mem0Frames(ds, cfg, decompose, executor_texts.index(goal))
    stats = ds.stats
    # The joint targets' range is the recorded demonstrations' (measured before any copies).
    norm = (None if cfg.action_space == "ee" else Normalizer.for_demonstrations(
        stats, examples.low_dim, cfg.horizon, cfg.relative_actions))
    if cfg.layout_copies:
        describe["layout_copies_kept"] = add_layout_copies(
            examples, cfg.layout_copies, cfg.layout_shift, COPIES_SEED)
    if norm is None:
        norm = to_pose_actions(examples, stats, cfg.horizon)
    model.executor.normalizer.load_state_dict(norm.state_dict())
    if cfg.reads_state:
        encoders = (model.executor.encoders, model.planner.encoders)
        set_state_stats(encoders, stats, examples.low_dim)
        if cfg.reach_input:
            env_states = np.concatenate([ep.environment_state for ep in examples.low_dim])
            for encoder in encoders:
                encoder.set_reach(ds.state_names, cfg.reach_input, env_states)
    out = Path(out)
    if executor_from is not None:  # checked before the planner's fit, which it would waste
        step = _executor_source(Path(executor_from), out, describe, cfg, train_cfg)
    planner_report = None
    if decompose and not (out / STATE).exists():
        planner_report = fit_planner(model, ds, cfg, train_cfg, planner_texts.index(DONE), progress)
    if executor_from is not None:
        return _beside_executor(Path(executor_from), step, model, out, describe, planner_report,
                                time.perf_counter() - t0)
    trainer = Mem0Trainer(model, train_cfg.batch_size, decompose, rank_seed(train_cfg.seed),
                          describe.get("state_names", ()))
    # kept in the training state, so a run interrupted after the planner's fit still reports it
    trainer.planner_report = planner_report
    frames = with_features(examples, ds, cfg)

    def batches(start: int, rank: int, world: int):
        sampler = EpisodeOrderSampler(frames, train_cfg.batch_size,
                                      seed=rank_seed(train_cfg.seed, rank))
        return batch_stream(frames, sampler, start, workers)

    result = train(trainer, batches, train_cfg, out, describe, progress,
                   write_checkpoint=save_checkpoint, checkpoint_step=saved_step,
                   config_defaults=type(cfg).saved_defaults(), data=ds.fingerprint)
    if trainer.planner_report is not None:
        write_json(out / "training" / "planner.json", trainer.planner_report, indent=2)
    return result


def _executor_source(source: Path, out: Path, describe: dict[str, Any], cfg: Mem0Config,
                     train_cfg: TrainConfig) -> int:
    """The step of ``source``, a finished training run of the same description and settings
    as this one but for the planner-only ablations, whose executor ``out`` takes (a
    TrainingError naming what differs otherwise, or where ``out`` holds a run of its own)."""
    if (out / STATE).exists() or out.resolve() == source.resolve():
        raise TrainingError(f"{out} holds a training run of its own; a checkpoint that takes "
                            f"the executor of {source} needs a new --out")
    saved, step = saved_run(source)
    executor_describe = {**describe, "config": cfg.executor_config().to_dict()}
    what = run_differences(saved, run_identity(executor_describe, train_cfg, saved.get("world", 1)),
                           type(cfg).saved_defaults())
    if what:
        raise TrainingError(f"{source} is not the executor run of this one ({what})")
    if step != train_cfg.steps:
        raise TrainingError(f"{source} has trained {step} of {train_cfg.steps} steps; finish it "
                            f"first")
    return step


def _beside_executor(source: Path, step: int, model: Mem0Model, out: Path,
                     describe: dict[str, Any], planner_report: dict[str, Any] | None,
                     wall_s: float) -> dict[str, Any]:
    """Write ``out``'s checkpoint: ``model``'s freshly fitted planner beside the executor
    ``source`` saved at ``step`` (checked by ``_executor_source``)."""
    if planner_report is None:
        raise TrainingError(f"{out}: no planner was fitted; a checkpoint beside another run's "
                            f"executor is made for an M(n) task's planner-only ablation")
    weights = read_weights(source, step)
    model.executor.load_state_dict({k.removeprefix("executor."): v for k, v in weights.items()
                                    if k.startswith("executor.")})
    # the planner's report first: the checkpoint's config is what says the run is done
    write_json(out / "training" / "planner.json", planner_report, indent=2)
    save_checkpoint(out, model, {**describe, "executor_from": str(source.resolve()),
                                 "executor_sha256": executor_digest(weights)}, step)
    return {"steps": step, "resumed_from": 0, "wall_s": round(wall_s, 1),
            "train_wall_s": round(wall_s, 1), "train_wall_from_step": 0,
            "machines": [describe_machine()], "executor_from": str(source.resolve())}


def executor_digest(weights: dict[str, torch.Tensor]) -> str:
    """sha256 over a checkpoint's executor tensors (name, dtype, bytes; by name): what ties a
    checkpoint made beside another run's executor to that run's weights."""
    h = hashlib.sha256()
    for name in sorted(k for k in weights if k.startswith("executor.")):
        t = weights[name].contiguous()
        h.update(f"{name}:{t.dtype}:{tuple(t.shape)};".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def check_executor_source(folder: Path) -> None:
    """A checkpoint made beside another run's executor (its config's ``executor_from``) still
    holds that run's executor: a CheckpointError where the source was trained again since, so
    that a planner-only ablation is never set beside an executor it was not made with."""
    config = read_config(folder)
    source = config.get("executor_from")
    if source is None:
        return
    step = saved_step(source)
    if step is None:
        raise CheckpointError(f"{folder} took its executor from {source}, which holds no "
                              f"complete checkpoint now")
    mine = executor_digest(read_weights(folder, config["step"]))
    if executor_digest(read_weights(source, step)) != mine:
        raise CheckpointError(f"{folder} took its executor from {source}, trained again "
                              f"since; move {folder} aside to make it again beside the new one")


def to_pose_actions(frames: Mem0Frames, stats, horizon: int) -> Normalizer:
    """Replace every episode's joint targets by grasp-pose targets (``action_space`` "ee"),
    and the normaliser of their ranges."""
    convert = EEActions()
    frames.replace_episodes([replace(ep, action=convert.from_joints(ep.action))
                             for ep in frames.low_dim])
    return Normalizer.from_episodes(stats, [ep.state for ep in frames.low_dim],
                                    [ep.action for ep in frames.low_dim], horizon,
                                    relative=np.zeros(EE_DIM, bool))


def fit_planner(model: Mem0Model, ds: Dataset, cfg: Mem0Config, train_cfg: TrainConfig,
                done: int, progress: bool) -> dict[str, Any]:
    """Train the planner on every decision of every demonstration (a few hundred): first
    subtask, each next one, then done (candidate index ``done``)."""
    planner = model.planner
    episodes = [ds.episode(e, cameras=[]) for e in range(ds.num_episodes)]
    examples = [x for e, ep in enumerate(episodes)
                for x in planner_examples(e, ep.subtask_index, ep.subtask_step, done)]
    if len(examples) == 2 * len(episodes):
        # one step per episode: the task counted none of its plan's steps while the data was
        # collected (battery_try-v3 under action noise), so there is nothing to plan
        raise ValueError(f"{ds.root}: every episode holds one step of its task's plan, so the "
                         f"planner has no decision to learn; collect the data again with a "
                         f"version of {ds.task} that counts its steps")
    frames = planner_frames(ds, cfg)
    gen = torch.Generator().manual_seed(train_cfg.seed)
    device = torch.device("cuda" if train_cfg.device.startswith("cuda") else "cpu")
    planner.to(device)
    trainable = [p for p in planner.parameters() if p.requires_grad]  # (LoRA: adapters only)
    opt = torch.optim.AdamW(trainable, lr=cfg.planner_lr, betas=(0.9, 0.999),
                            weight_decay=train_cfg.weight_decay, foreach=True)
    rng = np.random.default_rng(train_cfg.seed)
    acc_ema, loss_ema = 0.0, 0.0
    lengths = [len(ep.subtask_step) for ep in episodes]
    for step in range(cfg.planner_steps):
        picks = [examples[i] for i in rng.integers(len(examples), size=cfg.planner_batch)]
        if cfg.planner_key_delay:
            picks = [delayed(x, rng, cfg.planner_key_delay, lengths[x.episode]) for x in picks]
        batch = planner_batch(planner, frames, picks, gen, device)
        for g in opt.param_groups:
            g["lr"] = lr_at(step, cfg.planner_steps, 0.1, cfg.planner_lr, cfg.planner_lr * 0.01)
        loss, acc = planner_loss(planner, batch)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(trainable, train_cfg.grad_clip)
        opt.step()
        loss_ema = 0.98 * loss_ema + 0.02 * loss.item() if step else loss.item()
        acc_ema = 0.98 * acc_ema + 0.02 * float(acc) if step else float(acc)
        if progress and (step + 1) % 100 == 0:
            log.info("planner step %d: loss %.4f, accuracy %.3f", step + 1, loss_ema, acc_ema)
    opt.zero_grad(set_to_none=True)  # the frozen planner carries no gradients into the executor's run
    planner.eval()
    with torch.no_grad():
        correct = 0
        for i in range(0, len(examples), 32):
            b = planner_batch(planner, frames, examples[i:i + 32], None, device)
            correct += int((planner(b["first"], b["keys"], b["key_text"], b["key_valid"])
                            .argmax(-1) == b["target"]).sum())
    planner.train()
    return {"decisions": len(examples), "steps": cfg.planner_steps,
            "train_accuracy": round(correct / len(examples), 4), "final_loss": round(loss_ema, 5)}


def delayed(x: PlannerExample, rng: np.random.Generator, most: int, length: int) -> PlannerExample:
    """``x`` with each key frame, and the decision frame, moved 0..``most`` frames later (within
    the episode): the frames at which the end classifier may declare those ends."""
    shift = rng.integers(0, most + 1, size=len(x.keys) + 1)
    keys = tuple((s, min(f + int(d), length - 1)) for (s, f), d in zip(x.keys, shift[:-1], strict=True))
    return replace(x, keys=keys, current=min(x.current + int(shift[-1]), length - 1))


# (episode, frame indices, jitter generator or None) -> the planner's inputs at those frames
PlannerFrames = Callable[[int, list[int], torch.Generator | None], list[torch.Tensor]]


def planner_frames(ds: Dataset, cfg: Mem0Config) -> PlannerFrames:
    """The planner's inputs at given frames of an episode: the planner cameras' frames (from
    the frame cache, jittered when a generator is given) or their cached backbone features,
    or the environment and joint states."""
    if cfg.reads_state:
        low_dim = [ds.episode(e, cameras=[]) for e in range(ds.num_episodes)]

        def states(e: int, ts: list[int], gen) -> list[torch.Tensor]:
            ep = low_dim[e]
            return [torch.from_numpy(ep.environment_state[ts]), torch.from_numpy(ep.state[ts])]

        return states
    if cfg.reads_features:
        features = FeatureCache(ds, cfg.backbone, cfg.backbone_stride, cfg.image_size)

        def cached(e: int, ts: list[int], gen) -> list[torch.Tensor]:
            return [torch.from_numpy(np.array(features.features(e, cam)[ts])).float()
                    for cam in cfg.planner_cameras]

        return cached
    cache = FrameCache(ds, cfg.image_size)

    def frames(e: int, ts: list[int], gen) -> list[torch.Tensor]:
        out = []
        for cam in cfg.planner_cameras:
            img = torch.from_numpy(np.array(cache.frames(e, cam)[ts])).permute(0, 3, 1, 2)
            out.append(color_jitter(img, gen, *cfg.jitter) if gen is not None else img)
        return out

    return frames


def planner_batch(planner, frames: PlannerFrames, picks, gen, device) -> dict:
    """Embedded frames for a list of PlannerExamples (jittered when ``gen`` is given)."""
    m = max(1, max(len(x.keys) for x in picks))
    # o_0 and the key frames of each pick; with no_key the current frame alone
    times = [[0] + [f for _, f in x.keys] if planner.use_key else [x.current] for x in picks]
    # one embedding call for the whole batch (per input: every pick's frames in turn)
    per_input = zip(*(frames(x.episode, ts, gen) for x, ts in zip(picks, times, strict=True)),
                    strict=True)
    embedded = planner.embed([torch.cat(parts).to(device) for parts in per_input])
    firsts, keys, texts, valid = [], [], [], []
    for x, ts, emb in zip(picks, times, embedded.split([len(ts) for ts in times]), strict=True):
        firsts.append(emb[0])
        k = torch.zeros(m, emb.shape[1], device=device)
        k[:len(ts) - 1] = emb[1:]
        keys.append(k)
        texts.append(torch.tensor([s for s, _ in x.keys] + [0] * (m - len(x.keys))))
        valid.append(torch.arange(m) < len(x.keys))
    return {"first": torch.stack(firsts), "keys": torch.stack(keys),
            "key_text": torch.stack(texts).to(device), "key_valid": torch.stack(valid).to(device),
            "target": torch.tensor([x.target for x in picks], device=device)}

