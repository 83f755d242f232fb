"""``rmbench dataset check`` against one-field corruptions of every metadata file, data file
and video: each gives its own one-line refusal, none raises anything else, and every refusal
the checker and the reader have is reached by one."""

import json
import re
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from rmbench.data import DatasetError
from rmbench.data import layout as L
from rmbench.data.check import check_dataset

EP = 1  # the episode corrupted: a middle one, so index ranges on both sides matter
HEAD = "observation.images.head"

# Every refusal of check.py and of the reader's metadata checks, by a piece of its message.
REFUSALS = {
    "info missing": r"meta/info\.json: missing",
    "info not json": r"info\.json: not readable JSON",
    "info not an object": r"info\.json: not a JSON object",
    "codebase": r"codebase_version .* expected",
    "count": r"must be an integer >= 0",
    "fps": r"fps must be a positive integer",
    "no features": r"no 'features'",
    "feature dtype/shape": r"needs a dtype of",
    "camera name": r"video feature .* is not observation\.images\.CAMERA",
    "video shape": r"expected \[height, width, 3\]",
    "vector shape": r"expected \[size\]",
    "state names": r"needs one name per entry",
    "rmbench task": r"rmbench\.json: no task name",
    "names column": r"no integer 'task_index' column",
    "names index": r"rows are not indexed by 'task'",
    "names order": r"task_index is not 0\.\.",
    "parquet unreadable": r"not a readable parquet file",
    "parquet missing": r"file-001\.parquet: missing",
    "episode rows": r"an episode's metadata is one",
    "episode column": r"file-001\.parquet: no '.*' column",
    "episode column type": r"not what a reader reads",
    "required info": r"info\.json: no '\w+'",
    "info type": r"info\.json: \w+ must be (str|int|dict), got",
    "undeclared videos": r"videos of a camera info\.json does not declare",
    "locations": r"(chunk_index|file_index|timestamp) is .*, the layout's is",
    "row task": r"rmbench/(task|tmc) 'x', meta/rmbench\.json says",
    "row instruction": r"is not one instruction of",
    "key subtasks": r"key_subtasks .* are not the subtasks",
    "paths": r"data_path/video_path differ",
    "chunks": r"chunks_size .* the layout's is",
    "tasks count": r"tasks, info\.json says",
    "stats object": r"stats\.json: not a JSON object",
    "stats key": r"no statistics for",
    "stats values": r"is not the aggregate of the episodes' own statistics",
    "episode file missing": r"missing meta/episodes/chunk-000/file-003",
    "episode file beyond": r"beyond the 2 episodes",
    "episode index": r"episode_index 7, expected 1",
    "index range": r"dataset index range",
    "key frames": r"key frames .* do not match",
    "hidden": r"rmbench/hidden is not",
    "total frames": r"total_frames \d+, the episodes hold",
    "columns": r"columns differ from info\.json",
    "data rows": r"rows, the episode's length is",
    "nulls": r"missing values",
    "column type": r"has type .* info\.json declares",
    "nan": r"holds NaN or inf",
    "index columns": r"is not \[.*\]\.\.\. as it should be for episode \d",
    "task index": r"task_index outside",
    "subtask index": r"subtask_index outside",
    "subtask end": r"subtask_end flags do not mark",
    "subtask step": r"subtask_step does not count the plan's steps up from 0",
    "format": r"rmbench\.json: dataset format 'rmbench/1'",
    "task version": r"rmbench\.json: collected on 'rmbench/\w+-v0', this rmbench's",
    "unknown task": r"rmbench\.json: unknown task 'nope'",
    "required feature": r"info\.json: no feature '[\w.]+'",
    "subtask within a step": r"subtask_index changes within a plan step",
    "video missing": r"file-001\.mp4: missing",
    "video unreadable": r"file-001\.mp4: not a readable video",
    "video frames": r"frames, the episode has",
    "video size": r"64x48, info\.json declares 64x24",
}


