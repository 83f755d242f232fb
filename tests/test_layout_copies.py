"""Rendered layout copies: the source comes back unchanged, copies move the scene, resume, errors."""

import json
import shutil

import numpy as np
import pyarrow.parquet as pq
import pytest

from rmbench.cli.main import main
from rmbench.data import DatasetError, collect, writer
from rmbench.data import layout as L
from rmbench.data.check import check_dataset
from rmbench.data.layout_copies import COPY_KEY, copy_layouts, shifts
from rmbench.data.layout_shift import LayoutShift, xy_columns
from rmbench.data.reader import Dataset
from rmbench.envs.noise import NoiseSpec
from rmbench.envs.registration import make
from rmbench.eval.harness import dataset_seeds
from rmbench.policies.builtin import ReplayPolicy
from rmbench.sim import robot
from rmbench.sim.kinematics import GraspKinematics
from tests.conftest import DATA_TASK as TASK
from tests.conftest import small_collection

COPIES, REACH = 2, 0.02


@pytest.fixture(scope="module")
def noisy(tmp_path_factory):
    """Two demonstrations recorded with action noise: the replay must re-draw it."""
    out = tmp_path_factory.mktemp("data") / "noisy"
    collect(small_collection(out, episodes=2, noise=NoiseSpec("white", 0.02)))
    return out


@pytest.fixture(scope="module")
def copied(noisy, tmp_path_factory):
    out = tmp_path_factory.mktemp("data") / "copies"
    summary = copy_layouts(noisy, out, COPIES, REACH, progress=False)
    return out, summary


def contents(root):
    ds = Dataset(root)
    return ([pq.read_table(root / L.data_file(e)).to_pydict() for e in range(ds.num_episodes)],
            ds.episodes, [ds.video_path(c, e).read_bytes() for e in range(ds.num_episodes)
                          for c in ds.cameras])


