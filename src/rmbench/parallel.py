"""Running independent episode jobs: in this process, in local worker processes, or on Ray.

Every executor hands back jobs with a blocking ``result()``. Callers submit a bounded window
of jobs and consume results in submission order, so what they write does not depend on the
number of workers or on the backend. Worker processes import rmbench themselves, so each job
carries its sender's source fingerprint and a worker that imported other source refuses it
(:mod:`rmbench.source`).
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

from rmbench import source
from rmbench.machine import THREAD_VARS, usable_cores

BACKENDS = ("local", "ray")


class _Deferred:
    """A job of the in-process executor: it runs when its result is asked for, in order."""

    def __init__(self, fn, args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)


class Inline:
    """One worker: jobs run in this process, one at a time."""

    window = 1

    def __init__(self, on_close: Callable[[], None] | None = None):
        self.on_close = on_close

    def submit(self, fn, *args) -> _Deferred:
        return _Deferred(fn, args)

    def shutdown(self) -> None:
        if self.on_close is not None:
            self.on_close()


def exit_with_parent(parent: int, poll_s: float = 2.0) -> None:
    """End this process when ``parent`` (the pid of the process that started it) dies: it is
    then re-parented. A parent killed by a signal runs no clean-up: without this its workers
    and jobs would go on with what they hold (a layout copy or a training for minutes) beside
    the run that resumes it, taking its cores. The parent names itself because a worker that
    read its parent's pid at start-up would take the re-parenting process for its parent if the
    parent died before then. Whatever they committed stays: every writer here writes atomically."""

    def watch():
        while os.getppid() == parent:
            time.sleep(poll_s)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _start_worker(parent: int, threads: int) -> None:
    """Worker start-up: the worker ends with its parent, and each of N workers gets cores/N
    threads for OpenMP/BLAS (torch reads this when a learned policy first imports it),
    instead of every worker taking all cores."""
    exit_with_parent(parent)
    for var in THREAD_VARS:
        os.environ.setdefault(var, str(threads))


def _run_checked(parent_source: dict[str, str], fn, *args):
    """A job in a worker process: ``fn(*args)``, if the worker runs its parent's source."""
    source.check_same_source(parent_source)
    return fn(*args)


class Pool:
    """Local worker processes. Spawned, not forked: a fork would share MuJoCo/GL state."""

    def __init__(self, workers: int):
        self.window = 2 * workers
        self.pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"),
                                        initializer=_start_worker,
                                        initargs=(os.getpid(), max(1, usable_cores() // workers)))

    def submit(self, fn, *args):
        return self.pool.submit(_run_checked, source.AT_IMPORT, fn, *args)

    def shutdown(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)


class _RayJob:
    def __init__(self, ray, ref):
        self.ray, self.ref = ray, ref

    def result(self):
        return self.ray.get(self.ref)


def check_backend(backend: str) -> None:
    """A ValueError for an unknown backend, a RuntimeError for Ray where it is not installed:
    said before a command writes anything."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "ray":
        try:
            import ray  # noqa: F401
        except ImportError as err:
            raise RuntimeError("--backend ray needs Ray: pip install 'rmbench[ray]'") from err


class Ray:
    """Jobs spread over a Ray cluster (``RAY_ADDRESS``) or a local Ray instance. Results travel
    back to the caller, so workers need no shared file system."""

    def __init__(self, workers: int):
        check_backend("ray")
        import ray

        self.ray = ray
        self.window = 2 * workers
        if not ray.is_initialized():
            ray.init(ignore_reinit_error=True, log_to_driver=False)
        self._remote = ray.remote(num_cpus=1)(_run_checked)

    def submit(self, fn, *args) -> _RayJob:
        return _RayJob(self.ray, self._remote.remote(source.AT_IMPORT, fn, *args))

    def shutdown(self) -> None:
        pass


def in_order(executor, calls: Iterable[tuple]) -> Iterator[tuple]:
    """Run ``calls`` (``(tag, fn, args)`` each, drawn lazily) on ``executor`` with at most its
    window in flight, and yield ``(tag, result)`` in the order they were given: what a caller
    writes then does not depend on the number of workers or on the backend."""
    pending: deque = deque()
    calls = iter(calls)
    while True:
        while len(pending) < executor.window and (call := next(calls, None)) is not None:
            tag, fn, args = call
            pending.append((tag, executor.submit(fn, *args)))
        if not pending:
            return
        tag, job = pending.popleft()
        yield tag, job.result()


def make_executor(workers: int, backend: str = "local", on_close: Callable[[], None] | None = None):
    check_backend(backend)
    if backend == "ray":
        return Ray(workers)
    return Inline(on_close) if workers == 1 else Pool(workers)