# ------------------------------------------------------------------ corrupting helpers
def edit_json(rel, change, replace=False):
    """Corrupts JSON file ``rel`` by ``change(data)``, in place (or replaced by its result)."""
    def corrupt(root):
        path = root / rel
        data = json.loads(path.read_text())
        result = change(data)
        path.write_text(json.dumps(result if replace else data))
    return corrupt


def edit_info(change, replace=False):
    return edit_json(L.INFO, change, replace)


def edit_parquet(rel, change):
    def corrupt(root):
        path = root / rel
        table = change(pq.read_table(path))
        pq.write_table(table, path)
    return corrupt


def replace_column(name, make):
    """A change of table column ``name`` to ``make(column)``."""
    def change(table):
        i = table.column_names.index(name)
        return table.set_column(i, name, make(table.column(name)))
    return change


def drop(name):
    return lambda table: table.drop_columns([name])


def nulls(col):
    return pa.nulls(len(col), col.type)


def as_text(col):
    return pa.array(["x"] * len(col))


def set_value(col, value, at=0):
    values = col.to_pylist()
    values[at] = value
    return pa.array(values, col.type)


def with_nan(col):
    values = col.combine_chunks().flatten().to_numpy().copy()
    values[0] = np.nan
    return pa.FixedSizeListArray.from_arrays(pa.array(values), col.type.list_size)


def write_bytes(rel, data):
    def corrupt(root):
        (root / rel).write_bytes(data)
    return corrupt


