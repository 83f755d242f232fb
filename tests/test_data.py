"""Datasets: round trip, validation, resume after a crash or SIGKILL, worker-count determinism."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from rmbench.data import CollectConfig, DatasetError, collect, record, writer
from rmbench.data import layout as L
from rmbench.data.check import check_dataset
from rmbench.data.reader import Dataset
from rmbench.data.record import run_expert
from rmbench.envs.registration import make
from rmbench.experts import make_expert
from tests.conftest import DATA_TASK as TASK
from tests.conftest import small_collection as small


def copy(src: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "copy"
    shutil.copytree(src, dst)
    return dst


def contents(root: Path) -> tuple[list, list]:
    """Everything that defines the episodes: frame tables and meta rows (minus timings)."""
    ds = Dataset(root)
    tables = [pq.read_table(root / L.data_file(e)).to_pydict() for e in range(ds.num_episodes)]
    return tables, ds.episodes


def test_round_trip_matches_a_fresh_rollout(dataset):
    ds = Dataset(dataset)
    assert ds.num_episodes == 3 and ds.task == TASK and ds.cameras == ["head", "left_wrist"]
    ep = ds.episode(1)
    env = make(TASK, render=True, cameras=("head", "left_wrist"), width=64, height=48)
    traj = run_expert(env, make_expert(env), ep.seed)
    # States and actions are stored exactly (float32 of what the env saw and was sent).
    np.testing.assert_array_equal(ep.state, np.asarray(traj.state, np.float32))
    np.testing.assert_array_equal(ep.action, np.asarray(traj.action, np.float32))
    np.testing.assert_array_equal(ep.subtask_index, traj.subtask)
    assert ep.hidden == json.loads(json.dumps(traj.hidden, default=lambda v: v.tolist()))
    # Frames within codec tolerance of a fresh render of the stored actions.
    obs, _ = env.reset(seed=ep.seed)
    for t in range(len(ep)):
        if t in (0, len(ep) // 2, len(ep) - 1):
            for cam in ds.cameras:
                err = np.abs(ep.frames[cam][t].astype(int) - obs["pixels"][cam].astype(int)).mean()
                assert err < 6.0, (cam, t, err)  # H.264 CRF 23 on 64x48 frames
        obs, *_ = env.step(ep.action[t].astype(np.float64))
    env.close()
    # Subtask ends: last frame of each label run; key frames are exactly those frames.
    assert ep.subtask_end[-1] and ep.key_frames == np.flatnonzero(ep.subtask_end).tolist()
    assert [ep.subtask_text(k) for k in ep.key_frames] == [
        "watch the reference object", "pick up the matching object"]
    assert ep.instruction in ds.instructions


def test_stored_actions_replay_the_episode_exactly(dataset):
    ep = Dataset(dataset).episode(0, cameras=[])
    env = make(TASK, render=False)
    env.reset(seed=ep.seed)
    for a in ep.action:
        *_, terminated, truncated, info = env.step(a.astype(np.float64))
    assert terminated and info["is_success"]


def test_metadata_is_lerobot_v3(dataset):
    info = json.loads((dataset / L.INFO).read_text())
    assert info["codebase_version"] == "v3.0" and info["total_episodes"] == 3
    assert info["features"]["observation.state"]["shape"] == [14]
    stats = json.loads((dataset / L.STATS).read_text())
    assert stats["action"]["count"] == [info["total_frames"]]
    assert np.array(stats["observation.images.head"]["mean"]).shape == (3, 1, 1)
    rows = Dataset(dataset).episodes
    assert [r["dataset_from_index"] for r in rows] == [0, rows[0]["length"],
                                                       rows[0]["length"] + rows[1]["length"]]
    assert [r["rmbench/seed"] for r in rows] == [0, 1, 2]


def test_check_accepts_the_dataset(dataset):
    assert check_dataset(dataset)["episodes"] == 3


def test_check_names_a_truncated_parquet(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    path = root / L.data_file(1)
    path.write_bytes(path.read_bytes()[:200])
    with pytest.raises(DatasetError, match=r"file-001\.parquet: not a readable parquet"):
        check_dataset(root)


def test_check_names_a_missing_video(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    (root / L.video_file("observation.images.left_wrist", 2)).unlink()
    with pytest.raises(DatasetError, match=r"left_wrist/chunk-000/file-002\.mp4: missing"):
        check_dataset(root)


@pytest.mark.parametrize("kind", ["data", "video"])
def test_check_names_an_interrupted_episodes_files(dataset, tmp_path, kind):
    root = copy(dataset, tmp_path)  # a collection stopped inside episode 3's commit
    src, dst = ((L.data_file(0), L.data_file(3)) if kind == "data" else
                (L.video_file(L.image_key("head"), 0), L.video_file(L.image_key("head"), 3)))
    shutil.copy(root / src, root / dst)
    (root / dst).with_name(".x.999999999.tmp").write_bytes(b"x")  # a leftover is not named
    with pytest.raises(DatasetError, match=r"file-003\.(parquet|mp4): beyond the 3 episodes"):
        check_dataset(root)


def test_check_names_a_corrupt_video(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    (root / L.video_file("observation.images.head", 0)).write_bytes(b"not a video")
    with pytest.raises(DatasetError, match=r"file-000\.mp4: not a readable video"):
        check_dataset(root)


def test_resume_after_a_crash_mid_commit(dataset, tmp_path, monkeypatch):
    out = tmp_path / "ds"
    real = writer.write_parquet

    def crash_on_second_meta(path, table):
        if path.name == "file-001.parquet" and "episodes" in path.parts:
            raise KeyboardInterrupt  # killed after episode 1's data and videos were written
        real(path, table)

    monkeypatch.setattr(writer, "write_parquet", crash_on_second_meta)
    with pytest.raises(KeyboardInterrupt):
        collect(small(out))
    assert (out / L.data_file(1)).exists() and Dataset(out).num_episodes == 1
    monkeypatch.setattr(writer, "write_parquet", real)
    summary = collect(small(out))
    assert summary.new_episodes == 2
    assert contents(out) == contents(dataset)
    check_dataset(out)


def test_a_collection_stopped_at_its_start_resumes(dataset, tmp_path, monkeypatch):
    out = tmp_path / "ds"
    real = writer.write_parquet

    def crash_on_first_table(path, table):
        raise KeyboardInterrupt  # killed after meta/rmbench.json, before the task tables

    monkeypatch.setattr(writer, "write_parquet", crash_on_first_table)
    with pytest.raises(KeyboardInterrupt):
        collect(small(out))
    (out / "meta" / ".tasks.parquet.999999999.tmp").write_bytes(b"x")  # a dead writer's
    monkeypatch.setattr(writer, "write_parquet", real)
    assert collect(small(out)).new_episodes == 3
    assert contents(out) == contents(dataset) and not list(out.rglob(".*.tmp"))
    # a folder holding nothing but such leftovers is taken as empty
    bare = tmp_path / "bare"
    (bare / "meta").mkdir(parents=True)
    (bare / "meta" / ".rmbench.json.999999999.tmp").write_bytes(b"x")
    assert collect(small(bare, episodes=1)).new_episodes == 1


def test_sigkill_and_resume_loses_and_duplicates_nothing(dataset, tmp_path):
    out = tmp_path / "ds"
    cmd = [sys.executable, "-m", "rmbench.cli.main", "collect", TASK, "--episodes", "3",
           "--seed", "0", "--out", str(out), "--cameras", "head", "left_wrist",
           "--resolution", "64x48", "--json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while not (out / L.episodes_file(0)).exists() and time.time() < deadline:
        assert proc.poll() is None, "the collection ended before it was killed"
        time.sleep(0.05)
    time.sleep(0.3)  # somewhere inside the next episode
    os.kill(proc.pid, signal.SIGKILL)
    assert proc.wait(timeout=30) == -signal.SIGKILL  # killed, not finished
    # killed with its work unfinished: the last episode is not written yet
    assert not (out / L.episodes_file(2)).exists()
    assert subprocess.run(cmd, capture_output=True, timeout=300).returncode == 0
    assert contents(out) == contents(dataset)
    check_dataset(out)


@pytest.fixture(scope="module")
def two_worker_dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("workers") / "ds"
    collect(small(out, workers=2))
    return out


def test_same_dataset_whatever_the_worker_count(dataset, two_worker_dataset):
    assert contents(two_worker_dataset) == contents(dataset)


def test_same_videos_whatever_the_worker_count(dataset, two_worker_dataset):
    # Bit for bit: rendering is deterministic, and so is encoding with MB-tree off (see
    # rmbench.video.VideoCodec), in any process that runs the same source (rmbench.source).
    out = two_worker_dataset
    for e in range(3):
        for cam in ("head", "left_wrist"):
            key = L.image_key(cam)
            assert (out / L.video_file(key, e)).read_bytes() == \
                (dataset / L.video_file(key, e)).read_bytes()


def test_other_arguments_on_an_existing_dataset_are_refused(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    with pytest.raises(DatasetError, match=r"other arguments \(seed 0 there, 7 asked\)"):
        collect(small(root, seed=7))
    with pytest.raises(DatasetError, match="resolution"):
        collect(small(root, width=96, height=72))
    with pytest.raises(ValueError, match="already holds 3 episodes"):
        collect(small(root, episodes=2))
    assert check_dataset(root)["episodes"] == 3  # nothing was touched


def test_a_fingerprint_tells_other_demonstrations_apart(dataset, tmp_path):
    root = copy(dataset, tmp_path)  # the same demonstrations elsewhere: the same fingerprint
    assert Dataset(root).fingerprint == Dataset(dataset).fingerprint
    meta = json.loads((root / L.RMBENCH).read_text())
    meta["collection"]["resolution"] = "128x96"  # recorded at another resolution
    (root / L.RMBENCH).write_text(json.dumps(meta))
    assert Dataset(root).fingerprint != Dataset(dataset).fingerprint


def test_a_damaged_info_json_is_named_when_resuming(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    files = sorted(p.relative_to(root) for p in root.rglob("*"))
    (root / L.INFO).write_text("{bad")
    with pytest.raises(DatasetError, match=r"info\.json: damaged"):
        collect(small(root, episodes=4))
    assert sorted(p.relative_to(root) for p in root.rglob("*")) == files  # nothing removed


def test_overwrite_starts_over_and_foreign_folders_are_safe(tmp_path):
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me")
    with pytest.raises(DatasetError, match="holds no rmbench dataset"):
        collect(small(foreign, episodes=1))
    with pytest.raises(DatasetError, match="refusing to delete"):
        collect(small(foreign, episodes=1, overwrite=True))
    assert (foreign / "notes.txt").read_text() == "keep me"


def overwrite_killed_after(root, survives: int, monkeypatch) -> None:
    """An --overwrite of ``root`` killed after ``survives`` of its deletions."""
    real, deleted = writer._delete, []

    def killed(path):
        if len(deleted) == survives:
            raise KeyboardInterrupt
        deleted.append(path)
        real(path)

    with monkeypatch.context() as m:
        m.setattr(writer, "_delete", killed)
        with pytest.raises(KeyboardInterrupt):
            collect(small(root, episodes=1, overwrite=True))


def test_an_overwrite_killed_part_way_can_overwrite_again(dataset, tmp_path, monkeypatch):
    root = copy(dataset, tmp_path)
    for survives in range(4):  # killed after 0, 1, 2, 3 deletions
        overwrite_killed_after(root, survives, monkeypatch)
        assert (root / L.RMBENCH).exists()  # still known as a dataset
    collect(small(root, episodes=1, overwrite=True))
    assert Dataset(root).num_episodes == 1


def test_an_overwrite_killed_part_way_leaves_no_episode_without_its_data(dataset, tmp_path,
                                                                          monkeypatch):
    # the episodes' rows commit them: deleted first, a plain re-run after the kill collects
    # the episodes again rather than resuming past ones whose data or videos are gone
    for survives in (1, 2):  # info.json deleted; info.json and the episodes' rows
        root = copy(dataset, tmp_path / str(survives))
        overwrite_killed_after(root, survives, monkeypatch)
        left = 3 if survives == 1 else 0  # the episodes whose rows and data are still there
        collect(small(root, episodes=left + 1))
        assert check_dataset(root)["episodes"] == left + 1


def test_a_damaged_episode_record_is_named_when_resuming(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    (root / L.episodes_file(1)).write_bytes(b"")
    with pytest.raises(DatasetError, match=r"file-001\.parquet: unreadable"):
        collect(small(root, episodes=4))


def test_failed_seeds_are_skipped_and_logged(tmp_path, monkeypatch):
    real = record.run_expert

    def fail_seed_1(env, expert, seed, *args, **kwargs):
        traj = real(env, expert, seed, *args, **kwargs)
        if seed == 1:
            traj.success, traj.reason = False, "timeout"
        return traj

    monkeypatch.setattr(record, "run_expert", fail_seed_1)
    out = tmp_path / "ds"
    summary = collect(small(out, episodes=2, cameras=("head",)))
    assert summary.skipped == [{"seed": 1, "reason": "timeout"}]
    assert [r["rmbench/seed"] for r in Dataset(out).episodes] == [0, 2]
    assert json.loads((out / L.RMBENCH).read_text())["skipped"] == summary.skipped


def test_evaluation_seeds_are_refused_for_training():
    with pytest.raises(ValueError, match="evaluation episodes"):
        CollectConfig(TASK, "/tmp/x", seed=100000)


def test_lerobot_reads_the_dataset(dataset):
    lerobot = pytest.importorskip("lerobot.datasets.lerobot_dataset")
    ds = lerobot.LeRobotDataset("local/rmbench", root=dataset, video_backend="pyav")
    ours = Dataset(dataset)
    assert ds.num_episodes == 3 and ds.num_frames == ours.num_frames
    item = ds[ours.lengths[0] + 5]
    ep = ours.episode(1, cameras=[])
    np.testing.assert_array_equal(item["action"].numpy(), ep.action[5])
    assert item["subtask"] == ep.subtask_text(5) and item["task"] == ep.instruction


def test_cli_check_and_collect_errors_are_one_line(dataset, tmp_path, capsys):
    from rmbench.cli.main import main

    assert main(["dataset", "check", str(dataset)]) == 0
    assert capsys.readouterr().out.startswith("ok: 3 episodes")
    root = copy(dataset, tmp_path)
    (root / L.data_file(0)).write_bytes(b"")
    assert main(["dataset", "check", str(root)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "file-000.parquet" in err
    assert main(["collect", TASK, "--out", str(root), "--seed", "5", "--episodes", "3"]) == 2
    assert "other arguments" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:  # argparse's own usage error
        main(["collect", TASK, "--out", str(tmp_path / "x"), "--resolution", "320by240"])
    assert exit_.value.code == 2 and "expected WIDTHxHEIGHT, e.g. 320x240" in capsys.readouterr().err


def test_every_push_of_press_button_is_its_own_subtask():
    # press_button's plan repeats "press the left button once" d1 times: each push must end in
    # the data (one end flag, one key frame) where the simulator counts it, or the planner
    # cannot count pushes.
    env = make("press_button", obs_type="environment_state_agent_pos")
    seed = 100001  # d1 = 4, d2 = 6: eleven plan steps
    _, info = env.reset(seed=seed)
    traj = run_expert(env, make_expert(env), seed)
    assert traj.success
    ends = np.flatnonzero(writer.subtask_ends(np.asarray(traj.step)))
    assert [traj.subtask[e] for e in ends] == info["plan"] and len(info["plan"]) == 11
    # an end frame's action is the one after which the simulator's count of steps went up
    env.reset(seed=seed)
    counted = []
    for t, action in enumerate(traj.executed):
        *_, step_info = env.step(action)
        if step_info["subtask_end"]:
            counted.append(t)
    assert counted == ends.tolist() and ends[-1] == len(traj) - 1
    env.close()


def test_a_dataset_of_another_task_version_is_refused_and_not_extended(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    meta = json.loads((root / L.RMBENCH).read_text())
    old = meta["gym_id"].rsplit("-v", 1)[0] + "-v0"
    (root / L.RMBENCH).write_text(json.dumps({**meta, "gym_id": old}))
    with pytest.raises(DatasetError, match=rf"collected on '{old}'.*collect it again") as err:
        check_dataset(root)
    assert "\n" not in str(err.value)
    with pytest.raises(DatasetError, match=rf"another dataset format or task version \(gym_id "
                                           rf"'{old}' there"):
        collect(small(root, episodes=4))
    assert json.loads((root / L.RMBENCH).read_text())["gym_id"] == old  # nothing was touched


def test_a_dataset_of_the_previous_format_is_refused_in_one_line(dataset, tmp_path):
    root = copy(dataset, tmp_path)
    meta = json.loads((root / L.RMBENCH).read_text())
    (root / L.RMBENCH).write_text(json.dumps({**meta, "format": "rmbench/1"}))
    with pytest.raises(DatasetError, match=r"format 'rmbench/1'.*collect it again") as err:
        check_dataset(root)
    assert "\n" not in str(err.value)
