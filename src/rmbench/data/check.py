"""``rmbench dataset check``: every file of a dataset against the layout; the first problem in
one line. Checks what a reader relies on, without decoding video (headers are read instead).

It never raises anything but a one-line DatasetError: each field is checked for presence and
type before it is used (meta/info.json and meta/episodes by the reader, ``check_info`` and
``Dataset.episodes``), and whatever no check foresaw is still reported in one line, naming
the dataset, as a problem the checker could not name."""

from __future__ import annotations

import json
import math

import av
import numpy as np
import pyarrow as pa

from rmbench.data import layout as L
from rmbench.data.reader import Dataset, column, read_json, read_parquet
from rmbench.data.stats import aggregate
from rmbench.data.writer import DatasetError, subtask_ends
from rmbench.video import probe_video

REQUIRED_INFO = ("codebase_version", "robot_type", "total_episodes", "total_frames",
                 "total_tasks", "chunks_size", "data_files_size_in_mb", "video_files_size_in_mb",
                 "fps", "splits", "data_path", "video_path", "features")
# the frame columns every dataset has (the environment state is optional, cameras too)
REQUIRED_FEATURES = (L.STATE, L.EE_POSE, L.ACTION, L.SUBTASK_INDEX, L.SUBTASK_END,
                     L.SUBTASK_STEP, L.PROGRESS, *L.INDEX_COLUMNS)
# info.json fields LeRobot reads and the reader does not (check_info types the others)
INFO_TYPES = {"robot_type": str, "chunks_size": int, "data_files_size_in_mb": int,
              "video_files_size_in_mb": int, "splits": dict, "data_path": str, "video_path": str}
ARROW_TYPES = {"float32": pa.float32(), "int64": pa.int64(), "bool": pa.bool_()}


def _fail(msg: str):
    raise DatasetError(msg)


def _check_stats(ds: Dataset, stats: dict) -> None:
    """meta/stats.json against what it aggregates, each episode's own statistics (its
    meta/episodes row): the normalisers every training sets read it, so a value edited or
    damaged there would train on a wrong scale without a word."""
    _ = ds.episodes  # (the rows themselves checked first: one each, every column readable)
    per_episode = [ds.episode_stats(e) for e in range(ds.num_episodes)]
    for key, want in aggregate(per_episode).items():
        for stat, value in want.items():
            got = stats.get(key, {}).get(stat) if isinstance(stats.get(key), dict) else None
            try:
                got = np.asarray(got, np.float64)
                same = got.shape == np.shape(value) and np.allclose(got, value, rtol=1e-9,
                                                                    atol=1e-12)
            except (TypeError, ValueError):  # (missing, text, ragged)
                same = False
            if not same:
                _fail(f"{ds.root / L.STATS}: {key} {stat} is not the aggregate of the episodes' "
                      f"own statistics (edited or damaged)")


def check_dataset(root) -> dict:
    """Raise DatasetError naming the first problem; return a summary when all is well."""
    try:
        return _check(root)
    except DatasetError:
        raise
    except Exception as err:  # a corruption no check foresaw: still one line, never a trace
        first = (str(err).splitlines() or [""])[0][:200]
        raise DatasetError(f"{root}: unreadable in a way the checker does not name "
                           f"({type(err).__name__}: {first})") from None


