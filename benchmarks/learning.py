"""Learning curve in one command: collect demonstrations of a task, train each policy on them
from the state observation or from the cameras, evaluate each on expert-verified seeds, and
tabulate what each learned with which memory.

    .venv/bin/python benchmarks/learning.py --task put_back_block --obs state \\
        [--policies mem0,mem0:no_memory,mem0:no_anchor,mem0:no_sliding,dp,act] [--demos 50] \\
        [--steps 3000] [--batch 32] [--episodes 100] [--noise SIGMA --noise-kind white|smooth] \\
        [--set FIELD=VALUE ...] [--out runs/learning/state_put_back_block] [--workers 1] \\
        [--threads N] [--jobs N]

``--set`` overrides a field of every trained policy's config that has it (as ``rmbench train
--set``; a field no policy has is an error), e.g. ``--set head_layers=2 --set execute=20``;
the overrides name the training and evaluation folders, so runs with different ones coexist.

Checked end to end at toy scale (40 s on a loaded 2-core machine)::

    .venv/bin/python benchmarks/learning.py --task observe_and_pickup --obs state \\
        --policies mem0,mem0:no_memory,dp,act --demos 3 --steps 20 --episodes 2 \\
        --out /tmp/learning --results /tmp/learning/result.json

With ``--jobs 2`` the same toy run trains and evaluates both policies at once, one process
and one torch thread each (2 min 34 s beside two training runs).

Every stage resumes, so a re-run after an interruption does only what is missing:

- collection (``rmbench.data.collect``) continues the dataset in ``OUT/data``. With ``--obs
  state`` it records the smallest video collection allows (the head camera at 16x16; datasets
  hold at least one camera) beside ``observation.environment_state``, and the policies are
  trained with ``observation="state"``: no frame is decoded. With ``--obs pixels`` it records
  the three cameras at 320x240, as evaluation renders them;
- training (the shared loop) continues from ``OUT/train/<policy>-s<steps>-b<batch>``'s last
  saved state (every 500 steps); a finished run is not touched;
- evaluation (the harness) runs only the seeds missing from ``OUT/eval/<run>-e<episodes>``;
  the env gets the observation each checkpoint declares (the state for a state checkpoint).

Wall times are the sums over the calls that completed a stage's piece (a call killed midway
loses its own time, not what it saved). Writes ``benchmarks/results/learning_<obs>_<task>.json``
(or ``--results``): the command, and per policy its success rate, mean progress, endings (how
episodes ended, failure reasons counted), training and evaluation wall times and its memory.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path

import rmbench  # noqa: F401  (before mujoco: picks the OpenGL backend)
from rmbench.data import CollectConfig, collect
from rmbench.data.reader import Dataset
from rmbench.envs.noise import NoiseSpec
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.episode import ENDINGS
from rmbench.tasks import get_task
from rmbench.video import write_atomic

ROOT = Path(__file__).resolve().parent
POLICIES = ("mem0", "mem0:no_memory", "mem0:no_anchor", "mem0:no_sliding", "dp", "act")
STATE_CAMERAS, STATE_SIZE = ("head",), (16, 16)  # what collection must record at least
PIXEL_CAMERAS, PIXEL_SIZE = ("head", "left_wrist", "right_wrist"), (320, 240)


def parse_policy(spec: str) -> tuple[str, tuple[str, ...]]:
    """``mem0:no_memory`` -> ("mem0", ("no_memory",)); ``dp`` -> ("dp", ())."""
    name, _, ablations = spec.partition(":")
    if name not in ("mem0", "dp", "act"):
        raise SystemExit(f"unknown policy {spec!r}; policies: {', '.join(POLICIES)}")
    ablations = tuple(a for a in ablations.split("+") if a)
    if ablations and name != "mem0":
        raise SystemExit(f"{spec}: only Mem-0 has ablations")
    return name, ablations


def memory_of(spec: str, tmc: str, cfg) -> str:
    """What carries information across steps in this policy (``cfg``, its config), in words."""
    name, _ = parse_policy(spec)
    if name == "dp":
        return f"observation window only ({cfg.obs_steps} steps)"
    if name == "act":
        return "observation window only (1 step; temporal ensembling averages past chunks)"
    parts = []
    if tmc == "M(n)":
        parts.append("planner phase (subtask text" + (" + key memory)" if cfg.use_key else ")"))
    if cfg.use_anchor:
        parts.append("anchor (subtask's first step)")
    if cfg.use_sliding:
        parts.append(f"sliding window ({cfg.sliding_window} x {cfg.memory_every} steps)")
    return " + ".join(parts) or "current step only"


def run_name(spec: str, steps: int, batch: int, sets: list[str] = ()) -> str:
    tag = "".join(f"-{s.replace('=', '')}" for s in sets)
    return f"{spec.replace(':', '-')}-s{steps}-b{batch}{tag}".replace("/", "_").replace('"', "")


def config_for(name: str, obs: str, sets: list[str], ablations: tuple[str, ...] = ()):
    """The policy's config with ``observation`` and the ``--set`` fields it has."""
    from dataclasses import fields

    from rmbench.cli.train import parse_overrides, trainable

    cls, _ = trainable(name)
    names = {f.name for f in fields(cls)}
    mine = [s for s in sets if s.partition("=")[0] in names]
    extra = {"ablations": ablations} if ablations else {}
    try:
        return cls(**{"observation": obs, **parse_overrides(cls, mine), **extra})
    except (TypeError, ValueError) as err:
        raise SystemExit(f"{name} with {' '.join(mine) or 'its defaults'}: {err}") from None


