"""``rmbench eval``: a policy on expert-verified seeds of one or more tasks, resumable.

Layout of ``out``::

    run.json                   what was asked (policy, seed, episodes, instructions)
    <task>/episodes.jsonl      one record per episode, appended and flushed as it ends
    <task>/memory_reset-<name>.jsonl  the same seeds with a memory probe (--memory-reset)
    <task>/videos/seed-N.mp4   third-person videos (per --video)
    summary.json, summary.md   per-task success rate with its 95% interval, progress, and
                               each probe's rates with and without it and their difference

Records are appended in seed order whatever the worker count, so results are identical for
any number of workers or backend. Within a worker a policy with the batched form of the
interface (``policies/base.py``) plays ``batch`` episodes side by side (``eval/episode.py``);
one without it plays them one after another. A killed run re-run with the same arguments
keeps every complete record (a torn last line is dropped) and runs only the missing seeds;
a damaged record elsewhere is an error that leaves the file as it is.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tqdm import tqdm

from rmbench.eval.folder import check_identity, check_version
from rmbench.eval.probe import MemoryReset, arm_file, arm_name, compare
from rmbench.eval.records import EvalError, TaskResult, read_records, summarize
from rmbench.eval.seeds import verified_seeds
from rmbench.eval.summary import summary_markdown
from rmbench.eval.worker import close_worker, episodes_job, policy_batches
from rmbench.files import Locked, lock, write_atomic, write_json
from rmbench.parallel import Inline, check_backend, in_order, make_executor
from rmbench.policies.registry import check_policy, env_options, parse_spec
from rmbench.seeds import SPLITS
from rmbench.tasks import get_task
from rmbench.video_rule import keeps_video

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class EvalConfig:
    tasks: tuple[str, ...]
    policy: str
    out: str | Path
    episodes: int = 100
    seed: int = 0
    workers: int = 1
    backend: str = "local"
    video: str = "first:1"  # first:K | failures | none
    instructions: str = "seen"
    progress: bool = True
    seed_cache: str | Path | None = None
    seeds_of: str | Path | None = None
    """A dataset: run its demonstrations' seeds (the layouts a policy trained on, beside the
    held-out ones ``seed`` picks: the gap is what the policy memorised) instead of ``seed``'s."""
    split: str = "test"
    """The evaluation seed's episodes to run: "test", the ones a table reports, or
    "validation", disjoint from them, where recipes are chosen (``rmbench.seeds``)."""
    batch: int = 8
    """Episodes a worker plays side by side, asking the policy once per step for all of them,
    where the policy has the batched form (``policies/base.py``; others play one at a time).
    Not part of the folder's identity, like ``workers``. A seed's record does not depend on
    which seeds share its batch; Mem-0's numbers at another batch size differ in the last
    float bits, which a closed loop can carry into another episode (``policies/mem0/agent.py``):
    compare evaluations made at one batch size (1: as before batches)."""
    memory_reset: str | None = None
    """A memory probe (``eval/probe.py``: ``aliasing`` or ``every:K``): the same seeds run a
    second time with the policy reset there, into the folder's arm of that probe. Not part of
    the folder's identity: a probe is added to an evaluation already made."""

    def __post_init__(self):
        if not self.tasks:
            raise ValueError("no task to evaluate")
        object.__setattr__(self, "tasks", tuple(get_task(t).name for t in self.tasks))
        parse_spec(self.policy)  # unknown policy: one line listing the known ones
        if self.episodes < 1 or self.workers < 1 or self.batch < 1 or self.seed < 0:
            raise ValueError("episodes, workers and batch must be >= 1 and seed >= 0")
        check_backend(self.backend)  # (Ray missing: said before anything is written)
        if self.instructions not in ("seen", "unseen"):
            raise ValueError(f"instructions must be 'seen' or 'unseen', got {self.instructions!r}")
        if self.split not in SPLITS:
            raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {self.split!r}")
        self.video_rule(0, True)
        if self.memory_reset is not None:
            MemoryReset.parse(self.memory_reset)

    def video_rule(self, index: int, success: bool | None) -> bool:
        """Keep a video of the ``index``-th episode? (``success`` None: before it runs.)"""
        return keeps_video(self.video, index, success)

    def identity(self) -> dict[str, Any]:
        ident = {"policy": self.policy, "seed": self.seed, "episodes": self.episodes,
                 "instructions": self.instructions}
        if self.seeds_of is not None:  # (absent otherwise: earlier run.json files stay valid)
            ident["seeds_of"] = str(Path(self.seeds_of).resolve())
        if self.split != "test":  # (likewise: a test run's identity is what it was)
            ident["split"] = self.split
        return ident