def corruptions(dataset):
    """(name, corrupt(root)) for one-field corruptions of every file the checker reads."""
    info = json.loads((dataset / L.INFO).read_text())
    out = []
    add = lambda name, fn: out.append((name, fn))  # noqa: E731

    # meta/info.json: each field removed, of the wrong type, or off by one
    for key in info:
        add(f"info: no {key}", edit_info(lambda d, k=key: d.pop(k)))
        add(f"info: {key} wrong type", edit_info(
            lambda d, k=key: d.update({k: [] if isinstance(d[k], str) else "x"})))
    for key, value in (("total_episodes", 2), ("total_episodes", 4), ("total_frames", 1),
                       ("total_tasks", 5), ("fps", 0), ("fps", 10), ("fps", True),
                       ("codebase_version", "v2.1"), ("chunks_size", 10),
                       ("data_path", "data/{episode_index}.parquet")):
        add(f"info: {key}={value}", edit_info(lambda d, k=key, v=value: d.update({k: v})))
    add("info: not an object", edit_info(lambda d: [d], replace=True))
    add("info: not json", write_bytes(L.INFO, b"{"))
    add("info: missing", lambda root: (root / L.INFO).unlink())
    add("info: no features", edit_info(lambda d: d.update(features={})))
    for key in info["features"]:
        add(f"feature {key}: removed", edit_info(lambda d, k=key: d["features"].pop(k)))
        add(f"feature {key}: dtype float64", edit_info(
            lambda d, k=key: d["features"][k].update(dtype="float64")))
    for key in (HEAD, L.STATE, L.SUBTASK_END):  # a video, a vector, a scalar
        feat = lambda k, change: edit_info(lambda d: change(d["features"][k]))  # noqa: E731
        add(f"feature {key}: no dtype", feat(key, lambda f: f.pop("dtype")))
        add(f"feature {key}: no shape", feat(key, lambda f: f.pop("shape")))
        add(f"feature {key}: shape text", feat(key, lambda f: f.update(shape="14")))
        add(f"feature {key}: shape [0]", feat(key, lambda f: f.update(shape=[0])))
        add(f"feature {key}: not a map", edit_info(lambda d, k=key: d["features"].update({k: 1})))
    add("feature: extra column", edit_info(lambda d: d["features"].update(
        extra={"dtype": "float32", "shape": [1], "names": None})))
    add("feature: camera name", edit_info(lambda d: d.update(features={
        ("observation.images.../x" if k == HEAD else k): v for k, v in d["features"].items()})))
    add("feature: video 2-d", edit_info(lambda d: d["features"][HEAD].update(shape=[48, 64])))
    add("feature: video smaller", edit_info(lambda d: d["features"][HEAD].update(shape=[24, 64, 3])))
    add("feature: state 2-d", edit_info(lambda d: d["features"][L.STATE].update(shape=[14, 1])))
    add("feature: state shape", edit_info(lambda d: d["features"][L.STATE].update(shape=[13])))
    add("feature: env names", edit_info(lambda d: d["features"][L.ENV_STATE].update(names=None)))
    add("feature: env names short", edit_info(
        lambda d: d["features"][L.ENV_STATE].update(names=["a"])))

    # meta/rmbench.json, stats.json, the tasks table
    add("rmbench: no task", edit_json(L.RMBENCH, lambda d: d.pop("task")))
    add("rmbench: task number", edit_json(L.RMBENCH, lambda d: d.update(task=1)))
    add("rmbench: format", edit_json(L.RMBENCH, lambda d: d.update(format="rmbench/1")))
    add("rmbench: task version", edit_json(
        L.RMBENCH, lambda d: d.update(gym_id=d["gym_id"].rsplit("-v", 1)[0] + "-v0")))
    add("rmbench: unknown task", edit_json(L.RMBENCH, lambda d: d.update(task="nope")))
    add("stats: not an object", edit_json(L.STATS, lambda d: [d], replace=True))
    add("stats: no action", edit_json(L.STATS, lambda d: d.pop(L.ACTION)))
    add("stats: action mean edited", edit_json(L.STATS, lambda d: d[L.ACTION]["mean"].__setitem__(
        0, d[L.ACTION]["mean"][0] + 0.5)))
    add("stats: action std text", edit_json(L.STATS, lambda d: d[L.ACTION].update(std="x")))
    add("tasks: no task_index", edit_parquet(L.TASKS, drop("task_index")))
    add("tasks: task_index text", edit_parquet(L.TASKS, replace_column("task_index", as_text)))
    add("tasks: task_index gap", edit_parquet(L.TASKS, replace_column(
        "task_index", lambda c: pc.multiply(c, 2))))
    add("tasks: no index", edit_parquet(L.TASKS, lambda t: t.replace_schema_metadata(None)))
    add("tasks: truncated", lambda root: (root / L.TASKS).write_bytes(b"PAR1"))

    # the episode's meta/episodes row
    episodes = L.episodes_file(EP)
    meta = pq.read_table(dataset / episodes)
    for name in (c for c in meta.column_names if not c.startswith("stats/")):
        add(f"episodes: {name} text", edit_parquet(episodes, replace_column(name, as_text)))
        if not name.startswith("videos/"):  # one camera's columns are checked as another's
            add(f"episodes: no {name}", edit_parquet(episodes, drop(name)))
            add(f"episodes: {name} null", edit_parquet(episodes, replace_column(name, nulls)))
    for name, value in (("episode_index", 7), ("length", 3), ("dataset_from_index", 5),
                        ("dataset_to_index", 5), ("rmbench/key_frames", [0]),
                        ("rmbench/hidden", "x"), ("rmbench/hidden", "[]"),
                        ("tasks", ["another instruction"]), ("rmbench/key_subtasks", [1, 1])):
        add(f"episodes: {name}={value}", edit_parquet(episodes, replace_column(
            name, lambda c, v=value: set_value(c, v))))
    add("episodes: two rows", edit_parquet(episodes, lambda t: pa.concat_tables([t, t])))
    add("episodes: no rows", edit_parquet(episodes, lambda t: t.slice(0, 0)))
    add("episodes: truncated", write_bytes(episodes, b"PAR1"))

    # the episode's data file
    data = L.data_file(EP)
    table = pq.read_table(dataset / data)
    for name in table.column_names:
        add(f"data: no {name}", edit_parquet(data, drop(name)))
        add(f"data: {name} null", edit_parquet(data, replace_column(name, nulls)))
        add(f"data: {name} text", edit_parquet(data, replace_column(name, as_text)))
    for name in ("episode_index", "frame_index", "index", "timestamp"):
        add(f"data: {name} off", edit_parquet(data, replace_column(
            name, lambda c: set_value(c, c[3].as_py() + 1, at=3))))
    add("data: task_index 99", edit_parquet(data, replace_column(
        "task_index", lambda c: set_value(c, 99))))
    add("data: subtask_index 99", edit_parquet(data, replace_column(
        L.SUBTASK_INDEX, lambda c: set_value(c, 99))))
    add("data: subtask_index swapped", edit_parquet(data, replace_column(
        L.SUBTASK_INDEX, lambda c: set_value(c, 1))))
    add("data: subtask_step from 1", edit_parquet(data, replace_column(
        L.SUBTASK_STEP, lambda c: pc.add(c, 1))))
    add("data: progress gone", lambda root: (edit_info(lambda d: d["features"].pop(L.PROGRESS))(root),
                                             edit_parquet(data, drop(L.PROGRESS))(root)))
    add("data: subtask_end flipped", edit_parquet(data, replace_column(
        L.SUBTASK_END, lambda c: set_value(c, not c[0].as_py()))))
    add("data: action NaN", edit_parquet(data, replace_column(L.ACTION, with_nan)))
    add("data: last row dropped", edit_parquet(data, lambda t: t.slice(0, len(t) - 1)))
    add("data: int32 index", edit_parquet(data, replace_column("index", lambda c: c.cast(pa.int32()))))
    add("data: truncated", lambda root: (root / data).write_bytes((root / data).read_bytes()[:200]))
    add("data: missing", lambda root: (root / data).unlink())

    # the episode's video
    video = L.video_file(HEAD, EP)
    add("video: missing", lambda root: (root / video).unlink())
    add("video: garbage", write_bytes(video, b"not a video"))
    add("video: empty", write_bytes(video, b""))
    add("video: truncated", lambda root: (root / video).write_bytes((root / video).read_bytes()[:300]))
    add("video: a folder", lambda root: ((root / video).unlink(), (root / video).mkdir()))
    add("video: another episode's", lambda root: shutil.copyfile(root / L.video_file(HEAD, 0),
                                                                 root / video))
    return out


