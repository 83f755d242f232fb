"""Shifted layout copies are solved once per dataset: a second training reads them back; a
damaged, stale or mismatched cache file is solved again rather than trusted, and a dataset
folder the cache cannot be written to still trains."""

import os
import shutil

import numpy as np
import pytest

from rmbench.data.layout_shift import (
    LayoutShift,
    add_layout_copies,
    layout_copies_cached,
    solve_layout_copies,
)
from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import DemoDataset

COPIES, REACH = 2, 0.02
FIELDS = ("state", "action", "environment_state")


@pytest.fixture
def root(dataset, tmp_path):
    out = tmp_path / "ds"
    shutil.copytree(dataset, out, ignore=shutil.ignore_patterns(".cache"))
    return out


@pytest.fixture
def solves(monkeypatch):
    """How many single copies were solved."""
    calls = []
    shift = LayoutShift.shift
    monkeypatch.setattr(LayoutShift, "shift", lambda self, ep, d: calls.append(1) or shift(self, ep, d))
    return calls


def with_copies(root, seed=0):
    examples = DemoDataset(Dataset(root), chunk=8, cameras=[], environment_state=True)
    kept = add_layout_copies(examples, COPIES, REACH, seed)
    return examples.low_dim[len(examples.low_dim) - kept:]


def assert_same(a, b):
    assert len(a) == len(b) > 0
    for x, y in zip(a, b, strict=True):
        assert x.index == y.index and x.instruction == y.instruction
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(x, f), getattr(y, f))


def test_copies_are_solved_once_and_read_back(root, solves):
    n = Dataset(root).num_episodes
    first = with_copies(root)
    assert len(solves) == COPIES * n
    files = list((root / ".cache").glob("layout-shift-*.npz"))
    assert len(files) == 1
    again = with_copies(root)
    assert len(solves) == COPIES * n + 1  # the first copy solved again as the check
    assert_same(first, again)
    with_copies(root, seed=1)  # another seed draws other shifts: its own file
    assert len(list((root / ".cache").glob("layout-shift-*.npz"))) == 2


def test_a_dataset_copied_elsewhere_keeps_its_copies(root, tmp_path, solves):
    """The cache is named by the data files' bytes, not their times: a copy of the folder
    (another machine, an archive that keeps whole seconds) reads the copies back."""
    first = with_copies(root)
    moved = tmp_path / "moved"
    shutil.copytree(root, moved)
    for f in (moved / "data").rglob("*.parquet"):
        os.utime(f, ns=(10**9, 10**9))
    solved = len(solves)
    assert_same(first, with_copies(moved))
    assert len(solves) == solved + 1  # the first copy solved again as the check, no more


def test_copies_solved_across_workers_are_the_ones_training_solves(root, tmp_path, solves):
    alone = tmp_path / "alone"
    shutil.copytree(root, alone)
    assert not layout_copies_cached(root, COPIES, REACH, 0)
    kept = solve_layout_copies(root, COPIES, REACH, 0, workers=2)
    assert layout_copies_cached(root, COPIES, REACH, 0) and solves == []  # all in the workers
    read = with_copies(root)
    assert len(read) == kept and len(solves) == 1  # training read them: one solved as the check
    assert_same(read, with_copies(alone))  # solved in this process, one after another


def test_a_damaged_or_stale_cache_is_solved_again(root, solves, caplog):
    first = with_copies(root)
    (path,) = (root / ".cache").glob("layout-shift-*.npz")
    path.write_bytes(path.read_bytes()[:200])  # cut short
    solved = len(solves)
    assert_same(first, with_copies(root))
    assert len(solves) == 2 * solved and "solving the layout copies again" in caplog.text

    with np.load(path) as f:  # what an older solver might have stored
        arrays = dict(f)
    arrays["action"][0] += 0.01
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    caplog.clear()
    assert_same(first, with_copies(root))
    assert "solves differently" in caplog.text
    caplog.clear()
    assert_same(first, with_copies(root))  # replaced: read back, no warning
    assert "solving" not in caplog.text


def test_copies_that_do_not_fit_their_demonstrations_are_solved_again(root, caplog):
    first = with_copies(root)
    (path,) = (root / ".cache").glob("layout-shift-*.npz")
    with np.load(path) as f:
        arrays = dict(f)
    arrays["state"] = arrays["state"][:-1]  # one row short of its lengths
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    assert_same(first, with_copies(root))
    assert "lengths" in caplog.text


def test_a_dataset_folder_the_cache_cannot_be_written_to_still_trains(root, caplog):
    (root / ".cache").write_text("")  # a file where the cache folder would go
    assert len(with_copies(root)) > 0
    assert "not cached" in caplog.text