def _check_inputs(cfg: EvalConfig) -> None:
    """What the evaluation reads before it writes anything: the policy spec (with a
    checkpoint, its config; a remote policy, its server's answer) and the datasets whose seeds
    it plays, so that a typo is a one-line error and not a folder of failed episodes."""
    check_policy(cfg.policy)
    env_options(cfg.policy)
    entry, arg = parse_spec(cfg.policy)
    source = arg if entry.name == "replay" else cfg.seeds_of
    if source is not None:
        for task in cfg.tasks:
            dataset_seeds(source, task)


LOCK = ".evaluating"  # held by the process evaluating into a folder


def evaluate(cfg: EvalConfig) -> dict[str, Any]:
    out = Path(cfg.out)
    _check_inputs(cfg)
    out.mkdir(parents=True, exist_ok=True)
    try:  # two runs appending to one folder would both play every seed it lacks
        held = lock(out / LOCK)
    except Locked as err:
        raise EvalError(f"{out} is being evaluated by another process ({err.holder or '?'}); "
                        f"wait for it, or evaluate into another --out") from None
    try:
        try:
            check_identity(out, cfg.identity())
        except Exception:  # a folder it refuses is left as it was
            (out / LOCK).unlink(missing_ok=True)
            raise
        results = {}
        for task in cfg.tasks:
            results[task] = _evaluate_task(cfg, task, out / task)
        summary = {"policy": cfg.policy, "seed": cfg.seed, "instructions": cfg.instructions,
                   "tasks": {t: r.__dict__ for t, r in results.items()}}
        write_json(out / "summary.json", summary, indent=2)
        write_atomic(out / "summary.md", summary_markdown(summary).encode())
        (out / LOCK).unlink(missing_ok=True)  # (a finished folder keeps no lock file)
    finally:
        held.close()
    return summary


def _evaluate_task(cfg: EvalConfig, task: str, folder: Path) -> TaskResult:
    folder.mkdir(parents=True, exist_ok=True)
    check_version(folder, task)
    entry, arg = parse_spec(cfg.policy)
    # one executor for the seed search and the episodes: its workers keep their env
    executor = make_executor(cfg.workers, cfg.backend, on_close=close_worker)
    try:
        if entry.name == "replay" or cfg.seeds_of is not None:
            seeds = dataset_seeds(arg if entry.name == "replay" else cfg.seeds_of, task)
            seeds = seeds[: cfg.episodes]
        else:
            seeds = verified_seeds(task, cfg.seed, cfg.episodes, cfg.seed_cache, executor,
                                   progress=cfg.progress, split=cfg.split)
        result = _run_episodes(cfg, task, folder, seeds, executor)
        if cfg.memory_reset is not None:
            _run_episodes(cfg, task, folder, seeds, executor, MemoryReset.parse(cfg.memory_reset))
    finally:
        executor.shutdown()
    plain = read_records(folder / "episodes.jsonl")
    for path in sorted(folder.glob(arm_file("*"))):
        probed = [r for r in read_records(path) if r["seed"] in set(seeds)]
        result.memory_reset[arm_name(path.name)] = compare(plain, probed)
    return result


def dataset_seeds(path: str | Path, task: str) -> list[int]:
    """The seeds a dataset of ``task`` was recorded on, in episode order, each once (a dataset
    of layout copies holds each several times; a one-line error for another task's)."""
    from rmbench.data.reader import Dataset

    ds = Dataset(path)
    if ds.task != task:
        raise EvalError(f"{path} holds {ds.task} demonstrations, not {task}")
    return list(dict.fromkeys(int(r["rmbench/seed"]) for r in ds.episodes))


