"""Running a table: the jobs still missing, in dependency order (a task's collection before
its cells' training, Mem-0's training before a planner-only ablation's, a checkpoint before
its evaluations), ``jobs`` at a time on local worker
processes or on Ray, with a progress grid across the whole table.

Each job is a fresh process (``python -m rmbench.suite.job``) with ``cores / jobs`` torch
threads (a collect or evaluation job: as many worker processes) and its own log in
``OUT/logs``; on Ray each is a task with one CPU, and ``OUT`` must be a file system every
node sees (the stages read and write their folders there). Locally, slots no job can take
go to a collection or an evaluation (``GROWS``) as it starts, or to a running collection,
restarted with them (it resumes), which gives them back when jobs wait: a camera table's
last task would otherwise make its data, for hours, on one slot of two. A
job that fails is reported with its log and its dependants are skipped; the others go on.
Interrupted (Ctrl-C, SIGTERM, a closed terminal), the running jobs stop and what they saved
stays: a re-run of the same command plans only what is missing. One table at a time runs a task in an
``OUT`` (``OUT/<task>/.table.lock``): two would write one dataset or one training at once.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import IO, TextIO

from rmbench.machine import usable_cores
from rmbench.suite import clock, stages
from rmbench.suite.job import run_job, source_digest
from rmbench.suite.plan import Plan, executor_spec, trained_spec

BACKENDS = ("local", "ray")
PRIORITY = {"collect": 0, "eval": 1, "train": 2}  # within a task: unblock others, results early
# kinds whose results do not depend on their number of worker processes and that resume where
# they stopped: idle slots may be given to them (a training's float sums depend on its threads)
GROWS = ("collect", "eval")
# a collection's parts that commit as they go (an episode, a copied demonstration, a camera's
# features): a restart loses little of them (the state's layout-copy solve commits at its end)
RESUMABLE_PARTS = ("demos", "copies", "features")
LOCK = ".table.lock"
STOPS = (signal.SIGTERM, signal.SIGHUP)  # stop the table as Ctrl-C does


def start_order(needs: dict[Job, tuple[Job, ...]]) -> list[Job]:
    """The jobs in the order a free slot takes the first ready one: task by task in the
    table's order, and within a task collection, then evaluations, then trainings. A task's
    cells thus finish before the next task's data is made, while a slot no earlier task can
    use goes on with a later one (a camera table's data takes hours a task)."""
    tasks = list(dict.fromkeys(j.task for j in needs))
    return sorted(needs, key=lambda j: (tasks.index(j.task), PRIORITY[j.kind]))


@dataclass(frozen=True)
class Job:
    kind: str
    task: str
    spec: str = ""

    @property
    def name(self) -> str:
        return " ".join(x for x in (self.kind, self.task, self.spec) if x)

    @property
    def log_name(self) -> str:
        return self.name.replace(" ", "_").replace(":", "-").replace("+", "-") + ".log"


def plan_jobs(plan: Plan, out: Path) -> dict[Job, tuple[Job, ...]]:
    """Every job still to run, with the jobs it waits for, in table order."""
    needs: dict[Job, tuple[Job, ...]] = {}
    for task in dict.fromkeys(t for t, _ in plan.cells()):
        collect, fresh = Job("collect", task), None  # asked only where a cell trains
        for _, spec in (c for c in plan.cells() if c[0] == task):
            if stages.evaluated(plan, out, task, spec) is not None:
                continue
            if stages.trained(plan, out, task, spec):
                needs[Job("eval", task, spec)] = ()
                continue
            train = Job("train", task, trained_spec(spec))
            if fresh is None:
                fresh = not stages.collected(plan, out, task)
            if fresh:
                needs.setdefault(collect, ())
            first = (collect,) if fresh else ()
            source = executor_spec(train.spec)  # (no_key: Mem-0's executor first)
            if source is not None and not stages.trained(plan, out, task, source):
                needs.setdefault(Job("train", task, source), first)
                first = (*first, Job("train", task, source))
            needs.setdefault(train, first)
            needs[Job("eval", task, spec)] = (train,)
    return needs


# ------------------------------------------------------------------------------ backends
class LocalJobs:
    """Each job a subprocess of this Python, on ``slots`` of the table's slots of ``threads``
    cores each; ``stop`` terminates the running ones."""

    grows = True

    def __init__(self, threads: int):
        self.threads = threads
        self.running: dict[Job, tuple[subprocess.Popen, TextIO, int]] = {}
        self.slots: dict[Job, int] = {}

    def held(self) -> int:
        """The slots the running jobs hold."""
        return sum(self.slots[job] for job in self.running)

    def start(self, plan: Plan, out: Path, job: Job, log: Path, slots: int = 1) -> None:
        threads = self.threads * slots
        cmd = [sys.executable, "-m", "rmbench.suite.job", "--plan", json.dumps(plan.to_dict()),
               "--out", str(out), "--kind", job.kind, "--task", job.task, "--spec", job.spec,
               "--threads", str(threads), "--digest", source_digest(),
               "--parent", str(os.getpid())]
        env = {**os.environ, **{v: str(threads) for v in
                                ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")}}
        f = open(log, "a")  # (appended: a resumed job's log keeps its earlier runs)
        start = f.tell()  # where this run's lines begin
        self.running[job] = (subprocess.Popen(cmd, stdout=f, stderr=subprocess.STDOUT, env=env), f,
                             start)
        self.slots[job] = slots

    def restart(self, plan: Plan, out: Path, job: Job, slots: int, logs: Path) -> bool:
        """Stop ``job`` and start it again on ``slots`` slots: it resumes from what it saved,
        losing what its workers had in hand. False, and nothing done, if it has ended (the
        next ``finished`` reports it)."""
        proc, f, _ = self.running[job]
        if proc.poll() is not None:
            return False
        proc.terminate()
        proc.wait()
        f.close()
        del self.running[job]
        self.start(plan, out, job, logs / job.log_name, slots)
        return True

    def finished(self) -> list[tuple[Job, str | None]]:
        """Jobs that ended since the last call, each with None or its error in one line (the
        last line this run of the job wrote: its one-line error, or a traceback's last line)."""
        done = []
        for job, (proc, f, start) in list(self.running.items()):
            if proc.poll() is None:
                continue
            f.close()
            del self.running[job]
            if proc.returncode == 0:
                done.append((job, None))
                continue
            with open(f.name, "rb") as log:
                log.seek(start)
                lines = log.read().decode(errors="replace").strip().splitlines()
            done.append((job, f"exit {proc.returncode}: {lines[-1] if lines else 'no output'}"))
        return done

    def stop(self) -> None:
        for proc, f, _ in self.running.values():
            proc.terminate()
            proc.wait()
            f.close()
        self.running.clear()


class RayJobs:
    """Each job a Ray task with one CPU (``RAY_ADDRESS`` or a local Ray instance)."""

    grows = False  # (Ray places its tasks: one CPU each)

    def __init__(self):
        try:
            import ray
        except ImportError as err:
            raise RuntimeError("--backend ray needs Ray: pip install 'rmbench[ray]'") from err
        self.ray = ray
        if not ray.is_initialized():
            ray.init(ignore_reinit_error=True, log_to_driver=False)
        self.remote = ray.remote(num_cpus=1, max_retries=0)(run_job)
        self.running: dict[Job, object] = {}

    def held(self) -> int:
        return len(self.running)

    def start(self, plan: Plan, out: Path, job: Job, log: Path, slots: int = 1) -> None:
        # resolved: a worker on another node starts in another directory
        self.running[job] = self.remote.remote(plan.to_dict(), str(out.resolve()), job.kind, job.task,
                                               job.spec, 1, source_digest(), str(log.resolve()))

    def finished(self) -> list[tuple[Job, str | None]]:
        if not self.running:
            return []
        refs = list(self.running.values())
        ready, _ = self.ray.wait(refs, num_returns=len(refs), timeout=0)
        done = []
        for job, ref in list(self.running.items()):
            if ref not in ready:
                continue
            del self.running[job]
            try:
                self.ray.get(ref)
                done.append((job, None))
            except Exception as err:  # a task's error, re-raised by Ray: reported, not fatal
                done.append((job, f"{type(err).__name__}: {str(err).splitlines()[-1]}"))
        return done

    def stop(self) -> None:
        for ref in self.running.values():
            self.ray.cancel(ref, force=True)
        self.running.clear()


# ------------------------------------------------------------------------------- display
def column(spec: str) -> str:
    """A spec's short column name: Mem-0, DP, ACT, or Mem-0's ablation (and @seed)."""
    base, at, seed = spec.partition("@")
    name = {"mem0": "Mem-0", "dp": "DP", "act": "ACT"}.get(base, base.removeprefix("mem0:"))
    return name + at + seed


class Progress:
    """The table as a grid of cell states (waiting, collecting, training n%, evaluating n%,
    the success rate, failed) and a line per running job with the time it has left at its
    pace so far, redrawn in place on a terminal; otherwise (a log file) printed at each job's
    start and end, and between them when it changed, at most every ``every_s`` seconds, so
    that an hour-long training shows its progress in the log without a line per poll."""

    def __init__(self, plan: Plan, out: Path, stream: TextIO | None = None,
                 every_s: float = 300.0, pace_after_s: float = 60.0):
        self.plan, self.out = plan, out
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.every_s, self.pace_after_s = every_s, pace_after_s
        self.start = self.printed = time.monotonic()
        self.last = ""  # the last grid shown, without its clock
        self.paces: dict[Job, tuple[str, float, float]] = {}  # (part, time, fraction) first seen

    def job_progress(self, job: Job) -> tuple[str, float]:
        """A running job's part under way (a collection's: demos, copies or features) and how
        far it has come (0-1)."""
        if job.kind == "collect":
            return stages.data_progress(self.plan, self.out, job.task)
        return job.kind, stages.fraction(self.plan, self.out, job.kind, job.task, job.spec)

    def left_s(self, job: Job, part: str, done: float) -> float | None:
        """Seconds ``job`` has left of ``part`` at its pace since this display first saw it
        there (or since ``forget``); None until it has run ``pace_after_s`` and moved."""
        now = time.monotonic()
        seen = self.paces.get(job)
        if seen is None or seen[0] != part or done < seen[2]:
            self.paces[job] = (part, now, done)
            return None
        _, t0, f0 = seen
        if now - t0 < self.pace_after_s or done <= f0:
            return None
        return (now - t0) / (done - f0) * (1 - done)

    def forget(self, job: Job) -> None:
        """``job``'s pace starts again (it was restarted on more cores)."""
        self.paces.pop(job, None)

    def cell(self, task: str, spec: str, running: set[Job], failed: dict[Job, str]) -> str:
        row = stages.evaluated(self.plan, self.out, task, spec)
        if row is not None:
            return f"{100 * row['success_rate']:.0f}%"
        ev, tr = Job("eval", task, spec), Job("train", task, trained_spec(spec))
        if ev in failed or tr in failed or Job("collect", task) in failed:
            return "failed"
        for job in (ev, tr, Job("collect", task)):
            if job in running:
                part, done = self.job_progress(job)
                return f"{part} {done:.0%}"
        return "."

    def running_lines(self, running: set[Job]) -> list[str]:
        """A line per running job: its part, how far, and the time left at its pace."""
        for job in set(self.paces) - running:
            del self.paces[job]
        lines = []
        for job in sorted(running, key=lambda j: j.name):
            part, done = self.job_progress(job)
            left = self.left_s(job, part, done)
            lines.append(f"  {job.name}: {part} {done:.0%}" + (
                "" if left is None else
                f", about {int(left) // 3600}:{int(left) // 60 % 60:02d} left at its pace"))
        return lines

    def _with_clock(self, grid: str) -> str:
        """``grid`` with the time since the table started at the end of its first line."""
        elapsed = int(time.monotonic() - self.start)
        head, _, rest = grid.partition("\n")
        return (f"{head}, {elapsed // 3600}:{elapsed // 60 % 60:02d}:{elapsed % 60:02d}\n"
                f"{rest}")

    def render(self, running: set[Job], failed: dict[Job, str]) -> str:
        """The grid, without the clock."""
        cells = self.plan.cells()
        specs = list(self.plan.policies)
        grid = {(t, s): self.cell(t, s, running, failed) for t, s in cells}
        finished = sum(v.endswith("%") and " " not in v for v in grid.values())
        head = (f"rmbench table ({self.plan.obs}): {finished}/{len(cells)} cells evaluated, "
                f"{len(running)} running, {len(failed)} failed")
        width = {s: max(len(column(s)), 12) for s in specs}  # ("features 52%")
        lines = [head, f"{'task':<19}" + " ".join(f"{column(s):>{width[s]}}" for s in specs)]
        for task in dict.fromkeys(t for t, _ in cells):
            lines.append(f"{task:<19}" + " ".join(f"{grid.get((task, s), ''):>{width[s]}}"
                                                  for s in specs))
        return "\n".join(lines + self.running_lines(running))

    def show(self, running: set[Job], failed: dict[Job, str], event: str = "") -> None:
        grid = self.render(running, failed)
        text, now = self._with_clock(grid), time.monotonic()
        if self.tty:  # redrawn each poll: the clock moves
            self.stream.write("\x1b[H\x1b[2J" + text + "\n")
        elif event or (grid != self.last and now - self.printed >= self.every_s):
            # a log: the clock alone changing is not news
            self.stream.write(f"{event}\n{text}\n" if event else f"{text}\n")
            self.printed = now
        self.stream.flush()
        self.last = grid


# ------------------------------------------------------------------------------ the loop
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
        for old, new in stages.retire_other_versions(plan, out, task):
            progress.show(set(), {}, f"{old} was made on another version of {task}: "
                                     f"moved to {new.name}")
    stages.check_data(plan, out)
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
                                  lambda j: stages.data_progress(plan, out, j.task)[0])
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


def shares(ready: list[Job], free: int, grows: bool) -> list[tuple[Job, int]]:
    """The ``ready`` jobs that start on the ``free`` slots, each with its slots: one each, and
    the first of them whose kind is in ``GROWS`` the rest."""
    started = [[job, 1] for job in ready[:max(0, free)]]
    wide = next((s for s in started if s[0].kind in GROWS), None) if grows else None
    if wide is not None:
        wide[1] += free - len(started)
    return [(job, slots) for job, slots in started]


def resize(pool, jobs: int, waiting: list[Job], part) -> tuple[Job, int] | None:
    """A running collection to restart on other slots, with how many, or None: on the idle
    slots when no job is ready to take them (``waiting``: the ready ones not started), the
    one on the fewest; on fewer, giving one back per waiting job, when jobs wait and one
    holds several. Only a collection in a part that commits as it goes (``part(job)`` one of
    ``RESUMABLE_PARTS``) moves: an evaluation commits chunks of seeds, and a restart would
    lose the one in hand."""
    if not pool.grows:
        return None
    movable = [j for j in pool.running if j.kind == "collect" and part(j) in RESUMABLE_PARTS]
    free = jobs - pool.held()
    if not waiting and free > 0 and movable:
        job = min(movable, key=lambda j: pool.slots[j])
        return job, pool.slots[job] + free
    wide = [j for j in movable if pool.slots[j] > 1]
    if waiting and wide:
        job = max(wide, key=lambda j: pool.slots[j])
        return job, max(1, pool.slots[job] - len(waiting))
    return None


@contextlib.contextmanager
def _holding(path: Path):
    """An exclusive lock on ``path`` (released when the process ends, however it ends), or a
    one-line error naming the process that holds it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    f: IO[str] = open(path, "a+")
    try:
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            pid = f.read().strip()
            raise RuntimeError(f"{path.parent} is in use by another rmbench table"
                               f"{f' (process {pid})' if pid else ''}: wait for it to end, "
                               f"or use another --out") from None
        f.seek(0)
        f.truncate()
        f.write(f"{os.getpid()}\n")
        f.flush()
        yield
    finally:
        f.close()


def _interrupt(signum, frame):
    raise KeyboardInterrupt
