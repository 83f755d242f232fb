"""Policy speed on CPU: closed-loop steps/s on one core for Mem-0, Diffusion Policy and ACT
with the default camera set, Mem-0's planner latency, memory per step, and training steps/s
(forward, backward and AdamW on a batch of 32, or --batch) for each.

    python benchmarks/policy_speed.py [--steps 300] [--train-steps 20] [--task press_button] \
        [--batch 32] [--out FILE]
    python benchmarks/policy_speed.py --case backbone [--steps 100] [--train-steps 10] \
        [--batch 32] [--set FIELD=VALUE ...] [--out FILE]

Models are the default configurations with random weights (speed does not depend on the
weights). Observations are real renders of the task's station (three cameras at 320x240),
resized by the policy as in evaluation. Training batches are built from the same renders.
Prints a table and writes benchmarks/results/policy_speed.json.

``--case backbone`` compares, on one thread, Mem-0's training steps/s at the same batch with its
CNNs (on frames, jittered) and with the frozen EfficientNet-Lite0 (on features as the cache
holds them), the closed loop's step with the backbone in it (Mem-0, DP, ACT), and the cache's
encoding rate, at strides 8, 16 and 32; it writes benchmarks/results/policy_speed_backbone.json.
``--set FIELD=VALUE`` changes Mem-0's config in either case; here on both sides (e.g. the
action head a recipe trains, which both share: the smaller it is, the more of a step the
encoder is).
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

import numpy as np
import torch

import rmbench
from rmbench.data import layout as L
from rmbench.data.torch_dataset import resize
from rmbench.files import write_json
from rmbench.policies.act.agent import ACTPolicy
from rmbench.policies.act.config import ACTConfig
from rmbench.policies.act.modeling import ACTModel, ACTTrainer
from rmbench.policies.config import parse_overrides
from rmbench.policies.dp.agent import DPPolicy
from rmbench.policies.dp.config import DPConfig
from rmbench.policies.dp.modeling import DiffusionPolicyModel, DPTrainer
from rmbench.policies.feature_cache import ENCODE_BATCH, features_key
from rmbench.policies.mem0.agent import Mem0Policy
from rmbench.policies.mem0.config import Mem0Config
from rmbench.policies.mem0.modeling import Mem0Model, Mem0Trainer
from rmbench.policies.mem0.planner import DONE
from rmbench.policies.mem0.train import goal_text
from rmbench.policies.nn.backbone import EFFICIENTNET_LITE0, backbone_features
from rmbench.tasks import get_task

OUT = Path(__file__).parent / "results" / "policy_speed.json"
OUT_BACKBONE = Path(__file__).parent / "results" / "policy_speed_backbone.json"
STRIDES = (8, 16, 32)
BATCH = 32


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def closed_loop(policy, frames, steps: int) -> dict:
    policy.reset("", {"seed": 0})
    for k in range(20):  # warm-up
        policy.act(frames[k % len(frames)])
    rss0, t0 = rss_mb(), time.perf_counter()
    for k in range(steps):
        policy.act(frames[k % len(frames)])
    step_s = (time.perf_counter() - t0) / steps
    return {"step_ms": round(1000 * step_s, 2), "hz": round(1 / step_s, 1),
            "rss_growth_mb": round(rss_mb() - rss0, 1)}


def batch_from(frames, cfg, obs_steps: int, horizon: int, size: int) -> dict[str, torch.Tensor]:
    """A training batch of ``size`` items from the rendered frames, at the model's image size."""
    rng = np.random.default_rng(0)
    batch: dict[str, torch.Tensor] = {}
    window = (obs_steps,) if obs_steps > 1 else ()
    for cam in cfg.cameras:
        imgs = resize(np.stack([f["pixels"][cam] for f in frames]), tuple(cfg.image_size))
        pick = rng.integers(len(frames), size=(size, *window))
        batch[L.image_key(cam)] = torch.from_numpy(imgs[pick]).movedim(-1, -3).contiguous()
    state = torch.from_numpy(np.stack([f["agent_pos"] for f in frames]).astype(np.float32))
    batch[L.STATE] = state[rng.integers(len(frames), size=(size, *window))]
    batch[L.ACTION] = state[rng.integers(len(frames), size=(size, horizon))]
    batch["action_is_pad"] = torch.zeros(size, horizon, dtype=torch.bool)
    batch[L.SUBTASK_INDEX] = torch.zeros(size, dtype=torch.long)
    batch["text_index"] = torch.zeros(size, dtype=torch.long)
    batch["episode_start"] = torch.zeros(size, dtype=torch.bool)
    batch["end_label"] = torch.zeros(size, dtype=torch.bool)
    return batch


