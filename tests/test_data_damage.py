"""A damaged or contested dataset folder: a one-line error naming what is wrong, and nothing
of it deleted or read as something else."""

import json
import shutil

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from rmbench.data import CollectConfig, DatasetError, collect
from rmbench.data import layout as L
from rmbench.data.reader import Dataset, column
from rmbench.data.writer import DatasetWriter, vector_column
from tests.conftest import DATA_TASK as TASK
from tests.conftest import small_collection as small


@pytest.fixture
def copied(dataset, tmp_path):
    out = tmp_path / "ds"
    shutil.copytree(dataset, out)
    return out


def test_a_missing_episode_before_later_ones_is_damage_not_a_place_to_restart(copied):
    """Episodes commit in order: a meta file missing before later ones was lost, and a resume
    that started over from it would delete the episodes after it."""
    (copied / L.episodes_file(1)).unlink()
    with pytest.raises(DatasetError, match=r"file-001\.parquet is missing while the dataset "
                                           r"holds 3 episodes: it is damaged"):
        collect(small(copied))
    assert (copied / L.episodes_file(2)).exists() and (copied / L.data_file(2)).exists()


def test_a_skipped_seed_is_kept_before_the_next_commit(copied):
    """A run killed after a skip and before its next episode's bookkeeping resumes knowing the
    skip, so it tries the seeds a run never stopped tries."""
    cfg = small(copied)
    w = DatasetWriter(cfg.out, cfg.task, cfg.spec, cfg.identity())
    try:
        w.skip(99, "the expert failed")
        saved = json.loads((copied / L.RMBENCH).read_text())["skipped"]
    finally:
        w._lock.close()  # killed: no close(), no bookkeeping after the skip
    assert {"seed": 99, "reason": "the expert failed"} in saved
    resumed = DatasetWriter(cfg.out, cfg.task, cfg.spec, cfg.identity())
    try:  # the skip is known: the next seed is the one after it, as in a run never stopped
        assert resumed.next_seed == 100 and resumed.skipped[-1]["seed"] == 99
    finally:
        resumed.close()


def test_a_second_writer_of_a_folder_is_refused_while_the_first_writes(copied):
    cfg = small(copied)
    first = DatasetWriter(cfg.out, cfg.task, cfg.spec, cfg.identity())
    try:
        with pytest.raises(DatasetError, match="is being written by another process"):
            DatasetWriter(cfg.out, cfg.task, cfg.spec, cfg.identity())
    finally:
        first.close()
    DatasetWriter(cfg.out, cfg.task, cfg.spec, cfg.identity()).close()  # free again
    assert Dataset(copied).num_episodes == 3


@pytest.mark.parametrize("damage, said", [
    ("other episode", r"file-001\.parquet: (\d+ rows, its episode's length is|rows of episode 0)"),
    ("short", r"file-001\.parquet: \d+ rows, its episode's length is \d+"),
    ("no state", r"file-001\.parquet: no column\(s\) \['observation\.state'\]"),
    ("narrow action", r"file-001\.parquet: 'action' holds 13 values a frame, info\.json "
                      r"declares 14"),
    ("unknown subtask", r"file-001\.parquet: subtask_index 99 of \d+ subtasks"),
])
def test_an_episode_is_read_only_from_its_own_whole_data_file(copied, damage, said):
    """Training reads episodes without their videos, so the data file alone must be checked:
    another episode's file, one cut short or one without a column is an error naming it."""
    path = copied / L.data_file(1)
    if damage == "other episode":
        shutil.copy(copied / L.data_file(0), path)
    else:
        table = pq.read_table(path)
        if damage == "short":
            table = table.slice(0, len(table) - 3)
        elif damage == "no state":
            table = table.drop_columns([L.STATE])
        elif damage == "narrow action":
            i = table.column_names.index(L.ACTION)
            table = table.set_column(i, L.ACTION, vector_column(column(table, L.ACTION)[:, :13]))
        else:
            i = table.column_names.index(L.SUBTASK_INDEX)
            table = table.set_column(i, L.SUBTASK_INDEX, pa.array(
                np.full(len(table), 99, dtype=np.int64)))
        pq.write_table(table, path)
    ds = Dataset(copied)
    assert len(ds.episode(0, cameras=[])) == ds.lengths[0]
    with pytest.raises(DatasetError, match=said):
        ds.episode(1, cameras=[])


@pytest.mark.parametrize("name, value, said", [
    ("tasks", [], r"'tasks' holds 0 texts"),
    ("rmbench/hidden", "{bad", r"rmbench/hidden is not JSON"),
])
def test_an_episode_record_of_bad_values_is_named(copied, name, value, said):
    path = copied / L.episodes_file(1)
    table = pq.read_table(path)
    i = table.column_names.index(name)
    table = table.set_column(i, name, pa.array([value], type=table.schema.field(name).type))
    pq.write_table(table, path)
    with pytest.raises(DatasetError, match=r"file-001\.parquet: " + said):
        _ = Dataset(copied).episodes


def test_an_info_json_counting_fewer_episodes_than_are_committed_is_damage(copied):
    info = json.loads((copied / L.INFO).read_text())
    (copied / L.INFO).write_text(json.dumps({**info, "total_episodes": 1}))
    with pytest.raises(DatasetError, match=r"info\.json counts 1 episodes, but .*file-001\.parquet "
                                           r"holds one more"):
        _ = Dataset(copied).episodes


def test_records_of_the_wrong_shape_are_one_line_errors(copied):
    (copied / L.STATS).write_text("[]")
    with pytest.raises(DatasetError, match=r"stats\.json: not a JSON object \(a list\)"):
        _ = Dataset(copied).stats
    (copied / L.RMBENCH).write_text(json.dumps([1, 2]))
    with pytest.raises(DatasetError, match=r"rmbench\.json is not the record this rmbench "
                                           r"writes"):
        collect(small(copied))


def test_every_camera_the_station_has_may_be_recorded_once(tmp_path):
    CollectConfig(TASK, tmp_path / "a", cameras=("head", "third_person"))
    with pytest.raises(ValueError, match="cameras named twice"):
        CollectConfig(TASK, tmp_path / "b", cameras=("head", "head"))
    with pytest.raises(ValueError, match=r"unknown camera\(s\) \['top'\]"):
        CollectConfig(TASK, tmp_path / "c", cameras=("top",))
