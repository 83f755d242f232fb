"""Atomic files: a reader sees the old file or the whole new one, never a half-written one.

Every file rmbench writes that another process may read, or that a killed run leaves behind
(datasets, checkpoints, records, reports, results), is written under a temporary name in
its own folder and renamed into place (``os.replace`` is atomic within a filesystem). A JSON
file read back that is not what was written (edited by hand, damaged) is a one-line error
naming it (``read_json_object``).
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any


class Locked(RuntimeError):
    """A lock another process holds; ``holder`` its pid as it wrote it ("" if unknown)."""

    def __init__(self, path: Path, holder: str):
        super().__init__(f"{path} is locked by process {holder or '?'}")
        self.path, self.holder = path, holder


_LOCK_TRIES = 8  # files locked in turn that their holders had already removed


def lock(path: str | Path, wait: bool = False) -> IO[str]:
    """An exclusive lock on ``path`` (created, with this process's pid in it): the open file,
    whose closing releases it, as does the process's end however it ends; ``Locked`` if
    another process holds it, or with ``wait`` once that process lets it go."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(_LOCK_TRIES):
        f: IO[str] = open(path, "a+")
        try:
            fcntl.flock(f, fcntl.LOCK_EX if wait else fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip()
            f.close()
            raise Locked(path, holder) from None
        except OSError as err:  # a file system without locks (some network mounts): unlocked
            logging.getLogger(__name__).warning("%s: not locked, the file system takes no "
                                                "locks (%s)", path, err.strerror or err)
            break
        if _same_file(f, path):
            break
        # its holder removed the file before letting it go (a finished evaluation does): the
        # lock is on a file no other process can open, so take the one now at the path
        f.close()
    else:
        raise Locked(path, "") from None  # (replaced under every try: held by no one for long)
    f.seek(0)
    f.truncate()
    f.write(f"{os.getpid()}\n")
    f.flush()
    return f


def _same_file(f: IO[str], path: Path) -> bool:
    """Is the open file ``f`` still the one at ``path``?"""
    try:
        here = os.stat(path)
    except FileNotFoundError:
        return False
    mine = os.fstat(f.fileno())
    return (mine.st_dev, mine.st_ino) == (here.st_dev, here.st_ino)


@contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """A temporary path beside ``path`` for a writer that wants a file name (parquet, np.save):
    renamed onto ``path`` when the block ends without an error, removed otherwise; its bytes
    reach the disk before the rename and the folder's entry after it (as ``write_atomic``'s:
    a dataset's episode row commits its episode, and must never outlive a power loss that its
    data do not). ``suffix`` keeps an extension a writer insists on (np.save appends ``.npy``)."""
    path = Path(path)
    if path.is_dir():  # (the rename would fail after the work, naming the temporary file)
        raise IsADirectoryError(f"{path} is a folder, not a file to write")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp{suffix}")
    try:
        yield tmp
        _sync_file(tmp)
        os.replace(tmp, path)
        _sync_folder(path.parent)
    finally:
        tmp.unlink(missing_ok=True)


def _sync_file(path: Path) -> None:
    """Flush a file another writer closed to the disk."""
    with open(path, "rb") as f:
        os.fsync(f.fileno())


_LEFTOVER = re.compile(r"^\..+\.(\d+)\.tmp(\.\w+)?$")  # atomic_path's temporary names


def remove_leftovers(folder: str | Path, recursive: bool = False) -> int:
    """Delete the temporary files that writers killed before their rename left in ``folder``
    (``atomic_path``'s names, of processes no longer running: a live writer's are its own);
    how many."""
    folder = Path(folder)
    if not folder.is_dir():
        return 0
    removed = 0
    for path in (folder.rglob(".*.tmp*") if recursive else folder.glob(".*.tmp*")):
        m = _LEFTOVER.match(path.name)
        if m and path.is_file() and not _running(int(m.group(1))):
            path.unlink(missing_ok=True)
            removed += 1
    return removed


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def write_atomic(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically: against a kill the rename suffices; the data
    reach the disk before it, so that a power loss cannot leave a renamed empty file, and the
    folder's entry after it, so that a power loss cannot bring back the file it replaced."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def _sync_folder(folder: Path) -> None:
    """Flush ``folder``'s entries (a rename into it) to the disk, where the system allows it."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # (a system that cannot open a folder so: the rename stands unsynced)
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_json(path: str | Path, obj: Any, indent: int | None = 1) -> None:
    """``obj`` as JSON (indented, or on one line with ``indent=None``) with a final newline,
    written atomically."""
    write_atomic(path, (json.dumps(obj, indent=indent) + "\n").encode())


class FileFormatError(ValueError):
    """A file this rmbench wrote reads back as something else (hand-edited, damaged)."""


def read_json_or(path: str | Path, default: Any) -> Any:
    """The JSON object in ``path``, or ``default`` where it is missing, unreadable or not an
    object (a record a stage writes last, read to ask whether the stage is done)."""
    try:
        value = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return default
    return value if isinstance(value, dict) else default


def read_json_object(path: str | Path, keys: tuple[str, ...] = ()) -> dict[str, Any]:
    """The JSON object in ``path``, which must hold ``keys``; a FileFormatError naming the file
    for one that is unreadable, not an object, or lacks one of them."""
    try:
        obj = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise FileFormatError(f"{path}: not readable JSON ({err})") from None
    if not isinstance(obj, dict):
        raise FileFormatError(f"{path}: holds a JSON {type(obj).__name__}, not an object")
    missing = [k for k in keys if k not in obj]
    if missing:
        raise FileFormatError(f"{path}: no {', '.join(map(repr, missing))} field")
    return obj