def test_each_demonstration_comes_back_unchanged_before_its_copies(noisy, copied):
    out, summary = copied
    src, dst = Dataset(noisy), Dataset(out)
    assert summary.out_of_reach == 0 and dst.num_episodes == 2 * (COPIES + 1)
    check_dataset(out)
    for e in range(src.num_episodes):
        d = e * (COPIES + 1)
        a, b = src.episode(e), dst.episode(d)
        assert b.hidden[COPY_KEY] == {"episode": e, "copy": 0, "shift": [0.0, 0.0]}
        for field in ("state", "action", "ee_pose", "environment_state", "progress",
                      "subtask_index", "subtask_end"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        for cam in src.cameras:  # the recording's videos and their statistics, as they are
            assert src.video_path(cam, e).read_bytes() == dst.video_path(cam, d).read_bytes()
            a_stats, b_stats = src.image_stats(e)[cam], dst.image_stats(d)[cam]
            assert a_stats.keys() == b_stats.keys() == {"min", "max", "mean", "std", "count"}
            for k in a_stats:
                np.testing.assert_array_equal(a_stats[k], b_stats[k])
        # a drawn copy's statistics are its own frames'
        assert not np.array_equal(src.image_stats(e)[src.cameras[0]]["mean"],
                                  dst.image_stats(d + 1)[src.cameras[0]]["mean"])


def test_a_copy_moves_every_position_and_the_arms_with_the_scene(noisy, copied):
    out, _ = copied
    src, dst = Dataset(noisy), Dataset(out)
    source = src.episode(1)
    xs, ys = xy_columns(src.state_names)
    kin = GraspKinematics()
    for k in range(1, COPIES + 1):
        copy = dst.episode(COPIES + 1 + k)
        delta = shifts(0, 1, COPIES, REACH)[k]
        assert copy.hidden[COPY_KEY]["shift"] == pytest.approx(delta, abs=1e-6)
        assert copy.seed == source.seed and copy.instruction == source.instruction
        moved = copy.environment_state - source.environment_state
        np.testing.assert_allclose(moved[:, xs], delta[0], atol=1e-6)
        np.testing.assert_allclose(moved[:, ys], delta[1], atol=1e-6)
        rest = np.setdiff1d(np.arange(moved.shape[1]), np.concatenate([xs, ys]))
        np.testing.assert_array_equal(moved[:, rest], 0.0)
        expect = LayoutShift(src.state_names).shift(source, delta)
        np.testing.assert_array_equal(copy.state, expect.state)
        np.testing.assert_array_equal(copy.action, expect.action)
        # The grasp poses are those of the drawn arms, both of them, at every frame...
        for t in range(0, len(copy), 7):
            for a, side in enumerate(robot.SIDES):
                pos, _ = kin.forward(side, copy.state[t, 7 * a: 7 * a + 6].astype(np.float64))
                np.testing.assert_allclose(copy.ee_pose[t, 7 * a: 7 * a + 3], pos, atol=1e-4)
        # ... and follow the shift where an arm works (at rest it stays where it was).
        follows = [np.abs(copy.ee_pose[:, a:a + 2] - source.ee_pose[:, a:a + 2] - delta)
                   .max(1) < 2e-3 for a in (0, 7)]
        assert (follows[0] | follows[1]).mean() > 0.5
        for cam in dst.cameras:  # and the cameras see another scene
            assert not np.array_equal(copy.frames[cam], source.frames[cam])


def test_evaluation_reads_the_recorded_episodes_of_a_copies_dataset(noisy, copied):
    out, _ = copied
    assert dataset_seeds(out, TASK) == dataset_seeds(noisy, TASK)  # each layout once
    env = make(TASK)
    try:
        replay = ReplayPolicy(str(out), env)
    finally:
        env.close()
    assert list(replay.by_seed.values()) == [0, COPIES + 1]  # copy 0: what replays


def test_same_dataset_whatever_the_worker_count(noisy, copied, tmp_path):
    out = tmp_path / "copies"
    assert main(["dataset", "copy-layouts", str(noisy), "--out", str(out), "--copies",
                 str(COPIES), "--reach", str(REACH), "--workers", "2", "--json"]) == 0
    assert contents(out) == contents(copied[0])


def test_an_interrupted_run_resumes_to_the_same_dataset(noisy, copied, tmp_path, monkeypatch):
    out = tmp_path / "copies"
    real, commits = writer.write_parquet, []

    def die_on_fifth_commit(path, table):
        if "episodes" in path.parts:
            commits.append(path)
            if len(commits) == 5:
                raise KeyboardInterrupt  # killed between the second demonstration's copies
        real(path, table)

    monkeypatch.setattr(writer, "write_parquet", die_on_fifth_commit)
    with pytest.raises(KeyboardInterrupt):
        copy_layouts(noisy, out, COPIES, REACH, progress=False)
    monkeypatch.setattr(writer, "write_parquet", real)
    assert Dataset(out).num_episodes == 4  # the first demonstration's three, and one more
    summary = copy_layouts(noisy, out, COPIES, REACH, progress=False)
    assert summary.new_episodes == 2
    assert contents(out) == contents(copied[0])


def test_a_scene_of_fixed_pieces_only_is_copied(mn_dataset, tmp_path):
    out = tmp_path / "copies"  # press_button: buttons and lamps, nothing free
    copy_layouts(mn_dataset, out, 1, REACH, episodes=1, progress=False)
    ds = Dataset(out)
    source, copy = ds.episode(0, cameras=[]), ds.episode(1, cameras=[])
    dx, dy = copy.hidden[COPY_KEY]["shift"]
    xs, ys = xy_columns(ds.state_names)
    moved = copy.environment_state - source.environment_state
    np.testing.assert_allclose(moved[:, xs], dx, atol=1e-6)
    np.testing.assert_allclose(moved[:, ys], dy, atol=1e-6)


def test_bad_input_is_a_one_line_error(dataset, noisy, copied, tmp_path, capsys):
    with pytest.raises(DatasetError, match="other arguments"):
        copy_layouts(noisy, copied[0], COPIES + 1, REACH, progress=False)
    with pytest.raises(DatasetError, match="is the source dataset"):
        copy_layouts(noisy, noisy, COPIES, REACH, overwrite=True, progress=False)
    assert Dataset(noisy).num_episodes == 2  # and nothing was deleted
    with pytest.raises(ValueError, match="copies must be >= 0"):
        copy_layouts(noisy, tmp_path / "a", COPIES, float("nan"), progress=False)
    assert main(["dataset", "copy-layouts", str(noisy), "--out", str(tmp_path / "b"),
                 "--episodes", "3"]) == 2
    assert "episodes must be in 1..2" in capsys.readouterr().err
    assert main(["dataset", "copy-layouts", str(tmp_path / "none"), "--out",
                 str(tmp_path / "c")]) == 2
    assert "no such dataset folder" in capsys.readouterr().err
    # A recording that no longer replays (its actions edited) is refused, not copied.
    broken = tmp_path / "broken"
    shutil.copytree(dataset, broken)
    table = pq.read_table(broken / L.data_file(0))
    actions = np.stack(table.column(L.ACTION).to_numpy(zero_copy_only=False)).astype(np.float32)
    actions[5:, 0] += 0.05
    table = table.set_column(table.column_names.index(L.ACTION), L.ACTION,
                             writer.vector_column(actions))
    pq.write_table(table, broken / L.data_file(0))
    with pytest.raises(DatasetError, match="replay differs"):
        copy_layouts(broken, tmp_path / "d", 1, REACH, episodes=1, progress=False)
    meta = json.loads((tmp_path / "d" / L.RMBENCH).read_text())
    assert meta["episodes"] == 0  # nothing of the broken episode was committed


def test_a_hidden_object_stays_zeroed_in_a_copy():
    """cover_blocks zeroes a covered cube's pose behind its visibility flag; a copy moves the
    cubes in view and leaves the hidden one at zero (the arms at rest: nothing to solve)."""
    from rmbench.data.reader import Episode
    from rmbench.sim.station import home_action
    from rmbench.tasks import get_task

    names = get_task("cover_blocks").state_names
    env = np.random.default_rng(0).uniform(-0.2, 0.2, (3, len(names))).astype(np.float32)
    flag = names.index("cube_left_visible")
    hidden = [i for i, n in enumerate(names) if n.startswith("cube_left_")]
    env[:, flag] = 1.0
    env[1, hidden] = 0.0  # covered at frame 1
    rest = np.tile(home_action().astype(np.float32), (3, 1))
    ep = Episode(0, 0, "cover_blocks", "", "M(n)", {}, rest, np.zeros((3, 14), np.float32),
                 rest, np.zeros(3, np.int64), np.zeros(3, bool), np.zeros(3, np.float32),
                 np.zeros(3, np.float32), [], [], environment_state=env)
    moved = LayoutShift(names).shift(ep, (0.01, -0.02)).environment_state - env
    xs, ys = xy_columns(names)
    x0, y0 = names.index("cube_left_x"), names.index("cube_left_y")
    np.testing.assert_array_equal(moved[1, [x0, y0]], 0.0)
    np.testing.assert_allclose(moved[[0, 2]][:, [x0, y0]], [[0.01, -0.02]] * 2, atol=1e-6)
    others = [i for i in xs if i != x0]
    np.testing.assert_allclose(moved[:, others], 0.01, atol=1e-6)
    np.testing.assert_allclose(moved[:, [i for i in ys if i != y0]], -0.02, atol=1e-6)
