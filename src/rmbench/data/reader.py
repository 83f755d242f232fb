"""Reading an rmbench dataset: metadata, and whole episodes with their frames decoded (PyAV)."""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from rmbench.data import layout as L
from rmbench.data.stats import from_json, pop_stats
from rmbench.data.writer import DatasetError
from rmbench.tasks.registry import UnknownTaskError, get_task
from rmbench.video import decode_video

VECTOR_KEYS = (L.STATE, L.EE_POSE, L.ACTION)
FEATURE_DTYPES = ("video", "float32", "int64", "bool")
# a camera's name becomes a folder name: letters, digits and underscores only
CAMERA_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")
# meta/episodes columns a reader relies on, with what their one value must be
EPISODE_COLUMNS = {"episode_index": pa.types.is_integer, "length": pa.types.is_integer,
                   "dataset_from_index": pa.types.is_integer,
                   "dataset_to_index": pa.types.is_integer,
                   "tasks": lambda t: pa.types.is_list(t) and pa.types.is_string(t.value_type),
                   "rmbench/task": pa.types.is_string, "rmbench/seed": pa.types.is_integer,
                   "rmbench/tmc": pa.types.is_string, "rmbench/hidden": pa.types.is_string,
                   "rmbench/key_frames": lambda t: pa.types.is_list(t)
                   and pa.types.is_integer(t.value_type)}


@dataclass
class Episode:
    """One demonstration, one row per frame (the observation and the action taken there)."""

    index: int
    seed: int
    task: str
    instruction: str
    tmc: str
    hidden: dict[str, Any]
    state: np.ndarray  # (T, 14) float32
    ee_pose: np.ndarray  # (T, 14) float32
    action: np.ndarray  # (T, 14) float32
    subtask_index: np.ndarray  # (T,) int64
    subtask_end: np.ndarray  # (T,) bool
    progress: np.ndarray  # (T,) float32
    timestamp: np.ndarray  # (T,) float32
    key_frames: list[int]
    subtasks: list[str]  # the dataset's subtask table: text of each subtask index
    frames: dict[str, np.ndarray] = field(default_factory=dict)  # camera -> (T, H, W, 3) uint8
    # (T, len(state_names)) float32, the task's state observation; None in a dataset collected
    # before the column existed
    environment_state: np.ndarray | None = None
    # (T,) int64, the plan step of each frame (layout.SUBTASK_STEP); a subtask ends where its
    # step does. Derived from the end flags where not given.
    subtask_step: np.ndarray | None = None

    def __post_init__(self):
        if self.subtask_step is None:
            ends = np.asarray(self.subtask_end, bool)
            self.subtask_step = np.concatenate([[0], np.cumsum(ends[:-1])]).astype(np.int64)

    def __len__(self) -> int:
        return len(self.action)

    def subtask_text(self, t: int) -> str:
        return self.subtasks[int(self.subtask_index[t])]


def read_parquet(path: Path) -> pa.Table:
    try:
        return pq.read_table(path)
    except FileNotFoundError:
        raise DatasetError(f"{path}: missing") from None
    except (pa.ArrowException, OSError) as err:
        raise DatasetError(f"{path}: not a readable parquet file ({err})") from None


