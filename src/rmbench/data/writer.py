"""Writing a dataset one committed episode at a time, and picking an interrupted one back up.

An episode exists once its meta/episodes file exists. Its videos and data file are written
first, each atomically (temporary name, then rename), and the metadata file last, so a process
killed at any moment leaves either a whole episode or files that the next run removes. The
dataset-wide files (info.json, stats.json, tasks.parquet, rmbench.json) are derived from the
committed episodes and rewritten after each commit; resuming rebuilds them.
"""

from __future__ import annotations

import json
import logging
import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from rmbench.data import layout as L
from rmbench.data.record import EpisodeRecord
from rmbench.data.stats import aggregate, array_stats, pop_stats, to_json
from rmbench.files import (
    FileFormatError,
    Locked,
    atomic_path,
    lock,
    read_json_object,
    remove_leftovers,
    write_atomic,
    write_json,
)
from rmbench.identity import differences
from rmbench.tasks import get_task

log = logging.getLogger(__name__)


class DatasetError(ValueError):
    """A dataset that cannot be written or read as asked; the message names the problem."""


def write_parquet(path: Path, table: pa.Table) -> None:
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="snappy")


def vector_column(x: np.ndarray) -> pa.Array:
    """(T, D) -> a fixed-size list column, what LeRobot's readers expect for vectors."""
    x = np.ascontiguousarray(x, np.float32)
    return pa.FixedSizeListArray.from_arrays(pa.array(x.reshape(-1)), x.shape[1])


def subtask_ends(subtask_step: np.ndarray) -> np.ndarray:
    """True on the last frame of each plan step, and on the episode's last. Steps, not subtask
    labels: two pushes of one button are two subtasks with one text."""
    s = np.asarray(subtask_step)
    end = np.zeros(len(s), bool)
    end[:-1] = s[:-1] != s[1:]
    end[-1] = True
    return end


def frame_table(rec: EpisodeRecord, episode_index: int, first_index: int,
                task_index: int, fps: int, environment_state: bool = True) -> pa.Table:
    """One episode's rows; ``environment_state=False`` leaves that column out (a dataset
    collected before it existed, being extended)."""
    n = rec.length
    frames = np.arange(n, dtype=np.int64)
    cols = {L.STATE: vector_column(rec.state)}
    if environment_state:
        cols[L.ENV_STATE] = vector_column(rec.environment_state)
    cols.update({
        L.EE_POSE: vector_column(rec.ee_pose),
        L.ACTION: vector_column(rec.action),
        L.SUBTASK_INDEX: pa.array(rec.subtask_index.astype(np.int64)),
        L.SUBTASK_END: pa.array(subtask_ends(rec.subtask_step)),
        L.SUBTASK_STEP: pa.array(rec.subtask_step.astype(np.int64)),
        L.PROGRESS: pa.array(rec.progress.astype(np.float32)),
        "timestamp": pa.array((frames / fps).astype(np.float32)),
        "frame_index": pa.array(frames),
        "episode_index": pa.array(np.full(n, episode_index, np.int64)),
        "index": pa.array(first_index + frames),
        "task_index": pa.array(np.full(n, task_index, np.int64)),
    })
    return pa.table(cols)


def episode_stats(table: pa.Table, rec: EpisodeRecord, spec: L.Spec) -> dict[str, dict]:
    stats = {}
    for cam in spec.cameras:
        stats[L.image_key(cam)] = rec.image_stats[cam]
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_fixed_size_list(col.type):
            values = np.asarray(col.combine_chunks().flatten()).reshape(len(table), -1)
        else:
            values = np.asarray(col.to_numpy(zero_copy_only=False), np.float64)
        stats[name] = array_stats(values)
    return stats


WRITING = ".writer.lock"  # the lock file one writer holds in a dataset's folder


