"""A table's clock: each stage's wall time, kept in its folder's ``timing.json`` with the
machines it ran on, counted as the stage runs so that a stage killed after hours keeps it."""

from __future__ import annotations

import threading
import time
from contextlib import contextmanager
from pathlib import Path

from rmbench.files import read_json_object, write_json
from rmbench.machine import describe

TIMING = "timing.json"
# a task's data stages, shared by its cells (the pixel track's rendered copies and cached
# features; the state track's solved layout copies)
DATA_WALLS = ("collect_wall_s", "copies_wall_s", "features_wall_s", "layout_copies_wall_s")


@contextmanager
def timed(folder: Path, key: str, every: float = 60.0):
    """Count the block's wall time into ``folder/timing.json``'s ``key`` (``add_time``) as it
    runs, every ``every`` seconds and at its end, so that a stage killed after hours (a
    session's end, Ctrl-C) keeps its time up to the last minute and its resumption adds on."""
    add_time(folder, key, 0.0)  # a damaged record is an error now, not after the stage's hours
    stop, lock = threading.Event(), threading.Lock()
    last = [time.perf_counter()]

    def book() -> None:
        with lock:
            now = time.perf_counter()
            add_time(folder, key, now - last[0])
            last[0] = now

    def beat() -> None:
        while not stop.wait(every):
            book()

    clock = threading.Thread(target=beat, daemon=True)
    clock.start()
    try:
        yield
    finally:
        stop.set()
        clock.join()
        book()


def add_time(folder: Path, key: str, seconds: float) -> None:
    """Accumulate a stage's wall time in ``folder/timing.json``, and the machine it ran on in
    ``machines`` (each machine that added time once)."""
    path = Path(folder) / TIMING
    # a damaged record is an error, not a fresh start: the times it held would be lost
    timing = read_json_object(path) if path.exists() else {}
    timing[key] = timing.get(key, 0.0) + seconds  # unrounded: short stages add up
    machines = timing.setdefault("machines", [])
    here = describe()
    if here not in machines:
        machines.append(here)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, timing)