def train_speed(trainer, batch, steps: int) -> dict:
    trainer.train()
    opt = torch.optim.AdamW([p for g in trainer.param_groups() for p in g["params"]], lr=1e-4)

    def step():
        loss, _ = trainer(batch)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if hasattr(trainer, "after_step"):
            trainer.after_step()

    for _ in range(3):  # warm-up
        step()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return {"train_steps_per_s": round(steps / (time.perf_counter() - t0), 2)}


def with_features(batch: dict[str, torch.Tensor], cfg) -> dict[str, torch.Tensor]:
    """The batch with each camera's frames replaced by their backbone features (the cache's)."""
    out = {k: v for k, v in batch.items() if not k.startswith("observation.images.")}
    for cam in cfg.cameras:
        images = batch[L.image_key(cam)]
        out[features_key(cam)] = torch.cat([
            backbone_features(cfg.backbone, cfg.backbone_stride, images[i:i + ENCODE_BATCH])
            for i in range(0, len(images), ENCODE_BATCH)])
    return out


def mem0_describe(task) -> dict:
    subtasks = list(task.subtasks)
    return {"policy": "mem0", "task": task.name, "tmc": task.tmc,
            "executor_texts": subtasks + [goal_text(task.name)],
            "planner_texts": subtasks + [DONE], "text_encoder": "learned"}