def check_sets(sets: list[str]) -> None:
    from dataclasses import fields

    from rmbench.cli.train import TRAINABLE, trainable

    known = {f.name for name in TRAINABLE for f in fields(trainable(name)[0])}
    for s in sets:
        key, sep, _ = s.partition("=")
        if not sep or key not in known:
            raise SystemExit(f"--set {s!r}: expected FIELD=VALUE with a field of a policy's "
                             f"config; fields: {', '.join(sorted(known))}")


def read_json(path: Path, default):
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return default


def add_time(folder: Path, key: str, seconds: float) -> None:
    """Accumulate a stage's wall time in ``folder/timing.json``."""
    path = folder / "timing.json"
    timing = read_json(path, {})
    timing[key] = round(timing.get(key, 0.0) + seconds, 1)
    folder.mkdir(parents=True, exist_ok=True)
    write_atomic(path, (json.dumps(timing, indent=1) + "\n").encode())


def collect_stage(args, out: Path) -> dict:
    state = args.obs == "state"
    cameras, (width, height) = (STATE_CAMERAS, STATE_SIZE) if state else (PIXEL_CAMERAS, PIXEL_SIZE)
    root = out / "data"
    done = (root / "meta" / "info.json").exists() and Dataset(root).num_episodes >= args.demos
    if not done:
        t0 = time.perf_counter()
        collect(CollectConfig(args.task, root, episodes=args.demos, seed=0, cameras=cameras,
                              width=width, height=height, workers=args.workers,
                              noise=NoiseSpec(args.noise_kind, args.noise), progress=True))
        add_time(out, "collect_wall_s", time.perf_counter() - t0)
    ds = Dataset(root)
    return {"path": str(root), "episodes": ds.num_episodes, "frames": ds.num_frames,
            "cameras": list(ds.cameras), "resolution": f"{width}x{height}",
            "environment_state": ds.state_names is not None,
            "collect_wall_s": read_json(out / "timing.json", {}).get("collect_wall_s")}


def train_stage(args, spec: str, cfg, data: Path, folder: Path) -> None:
    describe = read_json(folder / "config.json", {})
    if describe.get("step") == args.steps:
        return
    from rmbench.cli.train import trainable
    from rmbench.training.loop import TrainConfig

    train_cfg = TrainConfig(steps=args.steps, batch_size=args.batch, seed=0,
                            save_every=min(500, args.steps))
    _, fit = trainable(parse_policy(spec)[0])
    t0 = time.perf_counter()
    fit(data, folder, cfg, train_cfg)
    add_time(folder, "train_wall_s", time.perf_counter() - t0)


