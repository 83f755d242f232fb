"""Running a table: the jobs still missing (``schedule``), ``jobs`` at a time on local worker
processes or on Ray (``backends``), with a progress grid across the whole table
(``progress``).

Each job is a fresh process (``python -m rmbench.suite.job``) with ``cores / jobs`` torch
threads (a collect or evaluation job: as many worker processes) and its own log in
``OUT/logs``; on Ray each is a task with one CPU. A job that fails is reported with its log
and its dependants are skipped; the others go on. Interrupted (Ctrl-C, SIGTERM, a closed
terminal), the running jobs stop and what they saved stays: a re-run of the same command
plans only what is missing. One table at a time runs a task in an ``OUT``
(``OUT/<task>/.table.lock``): two would write one dataset or one training at once.
"""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from pathlib import Path

from rmbench.files import Locked, lock
from rmbench.machine import usable_cores
from rmbench.suite import clock, data_stage, versions
from rmbench.suite.backends import LocalJobs, RayJobs
from rmbench.suite.plan import Plan
from rmbench.suite.progress import Progress
from rmbench.suite.schedule import Job, plan_jobs, resize, shares, start_order

BACKENDS = ("local", "ray")
LOCK = ".table.lock"
STOPS = (signal.SIGTERM, signal.SIGHUP)  # stop the table as Ctrl-C does


def run(plan: Plan, out: Path, jobs: int = 1, backend: str = "local",
        progress: Progress | None = None, poll_s: float = 2.0) -> dict[Job, str]:
    """Run every missing job of ``plan`` into ``out``; the failed ones, with their errors."""
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if jobs < 1:
        raise ValueError("jobs must be >= 1")
    out = Path(out)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    with contextlib.ExitStack() as held:
        for task in sorted(plan.tasks):
            held.enter_context(_holding(out / task / LOCK))
        return _run(plan, out, jobs, backend, progress or Progress(plan, out), poll_s)


def _run(plan: Plan, out: Path, jobs: int, backend: str, progress: Progress,
         poll_s: float) -> dict[Job, str]:
    logs = out / "logs"
    for task in dict.fromkeys(t for t, _ in plan.cells()):
        for old, new in versions.retire_other_versions(plan, out, task):
            progress.show(set(), {}, f"{old} was made on another version of {task}: "
                                     f"moved to {new.name}")
    data_stage.check_data(plan, out)
    needs = plan_jobs(plan, out)
    pool = (LocalJobs(max(1, usable_cores() // jobs)) if backend == "local"
            else RayJobs())
    pending = start_order(needs)
    done: set[Job] = set()
    failed: dict[Job, str] = {}
    main = threading.current_thread() is threading.main_thread()
    # terminated or hung up: stop the jobs as Ctrl-C does (handlers belong to the main thread);
    # a signal ignored already stays ignored (nohup's SIGHUP)
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, *STOPS)} if main else {}
    for sig in STOPS:
        if sig in handlers and handlers[sig] is not signal.SIG_IGN:
            signal.signal(sig, _interrupt)
    try:
        # counted every minute as it runs: a table killed outright keeps its time but a minute
        with clock.timed(out, "table_wall_s"):
            try:
                progress.show(set(pool.running), failed, f"{len(needs)} jobs to run")
                while pending or pool.running:
                    for job, error in pool.finished():
                        if error is None:
                            done.add(job)
                        else:
                            failed[job] = f"{error} (log {logs / job.log_name})"
                        progress.show(set(pool.running), failed,
                                      f"{'done' if error is None else 'FAILED'} {job.name}")
                    for job in list(pending):
                        if any(d in failed for d in needs[job]):  # its input failed: skipped
                            pending.remove(job)
                            failed[job] = ("skipped: " + " and ".join(
                                d.name for d in needs[job] if d in failed) + " failed")
                    ready = [j for j in pending if all(d in done for d in needs[j])]
                    for job, slots in shares(ready, jobs - pool.held(), pool.grows):
                        pending.remove(job)
                        pool.start(plan, out, job, logs / job.log_name, slots)
                        progress.show(set(pool.running), failed, f"started {job.name}"
                                      + (f" on {slots} slots" if slots > 1 else ""))
                    move = resize(pool, jobs, [j for j in ready if j in pending],
                                  lambda j: data_stage.data_progress(plan, out, j.task)[0])
                    if move is not None:
                        job, slots = move
                        why = ("no other job can start" if slots > pool.slots[job]
                               else "jobs wait for its slots")
                        if pool.restart(plan, out, job, slots, logs):
                            progress.forget(job)
                            progress.show(set(pool.running), failed,
                                          f"restarted {job.name} on {slots} slots: {why}")
                    if pending or pool.running:
                        time.sleep(poll_s)
                        progress.show(set(pool.running), failed)
            finally:
                # from here a second Ctrl-C or SIGTERM is ignored: it would leave jobs running
                # and the table's clock without its last minute
                for sig in handlers:
                    signal.signal(sig, signal.SIG_IGN)
                pool.stop()
    finally:
        for sig, handler in handlers.items():
            if handler is not None:  # (None: set outside Python, left as it is)
                signal.signal(sig, handler)
    return failed


@contextlib.contextmanager
def _holding(path: Path):
    """An exclusive lock on ``path`` (released when the process ends, however it ends), or a
    one-line error naming the process that holds it."""
    try:
        f = lock(path)
    except Locked as err:
        raise RuntimeError(f"{path.parent} is in use by another rmbench table"
                           f"{f' (process {err.holder})' if err.holder else ''}: wait for it "
                           f"to end, or use another --out") from None
    try:
        yield
    finally:
        f.close()


def _interrupt(signum, frame):
    raise KeyboardInterrupt
