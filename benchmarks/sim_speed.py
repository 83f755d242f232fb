"""Simulation speed: env steps/s with the default three cameras vs the bare MuJoCo render of the
same cameras, and physics-only steps/s, all in one run.

    .venv/bin/python benchmarks/sim_speed.py [--task put_back_block] [--steps 200] [--out FILE]

Prints a table and writes JSON (default benchmarks/results/sim_speed.json).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import rmbench  # before anything imports mujoco: it picks the OpenGL backend
from rmbench.experts import make_expert
from rmbench.files import write_json
from rmbench.machine import describe
from rmbench.sim.simulator import data_renderer


def expert_actions(task: str, seed: int, steps: int):
    env = rmbench.make(task, render=False)
    expert = make_expert(env)
    obs, info = env.reset(seed=seed)
    expert.reset(info["instruction"], info)
    actions = []
    for _ in range(steps):
        actions.append(expert.act(obs))
        obs, _, terminated, truncated, _ = env.step(actions[-1])
        if terminated or truncated:
            obs, info = env.reset(seed=seed)
            expert.reset(info["instruction"], info)
    env.close()
    return actions


def time_env(task: str, seed: int, actions, render: bool) -> float:
    env = rmbench.make(task, render=render)
    env.reset(seed=seed)
    env.step(actions[0])  # warm-up: renderer creation
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset(seed=seed)
    rate = len(actions) / (time.perf_counter() - t0)
    env.close()
    return rate


def time_bare_render(task: str, seed: int, n: int) -> float:
    env = rmbench.make(task, render=True)
    env.reset(seed=seed)
    sim = env.unwrapped.sim
    renderer = data_renderer(sim.model, sim.config.width, sim.config.height)
    t0 = time.perf_counter()
    for _ in range(n):
        for cam in sim.config.cameras:
            renderer.update_scene(sim.data, camera=cam)
            renderer.render()
    rate = n / (time.perf_counter() - t0)
    renderer.close()
    env.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="put_back_block")
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--seed", type=int, default=100000)
    parser.add_argument("--out", default="benchmarks/results/sim_speed.json")
    args = parser.parse_args()

    actions = expert_actions(args.task, args.seed, args.steps)
    env_render = time_env(args.task, args.seed, actions, render=True)
    bare = time_bare_render(args.task, args.seed, args.steps)
    physics = time_env(args.task, args.seed, actions, render=False)
    result = {
        "task": args.task, "steps": args.steps, "cameras": list(rmbench.sim.station.DEFAULT_CAMERAS),
        "resolution": "320x240", "gl_backend": os.environ.get("MUJOCO_GL"),
        "env_steps_per_s_rendered": round(env_render, 1),
        "bare_render_sets_per_s": round(bare, 1),
        "ratio_env_to_bare_render": round(env_render / bare, 3),
        "env_steps_per_s_physics_only": round(physics, 1),
        "machine": describe(),
    }
    rows = [("env step, 3 cameras rendered", f"{env_render:8.1f} steps/s"),
            ("bare MuJoCo render, same 3 cameras", f"{bare:8.1f} sets/s"),
            ("ratio env / bare render (target >= 0.7)", f"{env_render / bare:8.3f}"),
            ("env step, physics only (no render)", f"{physics:8.1f} steps/s")]
    width = max(len(r[0]) for r in rows)
    print(f"sim speed, task {args.task}, {args.steps} expert steps, MUJOCO_GL={result['gl_backend']}")
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_json(out, result, indent=2)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
