"""Every process of a run imports the same rmbench source: a test run's subprocesses import this
checkout, and a worker that imported other source than its parent refuses jobs."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

import rmbench
from rmbench import source
from rmbench.parallel import Pool
from rmbench.source import SourceChangedError

SRC = Path(__file__).resolve().parents[1] / "src"


def test_this_run_and_its_subprocesses_import_this_checkout():
    assert Path(rmbench.__file__).resolve().is_relative_to(SRC)
    found = subprocess.run(
        [sys.executable, "-c", "import importlib.util; print(importlib.util.find_spec('rmbench').origin)"],
        capture_output=True, text=True, check=True, timeout=60).stdout.strip()
    assert Path(found).resolve().is_relative_to(SRC)


def test_a_worker_refuses_jobs_once_the_source_changed_after_its_parent_imported_it(monkeypatch):
    pool = Pool(1)
    try:
        assert pool.submit(os.getpid).result() != os.getpid()  # same source: the job runs
        # As if tasks/observe_and_pickup.py had been edited on disk after this process imported
        # it: the worker's fingerprint (its files) no longer matches this process's.
        edited = {**source.AT_IMPORT, "tasks/observe_and_pickup.py": "0" * 40}
        monkeypatch.setattr(source, "AT_IMPORT", edited)
        with pytest.raises(SourceChangedError, match=r"\(tasks/observe_and_pickup\.py\).*restart"):
            pool.submit(os.getpid).result()
    finally:
        pool.shutdown()


def test_changed_files_names_edits_additions_and_removals():
    a = {"x.py": "1", "y.py": "2", "gone.py": "3"}
    b = {"x.py": "1", "y.py": "9", "new.py": "4"}
    assert source.changed_files(a, b) == ["gone.py", "new.py", "y.py"]
    assert source.changed_files(a, dict(a)) == []
