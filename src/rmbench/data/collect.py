"""Collecting expert demonstrations of a task into a dataset, in parallel, resumable.

Candidate seeds are tried in order from ``seed``; the n-th demonstration is the n-th seed the
expert solves. Workers may finish out of order, but results are committed in seed order, so
the dataset (episode order and content) is the same whatever the number of workers.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from rmbench.data import layout as L
from rmbench.data.record import SEARCH_MODES, EpisodeRecord, Recorder
from rmbench.data.writer import DatasetWriter
from rmbench.envs.noise import NoiseSpec
from rmbench.parallel import check_backend, make_executor
from rmbench.seeds import TRAIN_SEED_END, check_training_seed
from rmbench.sim.station import ALL_CAMERAS, StationConfig
from rmbench.tasks import get_task

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CollectConfig:
    """Arguments of ``rmbench collect``. Everything but ``episodes``, ``workers``, ``backend``,
    ``search`` and ``progress`` is part of a dataset's identity and must match to resume."""

    task: str
    out: str | Path
    episodes: int = 50
    seed: int = 0
    cameras: tuple[str, ...] = StationConfig().cameras
    width: int = 320
    height: int = 240
    workers: int = 1
    search: str = "search"
    backend: str = "local"
    overwrite: bool = False
    max_attempts: int | None = None  # candidate seeds to try before giving up
    progress: bool = True
    # Action noise executed on top of the expert's actions (DART); the expert's own actions
    # are recorded. sigma 0 (the default) records clean demonstrations.
    noise: NoiseSpec = NoiseSpec()

    def __post_init__(self):
        object.__setattr__(self, "task", get_task(self.task).name)
        object.__setattr__(self, "cameras", tuple(self.cameras))
        check_training_seed(self.seed)
        if self.episodes < 1:
            raise ValueError(f"episodes must be at least 1, got {self.episodes}")
        if self.workers < 1:
            raise ValueError(f"workers must be at least 1, got {self.workers}")
        if self.search not in SEARCH_MODES:
            raise ValueError(f"search must be one of {SEARCH_MODES}, got {self.search!r}")
        check_backend(self.backend)  # (Ray missing: said before anything is written)
        unknown = sorted(set(self.cameras) - set(ALL_CAMERAS))
        if unknown:
            raise ValueError(f"unknown camera(s) {unknown}; cameras: {list(ALL_CAMERAS)}")
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"cameras named twice: {list(self.cameras)}")
        L.Spec(self.cameras, self.width, self.height)  # validates the resolution

    @property
    def spec(self) -> L.Spec:
        return L.Spec(self.cameras, self.width, self.height)

    def identity(self) -> dict:
        """What must match for a re-run to continue an existing dataset."""
        identity = {"task": self.task, "seed": self.seed, "cameras": list(self.cameras),
                    "resolution": f"{self.width}x{self.height}", "fps": self.spec.fps,
                    "codec": self.spec.codec.info()}
        if self.noise.active:  # clean datasets keep the identity they always had
            identity["action_noise"] = self.noise.to_dict()
        return identity


@dataclass
class CollectSummary:
    root: str
    task: str
    episodes: int
    new_episodes: int
    frames: int
    skipped: list[dict]
    wall_s: float
    demos_per_min: float

    def to_dict(self) -> dict:
        return dict(self.__dict__)


# One Recorder per worker process, built on first use (envs take a while to compile).
_RECORDER: Recorder | None = None


def _record(task: str, spec: L.Spec, mode: str, seed: int,
            noise: NoiseSpec | None = None) -> EpisodeRecord:
    global _RECORDER
    key = (task, spec, mode, noise if noise is not None and noise.active else None)
    if _RECORDER is None or (_RECORDER.task, _RECORDER.spec, _RECORDER.mode,
                             _RECORDER.noise) != key:
        if _RECORDER is not None:
            _RECORDER.close()
        _RECORDER = Recorder(task, spec, mode, noise)
    return _RECORDER.record(seed)


def _close_recorder() -> None:
    global _RECORDER
    if _RECORDER is not None:
        _RECORDER.close()
        _RECORDER = None


def collect(cfg: CollectConfig) -> CollectSummary:
    """Collect ``cfg.episodes`` demonstrations into ``cfg.out`` (continuing what is there)."""
    t0 = time.perf_counter()
    writer = DatasetWriter(cfg.out, cfg.task, cfg.spec, cfg.identity(), overwrite=cfg.overwrite)
    start_episodes = writer.num_episodes
    if start_episodes > cfg.episodes:
        writer.close()
        raise ValueError(f"{cfg.out} already holds {start_episodes} episodes, more than the "
                         f"{cfg.episodes} asked; ask for at least {start_episodes}")
    max_attempts = cfg.max_attempts or 10 * cfg.episodes + 20
    attempts = writer.num_episodes + len(writer.skipped)
    try:
        executor = make_executor(cfg.workers, cfg.backend, on_close=_close_recorder)
    except BaseException:
        writer.close()
        raise
    window = executor.window
    pending: deque = deque()  # (seed, job), in seed order
    next_seed = writer.next_seed
    bar = tqdm(total=cfg.episodes, initial=start_episodes, unit="demo", disable=not cfg.progress,
               desc=cfg.task, dynamic_ncols=True)
    done_new = 0
    try:
        while writer.num_episodes < cfg.episodes:
            while len(pending) < window and attempts + len(pending) < max_attempts:
                if next_seed >= TRAIN_SEED_END:
                    break
                pending.append((next_seed, executor.submit(_record, cfg.task, cfg.spec,
                                                           cfg.search, next_seed, cfg.noise)))
                next_seed += 1
            if not pending:
                raise RuntimeError(
                    f"{cfg.task}: the expert solved {writer.num_episodes} of {attempts} seeds "
                    f"tried, short of {cfg.episodes}; see the skipped seeds in "
                    f"{Path(cfg.out) / L.RMBENCH}")
            seed, job = pending.popleft()
            rec = job.result()
            attempts += 1
            if rec.success:
                writer.commit(rec)
                done_new += 1
                bar.update(1)
            else:
                writer.skip(seed, rec.reason)
            minutes = (time.perf_counter() - t0) / 60
            bar.set_postfix(demos_min=f"{done_new / max(minutes, 1e-9):.1f}",
                            skipped=len(writer.skipped), refresh=False)
    finally:
        bar.close()
        executor.shutdown()
        writer.close()
    wall = time.perf_counter() - t0
    return CollectSummary(str(writer.root), cfg.task, writer.num_episodes, done_new,
                          writer.total_frames, writer.skipped, round(wall, 2),
                          round(60 * done_new / wall, 2) if done_new else 0.0)
