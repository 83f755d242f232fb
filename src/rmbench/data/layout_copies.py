"""Rendered layout copies: a dataset of each demonstration and copies of it with the scene moved.

``data/layout_shift.py`` gives a state-observation policy more layouts from the same
demonstrations: each one copied with every position of the environment state moved by
(dx, dy) and the arms' joints solved for the moved grasp poses. A pixel policy reads the
cameras, so its copies must be rendered. Here each demonstration is replayed from its seed
(the executed actions re-drawn from the dataset's noise spec, every frame checked against the
recorded state by ``record.replay``, as a collection's recorded pass is), and at every frame
each copy is drawn from a second ``MjData``: the recorded state with every scene piece moved
by the copy's shift (free pieces through their joints, fixed ones through ``model.body_pos``,
put back after the frame) and the arms at the copy's solved joints, the grippers as recorded.

The output is an ordinary dataset: per source episode, the episode itself (copy 0: its rows,
videos and image statistics the source's own) and then its kept copies, each committed through
``DatasetWriter`` with the copy's joints, actions, grasp poses, environment state and frames.
Each copy's ``hidden`` adds ``layout_copy`` (source episode, copy number, shift); the task's
own hidden entries are the source's. A copy out of the arms' reach is left out.

Like the state copies this is kinematics only: what the recorded arm motion looks like over
the moved scene, not a new simulation. Shifts are drawn per source episode from
``[seed, episode]``, so an interrupted run resumes after its last committed copy and writes
the same dataset.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path

import mujoco
import numpy as np
from tqdm import tqdm

from rmbench.data import layout as L
from rmbench.data.layout_shift import LayoutShift
from rmbench.data.reader import Dataset, Episode
from rmbench.data.record import EpisodeRecord, ImageStats, ReplayMismatch, executed_action, replay
from rmbench.data.writer import DatasetError, DatasetWriter
from rmbench.envs.noise import NoiseSpec, perturber
from rmbench.envs.registration import make
from rmbench.parallel import check_backend, in_order, make_executor
from rmbench.sim import robot
from rmbench.sim.fixtures import StaticPiece
from rmbench.sim.objects import FreePiece
from rmbench.video import Mp4Encoder

log = logging.getLogger(__name__)

COPY_KEY = "layout_copy"  # the hidden entry naming a copy's source episode, number and shift


@dataclass
class CopySummary:
    root: str
    source_episodes: int
    episodes: int
    new_episodes: int
    out_of_reach: int
    frames: int
    wall_s: float

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def shifts(seed: int, episode: int, copies: int, reach: float) -> np.ndarray:
    """(copies + 1, 2) shifts of one source episode: copy 0 (the episode itself) at (0, 0),
    the others ~ U[-reach, reach]^2 from the generator ``[seed, episode]``."""
    out = np.zeros((copies + 1, 2))
    out[1:] = np.random.default_rng([seed, episode]).uniform(-reach, reach, (copies, 2))
    return out


class SceneShift:
    """Draws one env's current state with its scene moved: a second MjData of the same model."""

    def __init__(self, env):
        self.sim, self.task = env.unwrapped.sim, env.unwrapped.task
        self.data = mujoco.MjData(self.sim.model)
        other = [p for p in self.task.pieces if not isinstance(p, FreePiece | StaticPiece)]
        if other:
            raise DatasetError(f"{self.task.name}: layout copies move free and fixed pieces; "
                               f"{type(other[0]).__name__} is neither")
        # A piece with a free joint moves through it; every other one (fixtures, and fixed
        # display copies such as observe_and_pickup's reference) through its body's position.
        free = [p for p in self.task.pieces if isinstance(p, FreePiece) and p.qpos_adr >= 0]
        self.free_xy = np.array([(p.qpos_adr, p.qpos_adr + 1) for p in free],
                                np.int64).reshape(-1, 2)
        self.bodies = np.array([p.body_id for p in self.task.pieces if p not in free], np.int64)

    def render(self, renderer: mujoco.Renderer, cameras, joints: np.ndarray,
               delta: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Frames of ``cameras`` and the grasp poses (14,) with the scene moved by ``delta`` and
        the arms at ``joints`` (the 14-vector layout; the grippers stay as they are)."""
        sim, d, model = self.sim, self.data, self.sim.model
        mujoco.mj_copyData(d, model, sim.data)
        for k, side in enumerate(robot.SIDES):
            d.qpos[sim.arm_qpos[side]] = joints[7 * k: 7 * k + 6]
        d.qpos[self.free_xy] += delta
        saved = model.body_pos[self.bodies].copy()
        try:
            model.body_pos[self.bodies, :2] += delta
            mujoco.mj_forward(model, d)
            frames = {}
            for cam in cameras:
                renderer.update_scene(d, camera=cam)
                frames[cam] = renderer.render()
        finally:  # the replay's own physics reads the model next
            model.body_pos[self.bodies] = saved
        return frames, sim.ee_pose(d)


def _recorded_as(src: Dataset) -> tuple[L.Spec, NoiseSpec | None]:
    """The cameras, resolution and action noise ``src`` was collected with; a DatasetError if
    it was recorded at a frame rate or codec this version does not write (its copies would
    not match it)."""
    collection = src.rmbench["collection"]
    width, height = (int(v) for v in collection["resolution"].split("x"))
    spec = L.Spec(tuple(src.cameras), width, height)
    if collection.get("fps") != spec.fps or collection.get("codec") != spec.codec.info():
        raise DatasetError(f"{src.root} was recorded at another frame rate or codec than this "
                           f"version writes; collect it again")
    noise = collection.get("action_noise")
    return spec, None if noise is None else NoiseSpec(**noise)


class Copier:
    """Copies of one source dataset's episodes, in one process: the env, its second MjData and
    the inverse kinematics are built once and reused."""

    def __init__(self, source: str | Path):
        self.source = str(source)
        self.src = Dataset(source)
        self.spec, self.noise = _recorded_as(self.src)
        # physics alone: copy 0's frames are the source's own videos, the others are drawn by
        # SceneShift (a render of the replay's frames would only draw copy 0 once more)
        self.env = make(self.src.task, render=False)
        self.shifter, self.scene = LayoutShift(self.src.state_names), SceneShift(self.env)
        self.renderer = self.env.unwrapped.sim.renderer(self.spec.width, self.spec.height)

    def close(self) -> None:
        self.env.close()

    def copy(self, e: int, copies: int, reach: float, seed: int,
             first: int = 0) -> tuple[list[EpisodeRecord], int]:
        """Copies ``first``..``copies`` of source episode ``e`` (copy 0: the episode itself)
        as records, and how many were out of reach."""
        ep = self.src.episode(e, cameras=[])
        deltas = shifts(seed, e, copies, reach)
        kept, missed = {}, 0
        for k in range(first, copies + 1):
            moved = ep if k == 0 else self.shifter.shift(ep, deltas[k])
            if moved is None:
                missed += 1
                continue
            kept[k] = replace(moved, hidden={**ep.hidden, COPY_KEY: {
                "episode": e, "copy": k, "shift": deltas[k].round(6).tolist()}})
        return self._render(ep, kept, deltas), missed

    def _render(self, ep: Episode, copies: dict[int, Episode],
                deltas: np.ndarray) -> list[EpisodeRecord]:
        """Replay ``ep`` from its seed and draw each copy k (moved by ``deltas[k]``) at every
        frame; the copies as records, in order."""
        cams, spec = self.spec.cameras, self.spec
        drawn_copies = [k for k in copies if k != 0]
        enc = {k: {c: Mp4Encoder(spec.fps, spec.codec) for c in cams} for k in drawn_copies}
        stats = {k: {c: ImageStats() for c in cams} for k in drawn_copies}
        ee = {k: np.empty_like(ep.ee_pose) for k in copies}
        perturb = perturber(self.noise, ep.seed, self.env)
        executed = [executed_action(a, perturb) for a in ep.action.astype(np.float64)]
        frames = replay(self.env, ep.seed, executed, ep.state, ep.environment_state,
                        f"episode {ep.index} (seed {ep.seed})")
        try:
            for t, _ in enumerate(frames):
                for k in drawn_copies:
                    drawn, ee[k][t] = self.scene.render(self.renderer, cams, copies[k].state[t],
                                                        deltas[k])
                    for c in cams:
                        enc[k][c].add(drawn[c])
                        stats[k][c].add(drawn[c])
        except ReplayMismatch as err:
            raise DatasetError(str(err)) from None
        videos = {k: {c: enc[k][c].finish() for c in cams} for k in drawn_copies}
        image_stats = {k: {c: s.result() for c, s in stats[k].items()} for k in drawn_copies}
        if 0 in copies:  # the episode itself, as recorded: its videos and their statistics
            ee[0] = ep.ee_pose
            videos[0] = {c: self.src.video_path(c, ep.index).read_bytes() for c in cams}
            image_stats[0] = self.src.image_stats(ep.index)
        return [EpisodeRecord(
            ep.task, ep.seed, True, "success", ep.instruction, copy.hidden, copy.state,
            ee[k].astype(np.float32), copy.action, ep.subtask_index, ep.progress,
            videos[k], image_stats[k], environment_state=copy.environment_state,
            subtask_step=ep.subtask_step)
            for k, copy in copies.items()]


# One Copier per worker process, built on first use (the env takes a while to compile).
_COPIER: Copier | None = None


def _copy(source: str, e: int, copies: int, reach: float, seed: int,
          first: int) -> tuple[list[EpisodeRecord], int]:
    global _COPIER
    if _COPIER is None or _COPIER.source != source:
        _close_copier()
        _COPIER = Copier(source)
    return _COPIER.copy(e, copies, reach, seed, first)


def _close_copier() -> None:
    global _COPIER
    if _COPIER is not None:
        _COPIER.close()
        _COPIER = None


def _resume_point(writer: DatasetWriter, copies: int) -> tuple[int, int]:
    """(source episode, copy) of the next copy to write."""
    if not writer.num_episodes:
        return 0, 0
    last = json.loads(writer.episodes[-1]["rmbench/hidden"]).get(COPY_KEY)
    if last is None:
        raise DatasetError(f"{writer.root} holds episodes that are not layout copies")
    e, k = int(last["episode"]), int(last["copy"]) + 1
    return (e + 1, 0) if k > copies else (e, k)


def copy_layouts(source: str | Path, out: str | Path, copies: int, reach: float, seed: int = 0,
                 episodes: int | None = None, overwrite: bool = False, workers: int = 1,
                 backend: str = "local", progress: bool = True) -> CopySummary:
    """Write to ``out`` the first ``episodes`` (default all) of ``source``, each followed by
    ``copies`` copies with the scene moved by up to ``reach`` metres in x and y. Workers copy
    demonstrations in parallel; they are committed in order, so the dataset is the same
    whatever their number."""
    t0 = time.perf_counter()
    if copies < 0 or not (np.isfinite(reach) and reach >= 0):
        raise ValueError(f"copies must be >= 0 and reach a finite number >= 0, got {copies} "
                         f"and {reach}")
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    check_backend(backend)
    src = Dataset(source)
    if L.root_path(out).resolve() == src.root.resolve():
        raise DatasetError(f"--out {out} is the source dataset; write the copies elsewhere")
    if not src.num_episodes:
        raise DatasetError(f"{src.root} holds no episodes")
    if src.state_names is None:
        raise DatasetError(f"{src.root} records no {L.ENV_STATE}: layout copies move it")
    if not src.cameras:
        raise DatasetError(f"{src.root} has no cameras: nothing to render")
    n = src.num_episodes if episodes is None else episodes
    if not 1 <= n <= src.num_episodes:
        raise ValueError(f"episodes must be in 1..{src.num_episodes}, got {episodes}")
    spec, _ = _recorded_as(src)
    collection = src.rmbench["collection"]
    identity = {**collection, COPY_KEY: {"copies": copies, "reach": reach, "seed": seed,
                                         "source_episodes": n}}
    writer = DatasetWriter(out, src.task, spec, identity, overwrite=overwrite)
    start = writer.num_episodes
    try:
        first, first_copy = _resume_point(writer, copies)
    except BaseException:
        writer.close()
        raise
    executor = make_executor(workers, backend, on_close=_close_copier)
    calls = ((e, _copy, (str(src.root), e, copies, reach, seed, first_copy if e == first else 0))
             for e in range(first, n))
    missed = 0
    bar = tqdm(total=n, initial=first, unit="demo", disable=not progress, desc="layout copies")
    try:
        for _, (records, out_of_reach) in in_order(executor, calls):
            missed += out_of_reach
            for rec in records:
                writer.commit(rec)
            bar.update(1)
    finally:
        bar.close()
        executor.shutdown()
        writer.close()
    return CopySummary(str(writer.root), n, writer.num_episodes, writer.num_episodes - start,
                       missed, writer.total_frames, round(time.perf_counter() - t0, 2))