def _run_episodes(cfg: EvalConfig, task: str, folder: Path, seeds: list[int],
                  executor, probe: MemoryReset | None = None) -> TaskResult:
    """The seeds' episodes not yet recorded, into the ordinary arm or ``probe``'s (whose
    episodes keep no video: the ordinary arm's show the same layouts)."""
    path = folder / (arm_file(probe.name) if probe else "episodes.jsonl")
    records = [r for r in read_records(path, repair=True) if r["seed"] in seeds]
    done = {r["seed"] for r in records}
    todo = [(i, s) for i, s in enumerate(seeds) if s not in done]
    n_todo = len(todo)
    n = job_count(cfg, task, len(todo), executor) if todo else 0
    jobs = [todo[k * len(todo) // n:(k + 1) * len(todo) // n] for k in range(n)]
    desc = f"{task} {cfg.policy}" + (f" memory reset {probe.spec}" if probe else "")
    bar = tqdm(total=len(seeds), initial=len(done), unit="ep", desc=desc,
               disable=not cfg.progress, dynamic_ncols=True)
    t0 = time.perf_counter()
    kept: set[int] = set()  # the seeds (by place) whose records are in the file
    f = open(path, "a", encoding="utf-8")  # each record appended, flushed and synced as kept

    def keep(i: int, rec: dict[str, Any]) -> None:
        if i in kept:
            return
        video = rec.pop("video")
        rec["video"] = None
        if video is not None and cfg.video_rule(i, rec["success"]):
            name = f"videos/seed-{rec['seed']}.mp4"
            write_atomic(folder / name, video)
            rec["video"] = name
        f.write(json.dumps(rec) + "\n")
        f.flush()
        os.fsync(f.fileno())
        kept.add(i)
        records.append(rec)
        bar.update(1)

    def as_they_end(job: list[tuple[int, int]]):
        """A job run in this process keeps its records as its episodes end, each once those
        before it in the job have: the file's order is the one kept when a job returns
        whole, and a run killed mid-job loses only its unfinished episodes, not the job."""
        ended: dict[int, dict[str, Any]] = {}
        first = [0]

        def on_record(k: int, rec: dict[str, Any]) -> None:
            ended[k] = rec
            while first[0] in ended:
                keep(job[first[0]][0], ended.pop(first[0]))
                first[0] += 1

        return on_record

    here = isinstance(executor, Inline)  # (a worker process's records come back with its job)
    calls = ((job, episodes_job, (task, cfg.policy, cfg.instructions, [s for _, s in job],
                                  [cfg.video_rule(i, None) and probe is None for i, _ in job],
                                  probe.spec if probe else None, cfg.batch,
                                  [i for i, _ in job], as_they_end(job) if here else None))
             for job in jobs)
    try:
        for job, recs in in_order(executor, calls):
            for (i, _), rec in zip(job, recs, strict=True):
                keep(i, rec)
            bar.set_postfix(success=f"{sum(r['success'] for r in records)}/{len(records)}",
                            refresh=False)
    finally:
        f.close()
        bar.close()
    log.info("%s: %d episodes in %.1fs", task, n_todo, time.perf_counter() - t0)
    order = {s: k for k, s in enumerate(seeds)}
    return summarize(task, sorted(records, key=lambda r: order[r["seed"]]))


# Batches a job holds: more seeds than slots keep the slots busy while episodes of other
# lengths end (a freed slot takes the next seed), fewer lose less to a kill where a worker
# process runs the job (its records come back when it returns; one in this process keeps
# them as they end) and leave work for every worker.
JOB_BATCHES = 4


def job_count(cfg: EvalConfig, task: str, todo: int, executor) -> int:
    """Worker jobs for ``todo`` seeds: one a seed for a policy without the batched form (its
    records are written as each episode ends, as before batches), else a multiple of
    ``workers`` jobs (one a seed where fewer seeds are left) of at most ``JOB_BATCHES``
    batches each, split evenly, so that no worker is left with a short last job while another
    runs a full one."""
    if cfg.batch == 1 or not executor.submit(policy_batches, task, cfg.policy,
                                             cfg.instructions).result():
        return todo
    return min(todo, cfg.workers * -(-todo // (cfg.workers * JOB_BATCHES * cfg.batch)))