class DatasetWriter:
    """Owns one dataset folder while a collection runs: a second writer of the same folder is
    refused (``WRITING``), as its resume would delete the first one's episode in progress."""

    def __init__(self, root: str | Path, task: str, spec: L.Spec, collection: dict[str, Any],
                 overwrite: bool = False):
        self.root = L.root_path(root)
        self.task = get_task(task)
        self.spec = spec
        self.collection = dict(collection)
        self.instructions = list(self.task.instructions_seen)
        self.episodes: list[dict[str, Any]] = []  # committed rows (without stats columns)
        self._stats: list[dict[str, dict]] = []
        self.skipped: list[dict[str, Any]] = []
        # Record observation.environment_state; False when extending a dataset whose
        # episodes were collected before that column existed.
        self.environment_state = True
        try:
            self._lock = lock(self.root / WRITING)
        except Locked as err:
            raise DatasetError(f"{self.root} is being written by another process "
                               f"({err.holder or '?'}): wait for it to end, or use another "
                               f"--out") from None
        try:
            self._open(overwrite)
        except BaseException:
            if not (self.root / L.RMBENCH).exists():  # (refused: leave a user's folder as it was;
                (self.root / WRITING).unlink(missing_ok=True)  # unlinked while still held)
            self._lock.close()
            raise

    def _open(self, overwrite: bool) -> None:
        remove_leftovers((self.root / L.RMBENCH).parent)  # (data and videos: _resume's own)
        if overwrite and self.root.exists():
            self._remove()
        if (self.root / L.RMBENCH).exists():
            self._resume()
        elif self.root.exists() and _holds_files(self.root):
            raise DatasetError(f"{self.root} exists, is not empty and holds no rmbench dataset "
                               f"({L.RMBENCH} is missing); choose another --out")
        self._write_dataset_meta()

    # ------------------------------------------------------------------ state
    @property
    def num_episodes(self) -> int:
        return len(self.episodes)

    @property
    def total_frames(self) -> int:
        return sum(e["length"] for e in self.episodes)

    @property
    def next_seed(self) -> int:
        """The first candidate seed not yet decided."""
        last = max([e["rmbench/seed"] for e in self.episodes]
                   + [s["seed"] for s in self.skipped], default=None)
        return self.collection["seed"] if last is None else last + 1

    # ----------------------------------------------------------------- commit
    def commit(self, rec: EpisodeRecord) -> int:
        """Write ``rec`` as the next episode; returns its episode index."""
        if not rec.success or rec.length == 0:
            raise ValueError(f"seed {rec.seed}: only successful demonstrations are written")
        if rec.instruction not in self.instructions:
            raise ValueError(f"seed {rec.seed}: instruction {rec.instruction!r} is not one of "
                             f"the task's training instructions")
        e = self.num_episodes
        first = self.total_frames
        table = frame_table(rec, e, first, self.instructions.index(rec.instruction), self.spec.fps,
                            self.environment_state)
        for cam in self.spec.cameras:
            write_atomic(self.root / L.video_file(L.image_key(cam), e), rec.videos[cam])
        write_parquet(self.root / L.data_file(e), table)

        chunk, file = L.chunk_file(e)
        ends = subtask_ends(rec.subtask_step)
        row: dict[str, Any] = {
            "episode_index": e, "tasks": [rec.instruction], "length": rec.length,
            "data/chunk_index": chunk, "data/file_index": file,
            "dataset_from_index": first, "dataset_to_index": first + rec.length,
        }
        for key in self.spec.video_keys:
            row.update({f"videos/{key}/chunk_index": chunk, f"videos/{key}/file_index": file,
                        f"videos/{key}/from_timestamp": 0.0,
                        f"videos/{key}/to_timestamp": rec.length / self.spec.fps})
        row.update({
            "meta/episodes/chunk_index": chunk, "meta/episodes/file_index": file,
            "rmbench/task": self.task.name, "rmbench/seed": rec.seed, "rmbench/tmc": self.task.tmc,
            "rmbench/hidden": json.dumps(rec.hidden, sort_keys=True),
            "rmbench/key_frames": np.flatnonzero(ends).astype(np.int64).tolist(),
            "rmbench/key_subtasks": rec.subtask_index[ends].astype(np.int64).tolist(),
        })
        stats = episode_stats(table, rec, self.spec)
        stat_cols = {f"stats/{k}/{s}": [np.asarray(v).tolist()] for k, d in stats.items()
                     for s, v in d.items()}
        meta = pa.table({**{k: [v] for k, v in row.items()}, **stat_cols})
        write_parquet(self.root / L.episodes_file(e), meta)  # the commit point
        self.episodes.append(row)
        self._stats.append(stats)
        self._write_dataset_meta()
        return e

    def skip(self, seed: int, reason: str) -> None:
        """A seed the collection passed over, kept at once: a run killed before its next
        commit resumes knowing it (the seeds tried, and so the dataset, are those of a run
        never stopped)."""
        log.info("seed %d skipped: %s", seed, reason)
        self.skipped.append({"seed": int(seed), "reason": reason})
        self._write_rmbench()

    def close(self) -> None:
        try:
            self._write_dataset_meta()
        finally:
            self._lock.close()

    # -------------------------------------------------------- derived metadata
    def _write_dataset_meta(self) -> None:
        n, frames = self.num_episodes, self.total_frames
        info = {
            "codebase_version": L.CODEBASE_VERSION, "robot_type": L.ROBOT_TYPE,
            "total_episodes": n, "total_frames": frames, "total_tasks": len(self.instructions),
            "chunks_size": L.CHUNKS_SIZE, "data_files_size_in_mb": 100,
            "video_files_size_in_mb": 500, "fps": self.spec.fps,
            "splits": {"train": f"0:{n}"}, "data_path": L.DATA_PATH, "video_path": L.VIDEO_PATH,
            "features": self.spec.features(self.task.state_names if self.environment_state
                                           else None),
        }
        tasks = pd.DataFrame({"task_index": np.arange(len(self.instructions), dtype=np.int64)},
                             index=pd.Index(self.instructions, name="task"))
        # rmbench.json first: a folder stopped anywhere after it is known as this dataset's
        self._write_rmbench()
        write_parquet(self.root / L.TASKS, pa.Table.from_pandas(tasks))
        # LeRobot's own subtask table: text as the index, so a frame's ``subtask_index``
        # gives ``item["subtask"]`` in LeRobotDataset.
        subtasks = pd.DataFrame({"subtask_index": np.arange(len(self.task.subtasks), dtype=np.int64)},
                                index=pd.Index(list(self.task.subtasks), name="subtask"))
        write_parquet(self.root / L.SUBTASKS, pa.Table.from_pandas(subtasks))
        write_json(self.root / L.STATS, to_json(aggregate(self._stats)), indent=2)
        write_json(self.root / L.INFO, info, indent=2)  # last: a reader sees counts that match the files

    def _write_rmbench(self) -> None:
        write_json(self.root / L.RMBENCH, {
            "format": L.FORMAT, "task": self.task.name, "gym_id": self.task.gym_id,
            "tmc": self.task.tmc, "step_limit": self.task.step_limit,
            "subtasks": list(self.task.subtasks), "collection": self.collection,
            "episodes": self.num_episodes, "skipped": self.skipped}, indent=2)

    # ----------------------------------------------------------------- resume
    def _resume(self) -> None:
        path = self.root / L.RMBENCH
        try:
            saved = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise DatasetError(f"{path} is unreadable ({err}); pass --overwrite to start "
                               f"over") from err
        skipped = saved.get("skipped", []) if isinstance(saved, dict) else None
        if not (isinstance(skipped, list) and all(
                isinstance(s, dict) and type(s.get("seed")) is int for s in skipped)):
            raise DatasetError(f"{path} is not the record this rmbench writes; pass --overwrite "
                               f"to start over")
        layout = {"format": L.FORMAT, "gym_id": self.task.gym_id}
        what = differences({k: saved.get(k) for k in layout}, layout)
        if what:  # another layout or task version: its episodes cannot join these
            raise DatasetError(f"{self.root} holds another dataset format or task version "
                               f"({what}); collect into another folder, or --overwrite to "
                               f"start over")
        what = differences(saved.get("collection", {}), self.collection)
        if what:
            raise DatasetError(f"{self.root} was collected with other arguments ({what}); run "
                               f"with the same arguments to resume, or --overwrite to start over")
        for meta in _committed_episode_files(self.root):
            try:
                row = {k: v[0] for k, v in pq.read_table(meta).to_pydict().items()}
            except (OSError, pa.ArrowException, IndexError) as err:
                raise DatasetError(f"{meta}: unreadable ({err}); the dataset is damaged, "
                                   f"--overwrite to start over") from None
            if type(row.get("rmbench/seed")) is not int:
                raise DatasetError(f"{meta}: no episode seed; the dataset is damaged, "
                                   f"--overwrite to start over")
            stats = pop_stats(row)
            self.episodes.append(row)
            self._stats.append(stats)
        if self.episodes:
            self.environment_state = L.ENV_STATE in self._stats[0]
            info = self.root / L.INFO
            if info.exists():  # (a run killed between its first episode and info.json has none)
                try:
                    features = read_json_object(info, ("features",))["features"]
                    names = features.get(L.ENV_STATE, {}).get("names")
                except (FileFormatError, AttributeError):
                    raise DatasetError(f"{info}: damaged, not the info.json this rmbench "
                                       f"writes; --overwrite to start over") from None
                if self.environment_state and names != list(self.task.state_names):
                    raise DatasetError(f"{self.root} records another {L.ENV_STATE} layout than "
                                       f"{self.task.name}'s state_names now; --overwrite to "
                                       f"start over")
        # seeds are decided in order, so every saved skip was decided (a skip after the last
        # commit too: written as it was made)
        self.skipped = list(skipped)
        removed = self._remove_uncommitted()
        if removed:
            log.warning("removed %d file(s) of an interrupted episode in %s", removed, self.root)
        log.info("resuming %s at episode %d", self.root, self.num_episodes)

    def _remove_uncommitted(self) -> int:
        """Delete temporary files and the data/videos of episodes that were never committed."""
        n, removed = self.num_episodes, 0
        for sub in ("data", "videos", L.EPISODES_DIR):
            for path in (self.root / sub).rglob("*") if (self.root / sub).exists() else []:
                if not path.is_file():
                    continue
                e = _episode_of(path)
                if path.name.startswith(".") or e is None or e >= n:
                    path.unlink()
                    removed += 1
        return removed

    def _remove(self) -> None:
        if not (self.root / L.RMBENCH).exists() and _holds_files(self.root):
            raise DatasetError(f"refusing to delete {self.root}: it is not an rmbench dataset")
        # info.json and the episodes' rows first: the rows commit the episodes, so a run
        # killed part way never leaves one whose data are gone, and info.json would count
        # them (a plain re-run then resumes from what is left; or, killed among the rows,
        # which go in no fixed order, refuses the gap as damage and asks for --overwrite,
        # losing nothing more); then all but
        # the lock this writer holds, and rmbench.json last: a run killed part way leaves a
        # folder still known as a dataset, which the next --overwrite deletes
        for first in (L.INFO, L.EPISODES_DIR):
            if (self.root / first).exists():
                _delete(self.root / first)
        mark = self.root / L.RMBENCH
        for path in [p for p in self.root.iterdir() if p.name != WRITING and p != mark.parent]:
            _delete(path)
        if mark.parent.is_symlink():  # (a link is removed, never what it points to)
            mark.parent.unlink()
        elif mark.parent.is_dir():
            for path in [p for p in mark.parent.iterdir() if p != mark]:
                _delete(path)
            mark.unlink(missing_ok=True)
            mark.parent.rmdir()