@pytest.fixture(scope="module")
def refusals(dataset, tmp_path_factory):
    """name -> the checker's message for each corruption (or what else it raised)."""
    base = tmp_path_factory.mktemp("corrupt")
    messages = {}
    for i, (name, corrupt) in enumerate(corruptions(dataset)):
        root = base / str(i)
        shutil.copytree(dataset, root)
        corrupt(root)
        try:
            check_dataset(root)
        except DatasetError as err:
            messages[name] = str(err)
        except Exception as err:  # noqa: BLE001 - what the test is there to catch
            messages[name] = f"RAISED {type(err).__name__}: {err}"
        else:
            messages[name] = "ACCEPTED"
        shutil.rmtree(root)
    return messages


def test_every_corruption_gets_a_one_line_refusal_that_names_it(refusals):
    bad = {name: msg for name, msg in refusals.items()
           if msg.startswith(("RAISED", "ACCEPTED")) or "\n" in msg
           or "does not name" in msg}
    assert not bad, bad


def test_every_refusal_is_reached_by_a_corruption(refusals):
    unreached = [what for what, pattern in REFUSALS.items()
                 if not any(re.search(pattern, msg) for msg in refusals.values())]
    assert not unreached, unreached


def test_every_message_is_a_known_refusal(refusals):
    unknown = {name: msg for name, msg in refusals.items()
               if not any(re.search(p, msg) for p in REFUSALS.values())}
    assert not unknown, unknown


def test_an_unforeseen_failure_is_still_one_line(dataset, tmp_path, monkeypatch):
    from rmbench.data import check

    root = tmp_path / "d"
    shutil.copytree(dataset, root)
    monkeypatch.setattr(check, "_check_video", lambda *a: 1 / 0)
    with pytest.raises(DatasetError, match=r"does not name \(ZeroDivisionError: division by zero\)"):
        check_dataset(root)