def _check(root) -> dict:
    ds = Dataset(root)  # info.json, rmbench.json, tasks and subtasks tables
    root = ds.root
    info = ds.info
    for key in REQUIRED_INFO:
        if key not in info:
            _fail(f"{root / L.INFO}: no {key!r}")
    for key, kind in INFO_TYPES.items():
        if type(info[key]) is not kind:
            _fail(f"{root / L.INFO}: {key} must be {kind.__name__}, got {info[key]!r:.40}")
    if info["data_path"] != L.DATA_PATH or info["video_path"] != L.VIDEO_PATH:
        _fail(f"{root / L.INFO}: data_path/video_path differ from the v3.0 layout")
    if info["chunks_size"] != L.CHUNKS_SIZE:
        _fail(f"{root / L.INFO}: chunks_size {info['chunks_size']!r:.40}, the layout's is "
              f"{L.CHUNKS_SIZE}")
    if len(ds.instructions) != info["total_tasks"]:
        _fail(f"{root / L.TASKS}: {len(ds.instructions)} tasks, info.json says {info['total_tasks']}")
    for key in REQUIRED_FEATURES:
        if key not in info["features"]:
            _fail(f"{root / L.INFO}: no feature {key!r}")
    stats = read_json(root / L.STATS)
    features = info["features"]
    for key in features:
        if info["total_episodes"] and key not in stats:
            _fail(f"{root / L.STATS}: no statistics for {key!r}")

    video_keys = [L.image_key(cam) for cam in ds.cameras]
    if (root / "videos").is_dir():
        undeclared = sorted(p.name for p in (root / "videos").iterdir() if p.name not in video_keys)
        if undeclared:
            _fail(f"{root / 'videos' / undeclared[0]}: videos of a camera info.json does not "
                  f"declare")

    found = sorted(p.relative_to(root).as_posix() for p in (root / L.EPISODES_DIR).rglob("*.parquet"))
    expected = [L.episodes_file(e) for e in range(ds.num_episodes)]
    if found != expected:
        extra = sorted(set(found) - set(expected))
        missing = sorted(set(expected) - set(found))
        _fail(f"{root / L.EPISODES_DIR}: "
              + (f"missing {missing[0]}" if missing else f"{extra[0]} beyond the "
                 f"{ds.num_episodes} episodes in info.json (an interrupted collection: re-run it "
                 f"to resume)"))
    _check_stats(ds, stats)
    # an episode's data and videos are written before its meta/episodes row: files of one
    # past the committed count are an interrupted episode's (missing ones are named below)
    committed = {L.data_file(e) for e in range(ds.num_episodes)} | {
        L.video_file(key, e) for key in video_keys for e in range(ds.num_episodes)}
    extra = sorted(p.relative_to(root).as_posix() for sub in ("data", "videos")
                   for p in (root / sub).rglob("*") if p.is_file() and not p.name.startswith(".")
                   and p.relative_to(root).as_posix() not in committed)
    if extra:
        _fail(f"{root / extra[0]}: beyond the {ds.num_episodes} episodes in info.json (an "
              f"interrupted collection: re-run it to resume)")

    first = 0
    for e in range(ds.num_episodes):
        row = ds.episodes[e]
        where = root / L.episodes_file(e)
        if row["episode_index"] != e:
            _fail(f"{where}: episode_index {row['episode_index']}, expected {e}")
        n = row["length"]
        if (row["dataset_from_index"], row["dataset_to_index"]) != (first, first + n):
            _fail(f"{where}: dataset index range [{row['dataset_from_index']}, "
                  f"{row['dataset_to_index']}) should be [{first}, {first + n})")
        _check_row(where, row, e, n, ds, video_keys)
        ends, sub = _check_data(root / L.data_file(e), features, e, n, first, ds)
        key_frames = list(row["rmbench/key_frames"])
        if key_frames != np.flatnonzero(ends).tolist():
            _fail(f"{where}: key frames {key_frames[:5]}... do not match the subtask_end flags")
        if row.get("rmbench/key_subtasks") != sub[ends].tolist():
            _fail(f"{where}: rmbench/key_subtasks {str(row.get('rmbench/key_subtasks'))[:40]} "
                  f"are not the subtasks ending at the key frames")
        try:
            if not isinstance(json.loads(row["rmbench/hidden"]), dict):
                raise ValueError("not a JSON object")
        except ValueError as err:
            _fail(f"{where}: rmbench/hidden is not the episode's hidden state ({err})")
        for cam in ds.cameras:
            _check_video(ds.video_path(cam, e), n, features[L.image_key(cam)])
        first += n
    if first != ds.num_frames:
        _fail(f"{root / L.INFO}: total_frames {ds.num_frames}, the episodes hold {first}")
    return {"root": str(root), "task": ds.task, "episodes": ds.num_episodes, "frames": first,
            "cameras": ds.cameras}