def _delete(path: Path) -> None:
    """A file, a link or a whole folder."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink()


def _holds_files(root: Path) -> bool:
    """Whether ``root`` holds any file but a writer's lock (empty folders, such as a start
    stopped before its first file, do not count)."""
    return any(p.is_file() and p != root / WRITING for p in root.rglob("*"))


_FILE = re.compile(r"chunk-(\d+)[/\\]file-(\d+)\.(parquet|mp4)$")


def _episode_of(path: Path) -> int | None:
    m = _FILE.search(path.as_posix())
    return None if m is None else int(m.group(1)) * L.CHUNKS_SIZE + int(m.group(2))


def _committed_episode_files(root: Path) -> list[Path]:
    """meta/episodes files of episodes 0, 1, ...: episodes commit in order, so one missing
    before a later one (or fewer than info.json counts) is damage, a DatasetError, never the
    place a resume starts over from (which deletes what follows)."""
    found = {}
    for path in (root / L.EPISODES_DIR).glob("chunk-*/file-*.parquet"):
        e = _episode_of(path)
        if e is not None:
            found[e] = path
    out = []
    while len(out) in found:
        out.append(found[len(out)])
    counted = 0
    if (root / L.INFO).exists():
        try:
            counted = json.loads((root / L.INFO).read_text()).get("total_episodes", 0)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError):
            counted = 0  # (a damaged info.json is the resume's to report)
    if len(found) > len(out) or (type(counted) is int and counted > len(out)):
        missing = root / L.episodes_file(len(out))
        raise DatasetError(f"{missing} is missing while the dataset holds "
                           f"{max(len(found), counted)} episodes: it is damaged; restore the "
                           f"file, or --overwrite to start over")
    return out
