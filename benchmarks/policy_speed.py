"""Policy speed on CPU: Mem-0's executor steps/s on one core with the default camera set, the
planner's latency, and whether memory per step stays bounded.

    python benchmarks/policy_speed.py [--steps 300] [--task press_button]

The model is Mem-0's default configuration with random weights (speed does not depend on the
weights). Observations are real renders of the task's station (three cameras at 320x240),
resized by the policy as in evaluation. Prints a table and writes
benchmarks/results/policy_speed.json.
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

import numpy as np
import torch

import rmbench
from rmbench.policies.mem0.agent import Mem0Policy
from rmbench.policies.mem0.config import Mem0Config
from rmbench.policies.mem0.modeling import Mem0Model
from rmbench.policies.mem0.planner import DONE
from rmbench.policies.mem0.train import goal_text
from rmbench.tasks import get_task

OUT = Path(__file__).parent / "results" / "policy_speed.json"


def rss_mb() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--task", default="press_button")
    args = ap.parse_args()
    torch.set_num_threads(1)  # one core, as the target says
    cfg = Mem0Config()
    task = get_task(args.task)
    subtasks = list(task.subtasks)
    describe = {"policy": "mem0", "task": task.name, "tmc": task.tmc,
                "executor_texts": subtasks + [goal_text(task.name)],
                "planner_texts": subtasks + [DONE], "text_encoder": "learned"}
    torch.manual_seed(0)
    model = Mem0Model(cfg, describe["executor_texts"], describe["planner_texts"], None)
    policy = Mem0Policy.from_model(model, describe)
    env = rmbench.make(task.name, cameras=cfg.cameras)
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    frames = [obs]
    for _ in range(20):  # a few distinct frames to cycle through
        obs, *_ = env.step(env.action_space.sample())
        frames.append(obs)
    env.close()

    for k in range(20):  # warm-up
        policy.act(frames[k % len(frames)])
    rss0 = rss_mb()
    t0 = time.perf_counter()
    for k in range(args.steps):
        policy.act(frames[k % len(frames)])
    step_s = (time.perf_counter() - t0) / args.steps
    rss1 = rss_mb()

    # the planner with a full key memory of 8 finished subtasks
    imgs = policy.images(frames[0])
    planner_cams = [imgs[i] for i in policy.planner_cams]
    with torch.no_grad():
        policy.first = model.planner.embed(planner_cams)
        policy.keys = [(k % len(subtasks), model.planner.embed(planner_cams)[0]) for k in range(8)]
        for _ in range(3):
            policy.subtask_ended(imgs)
        n, t0 = 20, time.perf_counter()
        for _ in range(n):
            policy.keys = policy.keys[:8]
            policy.subtask_ended(imgs)  # embeds the end frame, stores it, plans
        plan_s = (time.perf_counter() - t0) / n

    params = sum(p.numel() for p in model.executor.parameters())
    result = {
        "task": task.name, "cameras": list(cfg.cameras), "image_size": list(cfg.image_size),
        "threads": 1, "steps": args.steps, "executor_params": params,
        "executor_step_ms": round(1000 * step_s, 2), "executor_hz": round(1 / step_s, 1),
        "planner_ms": round(1000 * plan_s, 2), "rss_growth_mb": round(rss1 - rss0, 1),
        "memory_store_floats": int(policy.memory.anchor.numel() + policy.memory.sliding.numel()),
    }
    rows = [("executor step (1 core)", f"{result['executor_step_ms']:.1f} ms",
             f"{result['executor_hz']:.1f} Hz (target >= 20)"),
            ("planner call (8 keys)", f"{result['planner_ms']:.1f} ms", "target < 100 ms"),
            (f"RSS growth over {args.steps} steps", f"{result['rss_growth_mb']:.1f} MB",
             "bounded memory"),
            ("memory store", f"{result['memory_store_floats']} floats", "fixed size")]
    w = max(len(r[0]) for r in rows)
    for r in rows:
        print(f"{r[0]:<{w}}  {r[1]:>14}  {r[2]}")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {OUT}")
    assert np.isfinite(result["executor_step_ms"])


if __name__ == "__main__":
    main()