def eval_stage(args, spec: str, ckpt: Path, folder: Path) -> dict:
    name, _ = parse_policy(spec)
    summary = read_json(folder / "summary.json", {})
    result = summary.get("tasks", {}).get(get_task(args.task).name)
    if result is None or result["episodes"] < args.episodes:
        t0 = time.perf_counter()
        summary = evaluate(EvalConfig((args.task,), f"{name}:{ckpt}", folder,
                                      episodes=args.episodes, workers=args.workers,
                                      video="none", progress=True))
        add_time(folder, "eval_wall_s", time.perf_counter() - t0)
        result = summary["tasks"][get_task(args.task).name]
    return result


def failure_reasons(folder: Path) -> dict[str, int]:
    """How the failed episodes ended, by the message the task or the harness gave, most
    frequent first ("timeout" for an episode that ran out of steps)."""
    from collections import Counter

    from rmbench.eval.harness import read_records

    counts = Counter(r["message"] or r["reason"] for r in read_records(folder / "episodes.jsonl")
                     if not r["success"])
    return dict(counts.most_common())


def table(rows: dict[str, dict]) -> str:
    head = (f"{'policy':<18} {'success':>8} {'progress':>9} {'train s':>8} {'eval s':>8}  "
            + " ".join(f"{e[:8]:>8}" for e in ENDINGS) + "  memory")
    lines = [head, "-" * len(head)]
    for spec, r in rows.items():
        lines.append(f"{spec:<18} {100 * r['success_rate']:>7.1f}% {r['mean_progress']:>9.3f} "
                     f"{r['train_wall_s'] or 0:>8.0f} {r['eval_wall_s'] or 0:>8.0f}  "
                     + " ".join(f"{r['endings'].get(e, 0):>8}" for e in ENDINGS)
                     + f"  {r['memory']}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--task", required=True)
    p.add_argument("--obs", choices=("state", "pixels"), required=True)
    p.add_argument("--policies", default=",".join(POLICIES),
                   help="comma-separated: mem0, mem0:ABLATION (no_memory, no_anchor, "
                        "no_sliding, no_key), dp, act")
    p.add_argument("--demos", type=int, default=50)
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--noise", type=float, default=0.0,
                   help="action noise executed during collection (DART), radians")
    p.add_argument("--noise-kind", choices=("white", "smooth"), default="white")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a policy config field (VALUE as JSON), repeatable")
    p.add_argument("--out", type=Path, default=None,
                   help="data, checkpoints and evaluations (default runs/learning/<obs>_<task>)")
    p.add_argument("--results", type=Path, default=None,
                   help="the JSON written (default benchmarks/results/learning_<obs>_<task>.json)")
    p.add_argument("--workers", type=int, default=1, help="processes for collection and evaluation")
    p.add_argument("--threads", type=int, default=None, help="torch threads for training")
    p.add_argument("--jobs", type=int, default=1,
                   help="policies trained and evaluated at once, each in its own process with "
                        "cores / jobs torch threads (logs in OUT/jobs)")
    args = p.parse_args(argv)
    if args.jobs < 1:
        raise SystemExit("--jobs must be >= 1")
    args.task = get_task(args.task).name
    tmc = get_task(args.task).tmc
    specs = [s.strip() for s in args.policies.split(",") if s.strip()]
    check_sets(args.set)
    # every config is built before anything runs: a bad one stops here
    configs = {}
    for s in specs:
        name, ablations = parse_policy(s)
        configs[s] = config_for(name, args.obs, args.set, ablations)
    tag = f"{args.obs}_{args.task}" + (f"_{args.noise_kind}{args.noise:g}" if args.noise else "")
    out = args.out or ROOT.parent / "runs" / "learning" / tag
    results_path = args.results or ROOT / "results" / f"learning_{tag}.json"
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)

    dataset = collect_stage(args, out)
    if args.jobs > 1 and len(specs) > 1:
        threads = max(1, (os.cpu_count() or 1) // args.jobs)
        rows = run_jobs(args, specs, out, threads)
    else:
        import torch

        threads = torch.get_num_threads()
        rows = {spec: run_policy(args, spec, configs[spec], out, tmc) for spec in specs}
    command = "python benchmarks/learning.py " + " ".join(
        shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    result = {"command": command, "task": args.task, "tmc": tmc, "obs": args.obs,
              "demos": args.demos, "steps": args.steps, "batch": args.batch, "set": args.set,
              "episodes": args.episodes,
              "noise": NoiseSpec(args.noise_kind, args.noise).to_dict() if args.noise else None,
              "dataset": dataset, "policies": rows,
              "machine": {"cpu": platform.processor() or platform.machine(),
                          "cores": os.cpu_count(), "jobs": args.jobs, "torch_threads": threads}}
    results_path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(results_path, (json.dumps(result, indent=1) + "\n").encode())
    print(table(rows))
    print(f"wrote {results_path}")
    return 0


def run_policy(args, spec: str, cfg, out: Path, tmc: str) -> dict:
    """Train and evaluate one policy (config ``cfg``; each stage resumes); its row of the
    results."""
    run = run_name(spec, args.steps, args.batch, args.set)
    ckpt, evals = out / "train" / run, out / "eval" / f"{run}-e{args.episodes}"
    print(f"== {spec}: training into {ckpt}", flush=True)
    train_stage(args, spec, cfg, out / "data", ckpt)
    print(f"== {spec}: evaluating on {args.episodes} episodes into {evals}", flush=True)
    r = eval_stage(args, spec, ckpt, evals)
    return {"success_rate": r["success_rate"], "mean_progress": r["mean_progress"],
            "episodes": r["episodes"], "endings": r["endings"],
            "failure_reasons": failure_reasons(evals / args.task),
            "train_wall_s": read_json(ckpt / "timing.json", {}).get("train_wall_s"),
            "eval_wall_s": read_json(evals / "timing.json", {}).get("eval_wall_s"),
            "memory": memory_of(spec, tmc, cfg), "checkpoint": str(ckpt),
            "evaluation": str(evals)}


def job_command(args, spec: str, out: Path, results: Path, threads: int) -> list[str]:
    """This script for one policy, with the parent's settings (the data is collected)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--task", args.task, "--obs", args.obs,
           "--policies", spec, "--demos", str(args.demos), "--steps", str(args.steps),
           "--batch", str(args.batch), "--episodes", str(args.episodes),
           "--noise", repr(args.noise), "--noise-kind", args.noise_kind, "--out", str(out),
           "--results", str(results), "--workers", str(args.workers), "--threads", str(threads)]
    for item in args.set:
        cmd += ["--set", item]
    return cmd


def run_jobs(args, specs: list[str], out: Path, threads: int) -> dict[str, dict]:
    """Each policy in its own process, ``args.jobs`` at a time, each with ``threads`` torch
    threads; logs and per-policy results in ``OUT/jobs``. Their rows, in ``specs`` order."""
    import subprocess

    folder = out / "jobs"
    folder.mkdir(parents=True, exist_ok=True)
    pending, running, rows = list(specs), {}, {}
    try:
        while pending or running:
            while pending and len(running) < args.jobs:
                spec = pending.pop(0)
                name = spec.replace(":", "-")
                log = (folder / f"{name}.log").open("a")
                proc = subprocess.Popen(job_command(args, spec, out, folder / f"{name}.json",
                                                    threads), stdout=log, stderr=subprocess.STDOUT)
                running[spec] = (proc, log, name)
                print(f"== {spec}: started (log {folder / (name + '.log')})", flush=True)
            time.sleep(2)
            for spec, (proc, log, name) in list(running.items()):
                if proc.poll() is None:
                    continue
                log.close()
                del running[spec]
                if proc.returncode:
                    raise SystemExit(f"{spec} failed (exit {proc.returncode}): see "
                                     f"{folder / (name + '.log')}; a re-run resumes it")
                rows[spec] = read_json(folder / f"{name}.json", {})["policies"][spec]
                print(f"== {spec}: done", flush=True)
    finally:
        for proc, log, _ in running.values():  # interrupted: the jobs stop, their work resumes
            proc.terminate()
            proc.wait()
            log.close()
    return {s: rows[s] for s in specs}


if __name__ == "__main__":
    raise SystemExit(main())
