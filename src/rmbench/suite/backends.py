"""Where a table's jobs run: each a subprocess of this Python (``python -m
rmbench.suite.job``, its output in its own log), on a number of the table's slots of
``cores / jobs`` threads each, or each a Ray task with one CPU (``RAY_ADDRESS`` or a local
Ray instance; ``OUT`` then on a file system every node sees)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import TextIO

from rmbench.machine import THREAD_VARS
from rmbench.suite.job import run_job, source_digest
from rmbench.suite.plan import Plan
from rmbench.suite.schedule import Job


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
        env = {**os.environ, **{v: str(threads) for v in THREAD_VARS}}
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
                last = (str(err).strip().splitlines() or [""])[-1]  # (Ray's carry a traceback)
                done.append((job, f"{type(err).__name__}: {last}"))
        return done

    def stop(self) -> None:
        for ref in self.running.values():
            self.ray.cancel(ref, force=True)
        self.running.clear()