def backbone_case(task, frames, args) -> dict:
    """One thread throughout: Mem-0's training with the CNNs against the frozen backbone's
    cached features, the closed loop with the backbone in it, and the cache's encoding rate."""
    torch.set_num_threads(1)
    describe = mem0_describe(task)
    decompose = task.tmc == "M(n)"

    def mem0_trainer(cfg):
        torch.manual_seed(0)
        model = Mem0Model(cfg, describe["executor_texts"], describe["planner_texts"], None)
        return Mem0Trainer(model, args.batch, decompose, 0)

    cnn = Mem0Config(**args.mem0)
    images = batch_from(frames, cnn, 1, cnn.horizon, args.batch)
    results: dict = {"cnn": {"mem0": train_speed(mem0_trainer(cnn), images, args.train_steps)}}
    results["cnn"]["mem0"].update(closed_loop(
        Mem0Policy.from_model(mem0_trainer(cnn).model, describe), frames, args.steps))
    for stride in STRIDES:
        cfg = Mem0Config(**args.mem0, backbone=EFFICIENTNET_LITE0, backbone_stride=stride)
        features = with_features(images, cfg)
        row = train_speed(mem0_trainer(cfg), features, args.train_steps)
        row["feature_shape"] = list(features[features_key("head")].shape[1:])
        torch.manual_seed(0)
        model = Mem0Model(cfg, describe["executor_texts"], describe["planner_texts"], None)
        row["mem0_params"] = sum(p.numel() for p in model.executor.parameters())
        row["mem0"] = closed_loop(Mem0Policy.from_model(model, describe), frames, args.steps)
        for name, (bcfg, model_cls, policy_cls) in {
                "dp": (DPConfig(backbone=EFFICIENTNET_LITE0, backbone_stride=stride),
                       DiffusionPolicyModel, DPPolicy),
                "act": (ACTConfig(backbone=EFFICIENTNET_LITE0, backbone_stride=stride),
                        ACTModel, ACTPolicy)}.items():
            torch.manual_seed(0)
            row[name] = closed_loop(policy_cls.from_model(model_cls(bcfg)), frames, args.steps)
        # the backbone alone: three cameras in one batch, as the policies run it
        policy = Mem0Policy.from_model(model, describe)
        n, t0 = 50, time.perf_counter()
        for k in range(n):
            policy.inputs(frames[k % len(frames)])
        row["inputs_ms"] = round(1000 * (time.perf_counter() - t0) / n, 2)
        # the cache's encoding rate (frames already resized, in ENCODE_BATCH batches)
        head = images[L.image_key("head")]
        t0 = time.perf_counter()
        for i in range(0, len(head), ENCODE_BATCH):
            backbone_features(cfg.backbone, stride, head[i:i + ENCODE_BATCH])
        row["encode_frames_per_s"] = round(len(head) / (time.perf_counter() - t0), 1)
        speed = row.pop("train_steps_per_s")
        results[f"stride{stride}"] = {"mem0": {"train_steps_per_s": speed,
                                               "train_speedup": round(
                                                   speed / results["cnn"]["mem0"]
                                                   ["train_steps_per_s"], 1),
                                               "params": row.pop("mem0_params"),
                                               **row.pop("mem0")}, **row}
    result = {"task": task.name, "cameras": list(cnn.cameras), "image_size": list(cnn.image_size),
              "threads": 1, "batch_size": args.batch, "steps": args.steps,
              "train_steps": args.train_steps, "set": args.set, "results": results}
    print(f"one thread; Mem-0 with its CNNs: training at batch {args.batch} on frames "
          f"{results['cnn']['mem0']['train_steps_per_s']:.2f} steps/s, closed-loop step "
          f"{results['cnn']['mem0']['step_ms']:.1f} ms; with the frozen backbone:")
    print(f"{'stride':<8}{'features':>14}{'train steps/s':>15}{'speedup':>9}{'inputs':>10}"
          f"{'Mem-0 step':>12}"
          f"{'DP step':>10}{'ACT step':>10}{'encode':>14}")
    for stride in STRIDES:
        r = results[f"stride{stride}"]
        print(f"{stride:<8}{'x'.join(map(str, r['feature_shape'])):>14}"
              f"{r['mem0']['train_steps_per_s']:>15.2f}{r['mem0']['train_speedup']:>8.1f}x"
              f"{r['inputs_ms']:>7.1f} ms"
              f"{r['mem0']['step_ms']:>9.1f} ms{r['dp']['step_ms']:>7.1f} ms"
              f"{r['act']['step_ms']:>7.1f} ms{r['encode_frames_per_s']:>8.0f} fr/s")
    write_json(args.out or OUT_BACKBONE, result, indent=2)
    print(f"wrote {args.out or OUT_BACKBONE}")
    return result


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--train-steps", type=int, default=20)
    ap.add_argument("--task", default="press_button")
    ap.add_argument("--case", choices=("all", "backbone"), default="all")
    ap.add_argument("--batch", type=int, default=BATCH, help="training batch size")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a Mem-0 config field (VALUE as JSON); with --case backbone on both sides")
    ap.add_argument("--out", type=Path, default=None,
                    help=f"the JSON written (default {OUT}, with --case backbone {OUT_BACKBONE})")
    args = ap.parse_args()
    try:
        args.mem0 = parse_overrides(Mem0Config, args.set)
    except ValueError as err:
        ap.error(str(err))
    cores = len(os.sched_getaffinity(0))
    task = get_task(args.task)
    env = rmbench.make(task.name, cameras=Mem0Config().cameras)
    obs, info = env.reset(seed=100000)
    frames = [obs]
    env.action_space.seed(0)
    for k in range(20):  # a few distinct frames to cycle through
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        frames.append(obs)
        if terminated or truncated:  # a random action can end the episode (a failure)
            obs, _ = env.reset(seed=100001 + k)
    env.close()
    if args.case == "backbone":
        backbone_case(task, frames, args)
        return

    # --- Mem-0
    cfg = Mem0Config(**args.mem0)
    describe = mem0_describe(task)
    torch.manual_seed(0)
    model = Mem0Model(cfg, describe["executor_texts"], describe["planner_texts"], None)
    policy = Mem0Policy.from_model(model, describe)
    torch.set_num_threads(1)  # one core, as the inference target says
    results = {"mem0": closed_loop(policy, frames, args.steps)}
    results["mem0"]["params"] = sum(p.numel() for p in model.executor.parameters())
    imgs = policy.inputs(frames[0])
    planner_cams = policy.planner_inputs(imgs)
    with torch.no_grad():  # the planner with a full key memory of 8 finished subtasks
        policy.first = model.planner.embed(planner_cams)
        policy.keys = [(k % len(task.subtasks), model.planner.embed(planner_cams)[0]) for k in range(8)]
        for _ in range(3):
            policy.subtask_ended(imgs)
        n, t0 = 20, time.perf_counter()
        for _ in range(n):
            policy.keys = policy.keys[:8]
            policy.subtask_ended(imgs)  # embeds the end frame, stores it, plans
        results["mem0"]["planner_ms"] = round(1000 * (time.perf_counter() - t0) / n, 2)
    results["mem0"]["memory_store_floats"] = int(policy.memory.anchor.numel()
                                                 + policy.memory.sliding.numel())

    # --- the baselines
    baselines = {"dp": (DPConfig(), DiffusionPolicyModel, DPPolicy, DPTrainer),
                 "act": (ACTConfig(), ACTModel, ACTPolicy, ACTTrainer)}
    for name, (bcfg, model_cls, policy_cls, _) in baselines.items():
        torch.manual_seed(0)
        bmodel = model_cls(bcfg)
        results[name] = closed_loop(policy_cls.from_model(bmodel), frames, args.steps)
        results[name]["params"] = sum(p.numel() for p in bmodel.parameters())

    # --- training, on every core
    torch.set_num_threads(cores)
    torch.manual_seed(0)
    mem0_trainer = Mem0Trainer(Mem0Model(cfg, describe["executor_texts"], describe["planner_texts"],
                                         None), args.batch, task.tmc == "M(n)", 0)
    results["mem0"].update(train_speed(mem0_trainer, batch_from(frames, cfg, 1, cfg.horizon,
                                                                  args.batch),
                                       args.train_steps))
    for name, (bcfg, model_cls, _, trainer_cls) in baselines.items():
        trainer = trainer_cls(model_cls(bcfg), 0)
        results[name].update(train_speed(trainer, batch_from(frames, bcfg, bcfg.obs_steps,
                                                             bcfg.horizon, args.batch),
                                         args.train_steps))

    result = {"task": task.name, "cameras": list(cfg.cameras), "image_size": list(cfg.image_size),
              "inference_threads": 1, "training_threads": cores, "batch_size": args.batch,
              "steps": args.steps, "train_steps": args.train_steps, "set": args.set,
              "policies": results}
    print(f"{'policy':<8}{'params':>10}{'step (1 core)':>16}{'Hz':>8}{'RSS growth':>12}"
          f"{f'train steps/s ({cores} cores, batch {args.batch})':>34}")
    for name, r in results.items():
        print(f"{name:<8}{r['params'] / 1e6:>9.2f}M{r['step_ms']:>13.1f} ms{r['hz']:>8.1f}"
              f"{r['rss_growth_mb']:>9.1f} MB{r['train_steps_per_s']:>34.2f}")
    print(f"Mem-0 planner call with 8 keys: {results['mem0']['planner_ms']:.1f} ms (target < 100); "
          f"memory store {results['mem0']['memory_store_floats']} floats (fixed size); "
          f"executor target >= 20 Hz")
    write_json(args.out or OUT, result, indent=2)
    print(f"wrote {args.out or OUT}")


if __name__ == "__main__":
    main()