def read_json(path: Path) -> dict:
    """A JSON object (a map) from ``path``, or a DatasetError naming it."""
    try:
        value = json.loads(path.read_text())
    except FileNotFoundError:
        raise DatasetError(f"{path}: missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DatasetError(f"{path}: not readable JSON ({err})") from None
    if not isinstance(value, dict):
        raise DatasetError(f"{path}: not a JSON object (a {type(value).__name__})")
    return value


def _is_count(value) -> bool:
    return type(value) is int and value >= 0


def check_info(info: dict, path: Path) -> dict:
    """``info`` (meta/info.json) if it holds what a reader reads, of the types it reads them
    as; else a one-line DatasetError naming the first field that does not."""
    if info.get("codebase_version") != L.CODEBASE_VERSION:
        raise DatasetError(f"{path}: codebase_version {info.get('codebase_version')!r}, "
                           f"expected {L.CODEBASE_VERSION!r}")
    for key in ("total_episodes", "total_frames", "total_tasks"):
        if not _is_count(info.get(key)):
            raise DatasetError(f"{path}: {key} must be an integer >= 0, got {info.get(key)!r:.40}")
    if not _is_count(info.get("fps")) or info["fps"] == 0:
        raise DatasetError(f"{path}: fps must be a positive integer, got {info.get('fps')!r:.40}")
    features = info.get("features")
    if not isinstance(features, dict) or not features:
        raise DatasetError(f"{path}: no 'features'")
    for key, ft in features.items():
        shape = ft.get("shape") if isinstance(ft, dict) else None
        if not isinstance(ft, dict) or ft.get("dtype") not in FEATURE_DTYPES or not (
                isinstance(shape, list) and shape and all(_is_count(n) and n for n in shape)):
            raise DatasetError(f"{path}: feature {key!r:.60} needs a dtype of "
                               f"{', '.join(FEATURE_DTYPES)} and a shape of positive sizes")
        if ft["dtype"] == "video":
            camera = key[len(L.IMAGE_PREFIX):]
            if not key.startswith(L.IMAGE_PREFIX) or not CAMERA_NAME.fullmatch(camera):
                raise DatasetError(f"{path}: video feature {key!r:.60} is not "
                                   f"{L.IMAGE_PREFIX}CAMERA with CAMERA letters, digits, '_'")
            if len(shape) != 3 or shape[2] != 3:
                raise DatasetError(f"{path}: video feature {key!r} has shape {shape}, "
                                   f"expected [height, width, 3]")
        elif len(shape) != 1:
            raise DatasetError(f"{path}: feature {key!r} has shape {shape}, expected [size]")
    env_state = features.get(L.ENV_STATE)
    if env_state is not None:
        names = env_state.get("names")
        if not (isinstance(names, list) and all(isinstance(n, str) for n in names)
                and len(names) == env_state["shape"][0]):
            raise DatasetError(f"{path}: {L.ENV_STATE} needs one name per entry")
    return info


def _names(path: Path, index: str, column_name: str) -> list[str]:
    """The texts of a tasks or subtasks table (its pandas index), ordered by ``column_name``."""
    table = read_parquet(path)
    if column_name not in table.column_names or not pa.types.is_integer(
            table.schema.field(column_name).type):
        raise DatasetError(f"{path}: no integer {column_name!r} column")
    frame = table.to_pandas()
    if frame.index.name != index:
        raise DatasetError(f"{path}: its rows are not indexed by {index!r}")
    ordered = frame.sort_values(column_name)
    if ordered[column_name].tolist() != list(range(len(frame))):
        raise DatasetError(f"{path}: {column_name} is not 0..{len(frame) - 1}")
    return [str(t) for t in ordered.index]


# the columns Dataset.episode reads from a data file
DATA_COLUMNS = (L.STATE, L.EE_POSE, L.ACTION, L.SUBTASK_INDEX, L.SUBTASK_END, L.PROGRESS,
                "timestamp", "episode_index", L.SUBTASK_STEP)


def column(table: pa.Table, name: str) -> np.ndarray:
    col = table.column(name).combine_chunks()
    if pa.types.is_fixed_size_list(col.type) or pa.types.is_list(col.type):
        return np.asarray(col.flatten()).reshape(len(table), -1)
    return col.to_numpy(zero_copy_only=False)


class Dataset:
    """An rmbench dataset folder. ``episode(i)`` loads one episode; frames are decoded only
    for the cameras asked for."""

    def __init__(self, root: str | Path):
        self.root = L.root_path(root)
        if not self.root.is_dir():
            raise DatasetError(f"{self.root}: " + ("a file, not a dataset folder"
                                                   if self.root.exists() else
                                                   "no such dataset folder"))
        self.info = check_info(read_json(self.root / L.INFO), self.root / L.INFO)
        self.rmbench = read_json(self.root / L.RMBENCH)
        if not isinstance(self.rmbench, dict) or not isinstance(self.rmbench.get("task"), str):
            raise DatasetError(f"{self.root / L.RMBENCH}: no task name")
        if self.rmbench.get("format") != L.FORMAT:
            raise DatasetError(
                f"{self.root / L.RMBENCH}: dataset format {self.rmbench.get('format')!r}, this rmbench "
                f"reads {L.FORMAT!r} (one subtask per plan step): collect it again with rmbench collect")
        self._check_version()
        if not isinstance(self.rmbench.get("collection"), dict):
            raise DatasetError(f"{self.root / L.RMBENCH}: no record of how it was collected")
        self.features: dict[str, dict] = self.info["features"]
        self.fps: int = self.info["fps"]
        self.cameras = [k[len(L.IMAGE_PREFIX):] for k, f in self.features.items()
                        if f["dtype"] == "video"]
        self.instructions: list[str] = _names(self.root / L.TASKS, "task", "task_index")
        self.subtasks: list[str] = _names(self.root / L.SUBTASKS, "subtask", "subtask_index")

    def _check_version(self) -> None:
        """A dataset serves only the task version it was collected on: a change to a task's
        plan or its subtask ends (CHANGELOG.md) bumps the version in its gym id."""
        try:
            current = get_task(self.rmbench["task"]).gym_id
        except UnknownTaskError as err:
            raise DatasetError(f"{self.root / L.RMBENCH}: {err.args[0]}") from None
        if self.rmbench.get("gym_id") != current:
            raise DatasetError(
                f"{self.root / L.RMBENCH}: collected on {self.rmbench.get('gym_id')!r}, this "
                f"rmbench's {self.rmbench['task']} is {current!r} (CHANGELOG.md): collect it "
                f"again with rmbench collect")

    @property
    def task(self) -> str:
        return self.rmbench["task"]

    @property
    def gym_id(self) -> str:
        """The task version the demonstrations were collected on (``rmbench/Task-vN``)."""
        return self.rmbench["gym_id"]

    @property
    def state_names(self) -> list[str] | None:
        """Names of ``observation.environment_state``'s entries; None if it is not recorded."""
        feature = self.features.get(L.ENV_STATE)
        return None if feature is None else list(feature["names"])

    @property
    def num_episodes(self) -> int:
        return int(self.info["total_episodes"])

    @property
    def num_frames(self) -> int:
        return int(self.info["total_frames"])

    def __len__(self) -> int:
        return self.num_episodes

    @cached_property
    def episodes(self) -> list[dict[str, Any]]:
        """Each episode's meta/episodes row, without its statistics columns."""
        beyond = self.root / L.episodes_file(self.num_episodes)
        if beyond.exists():  # (info.json lowered by hand would drop episodes without a word)
            raise DatasetError(f"{self.root / L.INFO} counts {self.num_episodes} episodes, but "
                               f"{beyond} holds one more: a collection stopped before it counted "
                               f"its last episode (run it again to resume) or is still running, "
                               f"or info.json was edited")
        rows = []
        for e in range(self.num_episodes):
            path = self.root / L.episodes_file(e)
            table = read_parquet(path)
            if len(table) != 1:
                raise DatasetError(f"{path}: {len(table)} rows, an episode's metadata is one")
            for name, fits in EPISODE_COLUMNS.items():
                if name not in table.column_names:
                    raise DatasetError(f"{path}: no {name!r} column")
                col = table.column(name)
                if not fits(col.type) or col.null_count:
                    raise DatasetError(f"{path}: {name!r} is {col.type}"
                                       f"{' null' if col.null_count else ''}, not what a reader reads")
            table = table.select([c for c in table.column_names if not c.startswith("stats/")])
            row = {k: v[0] for k, v in table.to_pydict().items()}
            if len(row["tasks"]) != 1:
                raise DatasetError(f"{path}: 'tasks' holds {len(row['tasks'])} texts, an "
                                   f"episode has one instruction")
            try:
                json.loads(row["rmbench/hidden"])
            except json.JSONDecodeError as err:
                raise DatasetError(f"{path}: rmbench/hidden is not JSON ({err})") from None
            rows.append(row)
        return rows

    def episode_stats(self, episode: int) -> dict[str, dict[str, np.ndarray]]:
        """Every feature's statistics of one episode's frames (min, max, mean, std, count), as
        its collection computed them (the episode's meta/episodes row); meta/stats.json
        aggregates them."""
        path = self.root / L.episodes_file(episode)
        return pop_stats({k: v[0] for k, v in read_parquet(path).to_pydict().items()})

    def image_stats(self, episode: int) -> dict[str, dict[str, np.ndarray]]:
        """Each camera's statistics of one episode's frames (``episode_stats``')."""
        path = self.root / L.episodes_file(episode)
        stats = self.episode_stats(episode)
        missing = [c for c in self.cameras if L.image_key(c) not in stats]
        if missing:
            raise DatasetError(f"{path}: no statistics of camera {missing[0]!r}")
        return {c: stats[L.image_key(c)] for c in self.cameras}

    @cached_property
    def fingerprint(self) -> str:
        """What tells these demonstrations from others, in 16 hex digits: the task version,
        the collection's arguments (cameras, resolution, noise, seed), the features' layout and
        each episode's seed and length. The same for a dataset collected again with the same
        arguments (no wall time enters it)."""
        key = {"gym_id": self.gym_id, "collection": self.rmbench.get("collection"),
               "features": self.features,
               "episodes": [[int(r["rmbench/seed"]), int(r["length"])] for r in self.episodes]}
        return hashlib.sha256(json.dumps(key, sort_keys=True, default=str).encode()).hexdigest()[:16]

    @cached_property
    def stats(self) -> dict[str, dict[str, np.ndarray]]:
        """meta/stats.json: per feature, its min, max, mean, std and count as arrays."""
        path = self.root / L.STATS
        try:
            return from_json(read_json(path))
        except (AttributeError, TypeError, ValueError) as err:  # (a feature's entry not a map)
            raise DatasetError(f"{path}: not the statistics this rmbench writes ({err})") from None

    @cached_property
    def lengths(self) -> np.ndarray:
        return np.array([row["length"] for row in self.episodes], dtype=np.int64)

    def video_path(self, camera: str, episode: int) -> Path:
        return self.root / L.video_file(L.image_key(camera), episode)

    def _data(self, index: int, row: dict) -> pa.Table:
        """Episode ``index``'s data file, checked against its meta row: the columns an
        episode is read from, its length, and its own episode index in every row (a file
        copied over another episode's, or cut short, is an error naming it, not another
        episode's frames)."""
        path = self.root / L.data_file(index)
        table = read_parquet(path)
        missing = [c for c in DATA_COLUMNS if c not in table.column_names]
        if missing:
            raise DatasetError(f"{path}: no column(s) {missing}")
        if len(table) != row["length"]:
            raise DatasetError(f"{path}: {len(table)} rows, its episode's length is {row['length']}")
        own = column(table, "episode_index")
        if len(own) and not (own == index).all():
            raise DatasetError(f"{path}: rows of episode {int(own[own != index][0])}, not {index}")
        for key in (L.STATE, L.EE_POSE, L.ACTION, L.ENV_STATE):
            declared = self.features.get(key, {}).get("shape")
            if key in table.column_names and declared:
                width = len(table.column(key).combine_chunks().flatten()) // max(len(table), 1)
                if len(table) and width != declared[0]:
                    raise DatasetError(f"{path}: {key!r} holds {width} values a frame, "
                                       f"info.json declares {declared[0]}")
        subtask = column(table, L.SUBTASK_INDEX)
        if len(subtask) and not 0 <= subtask.min() <= subtask.max() < len(self.subtasks):
            raise DatasetError(f"{path}: subtask_index {int(subtask.max())} of "
                               f"{len(self.subtasks)} subtasks (meta/subtasks.parquet)")
        return table

    def episode(self, index: int, cameras: list[str] | tuple[str, ...] | None = None) -> Episode:
        """Episode ``index`` with frames of ``cameras`` (all by default; ``[]`` for none)."""
        if not 0 <= index < self.num_episodes:
            raise IndexError(f"episode {index} out of range: the dataset has {self.num_episodes}")
        cameras = self.cameras if cameras is None else list(cameras)
        unknown = sorted(set(cameras) - set(self.cameras))
        if unknown:
            raise DatasetError(f"camera(s) {unknown} not in the dataset; it has {self.cameras}")
        row = self.episodes[index]
        table = self._data(index, row)
        ep = Episode(
            index=index, seed=int(row["rmbench/seed"]), task=row["rmbench/task"],
            instruction=row["tasks"][0], tmc=row["rmbench/tmc"],
            hidden=json.loads(row["rmbench/hidden"]),
            state=column(table, L.STATE), ee_pose=column(table, L.EE_POSE),
            action=column(table, L.ACTION), subtask_index=column(table, L.SUBTASK_INDEX),
            subtask_end=column(table, L.SUBTASK_END).astype(bool),
            progress=column(table, L.PROGRESS), timestamp=column(table, "timestamp"),
            key_frames=list(row["rmbench/key_frames"]), subtasks=self.subtasks,
            environment_state=(column(table, L.ENV_STATE) if L.ENV_STATE in table.column_names
                               else None),
            subtask_step=column(table, L.SUBTASK_STEP))
        for cam in cameras:
            path = self.video_path(cam, index)
            if not path.exists():
                raise DatasetError(f"{path}: missing")
            try:
                frames = decode_video(path)
            except (av.FFmpegError, ValueError) as err:
                raise DatasetError(f"{path}: not a readable video ({err})") from None
            if len(frames) != len(ep):
                raise DatasetError(f"{path}: {len(frames)} frames, the episode has {len(ep)}")
            ep.frames[cam] = frames
        return ep
