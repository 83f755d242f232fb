"""Atomic files: leftovers of killed writers, and JSON read back with a one-line error."""

import os

import pytest

from rmbench.files import FileFormatError, read_json_object, remove_leftovers, write_atomic


def test_only_dead_writers_leftovers_are_removed(tmp_path):
    (tmp_path / "sub").mkdir()
    dead = [tmp_path / ".state.pt.999999999.tmp", tmp_path / "sub" / ".f.npy.999999998.tmp.npy"]
    live = tmp_path / f".config.json.{os.getpid()}.tmp"  # a writer still at work
    kept = [tmp_path / "state.pt", tmp_path / ".hidden", live]
    for path in dead + kept:
        path.write_bytes(b"x")
    assert remove_leftovers(tmp_path) == 1 and not dead[0].exists() and dead[1].exists()
    assert remove_leftovers(tmp_path, recursive=True) == 1 and not dead[1].exists()
    assert all(path.exists() for path in kept)
    assert remove_leftovers(tmp_path / "missing") == 0


@pytest.mark.parametrize("text, message", [
    ("{bad", "not readable JSON"), ("[1]", "holds a JSON list, not an object"),
    ('{"a": 1}', "no 'b' field")])
def test_a_json_object_read_back_names_its_file(tmp_path, text, message):
    path = tmp_path / "x.json"
    path.write_text(text)
    with pytest.raises(FileFormatError, match=f"x.json: {message}"):
        read_json_object(path, ("a", "b"))
    path.write_text('{"a": 1, "b": 2}')
    assert read_json_object(path, ("a", "b")) == {"a": 1, "b": 2}


def test_a_lock_refuses_a_second_holder_or_waits_for_it(tmp_path):
    import threading

    from rmbench.files import Locked, lock

    path = tmp_path / "x.lock"
    first = lock(path)
    with pytest.raises(Locked, match=rf"locked by process {os.getpid()}"):
        lock(path)
    got = []
    waiter = threading.Thread(target=lambda: got.append(lock(path, wait=True)))
    waiter.start()
    waiter.join(0.3)
    assert waiter.is_alive() and not got  # still waiting while the first holds it
    first.close()
    waiter.join(5)
    assert got and not waiter.is_alive()
    got[0].close()


def test_a_lock_whose_holder_removed_its_file_is_taken_on_the_new_file(tmp_path, monkeypatch):
    import fcntl

    from rmbench import files

    path = tmp_path / "x.lock"
    real, calls = fcntl.flock, []

    def holder_removes_it_first(f, op):
        # the holder removes the file and lets it go between this process's open and its lock
        # (a finished evaluation does): the lock then falls on a file no one else can open
        calls.append(op)
        if len(calls) == 1:
            path.unlink()
        return real(f, op)

    monkeypatch.setattr(files.fcntl, "flock", holder_removes_it_first)
    held = files.lock(path)
    assert len(calls) == 2  # the removed file let go, the one now at the path locked
    assert os.fstat(held.fileno()).st_ino == os.stat(path).st_ino
    monkeypatch.setattr(files.fcntl, "flock", real)
    with pytest.raises(files.Locked):
        files.lock(path)  # a newcomer finds it held
    held.close()
    # a file replaced under every try is not waited on for ever
    monkeypatch.setattr(files.fcntl, "flock", lambda f, op: (path.unlink(), real(f, op)))
    with pytest.raises(files.Locked):
        files.lock(path)


def test_a_stage_record_that_is_not_an_object_reads_as_absent(tmp_path):
    from rmbench.files import read_json_or

    path = tmp_path / "timing.json"
    assert read_json_or(path, {}) == {}  # missing
    for text in ("null", "[1, 2]", "{bad", "\xff"):
        path.write_text(text, encoding="latin-1")
        assert read_json_or(path, {}) == {} and read_json_or(path, None) is None
    path.write_text('{"step": 3}')
    assert read_json_or(path, {}) == {"step": 3}


def test_write_atomic_syncs_the_data_then_the_folder_entry(tmp_path, monkeypatch):
    synced = []
    real = os.fsync
    monkeypatch.setattr(os, "fsync", lambda fd: synced.append(os.path.isdir(f"/proc/self/fd/{fd}"))
                        or real(fd))
    write_atomic(tmp_path / "a.json", b"{}\n")
    assert synced == [False, True]  # the file's bytes before the rename, the folder after it
    assert (tmp_path / "a.json").read_bytes() == b"{}\n"
    assert [p.name for p in tmp_path.iterdir()] == ["a.json"]