def _check_row(where, row, e, n, ds, video_keys) -> None:
    """Episode ``e``'s meta/episodes row beyond what the reader types: where LeRobot finds its
    files, its task and instruction."""
    chunk, file = L.chunk_file(e)
    want: dict[str, float] = {"data/chunk_index": chunk, "data/file_index": file,
                              "meta/episodes/chunk_index": chunk, "meta/episodes/file_index": file}
    for key in video_keys:
        want.update({f"videos/{key}/chunk_index": chunk, f"videos/{key}/file_index": file,
                     f"videos/{key}/from_timestamp": 0.0, f"videos/{key}/to_timestamp": n / ds.fps})
    for col, value in want.items():
        got = row.get(col)
        if type(got) not in (int, float) or not math.isclose(got, value, abs_tol=1e-6):
            _fail(f"{where}: {col} is {got!r:.40}, the layout's is {value}")
    for col, value in (("rmbench/task", ds.task), ("rmbench/tmc", ds.rmbench.get("tmc"))):
        if row[col] != value:
            _fail(f"{where}: {col} {row[col]!r:.40}, {L.RMBENCH} says {value!r}")
    if len(row["tasks"]) != 1 or row["tasks"][0] not in ds.instructions:
        _fail(f"{where}: tasks {str(row['tasks'])[:60]} is not one instruction of {L.TASKS}")


def _check_data(path, features, e, n, first, ds) -> tuple[np.ndarray, np.ndarray]:
    """The data file of episode ``e``; returns its subtask_end flags and subtask indices."""
    table = read_parquet(path)
    expected_cols = [k for k, f in features.items() if f["dtype"] != "video"]
    if table.column_names != expected_cols:
        missing = sorted(set(expected_cols) - set(table.column_names))
        extra = sorted(set(table.column_names) - set(expected_cols))
        _fail(f"{path}: columns differ from info.json (missing {missing}, extra {extra})")
    if len(table) != n:
        _fail(f"{path}: {len(table)} rows, the episode's length is {n}")
    for key in expected_cols:
        if table.column(key).null_count:
            _fail(f"{path}: column {key!r} has {table.column(key).null_count} missing values")
        ft, typ = features[key], table.schema.field(key).type
        want = ARROW_TYPES[ft["dtype"]]
        if ft["shape"] == [1]:
            ok = typ == want
        else:
            ok = pa.types.is_fixed_size_list(typ) and typ.list_size == ft["shape"][0] \
                and typ.value_type == want
        if not ok:
            _fail(f"{path}: column {key!r} has type {typ}, info.json declares "
                  f"{ft['dtype']} {ft['shape']}")
    for key in (L.STATE, L.ACTION, L.EE_POSE, L.ENV_STATE):
        if key in features and not np.isfinite(column(table, key)).all():
            _fail(f"{path}: {key} holds NaN or inf")
    checks = {
        "episode_index": np.full(n, e), "frame_index": np.arange(n),
        "index": first + np.arange(n), "timestamp": (np.arange(n) / ds.fps).astype(np.float32)}
    for key, want in checks.items():
        if not np.array_equal(column(table, key), want):
            _fail(f"{path}: {key} is not {want[:3].tolist()}... as it should be for episode {e}")
    if not np.isin(column(table, "task_index"), np.arange(len(ds.instructions))).all():
        _fail(f"{path}: task_index outside the {len(ds.instructions)} tasks of {L.TASKS}")
    sub = column(table, L.SUBTASK_INDEX)
    if not np.isin(sub, np.arange(len(ds.subtasks))).all():
        _fail(f"{path}: subtask_index outside the {len(ds.subtasks)} subtasks of {L.SUBTASKS}")
    step = column(table, L.SUBTASK_STEP)
    if n and (step[0] != 0 or (np.diff(step) < 0).any()):
        _fail(f"{path}: subtask_step does not count the plan's steps up from 0")
    if ((np.diff(sub) != 0) & (np.diff(step) == 0)).any():
        _fail(f"{path}: subtask_index changes within a plan step (a step names one subtask)")
    ends = column(table, L.SUBTASK_END).astype(bool)
    if not np.array_equal(ends, subtask_ends(step)):
        _fail(f"{path}: subtask_end flags do not mark the last frame of each plan step")
    return ends, sub


def _check_video(path, n, feature) -> None:
    if not path.exists():
        _fail(f"{path}: missing")
    try:
        meta = probe_video(path)
    except (av.FFmpegError, ValueError, OSError) as err:
        _fail(f"{path}: not a readable video ({err})")
    if meta["frames"] != n:
        _fail(f"{path}: {meta['frames']} frames, the episode has {n}")
    h, w, _ = feature["shape"]
    if (meta["height"], meta["width"]) != (h, w):
        _fail(f"{path}: {meta['width']}x{meta['height']}, info.json declares {w}x{h}")
