"""A table's progress as a grid of cell states and a line per running job, on a terminal or
in a log."""

from __future__ import annotations

import sys
import time
from collections import deque
from pathlib import Path
from typing import TextIO

from rmbench.suite import data_stage, stages
from rmbench.suite.plan import Plan, trained_spec
from rmbench.suite.schedule import Job


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
                 every_s: float = 300.0, pace_after_s: float = 60.0,
                 pace_window_s: float = 1200.0):
        self.plan, self.out = plan, out
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.every_s, self.pace_after_s = every_s, pace_after_s
        self.pace_window_s = pace_window_s
        self.start = self.printed = time.monotonic()
        self.last = ""  # the last grid shown, without its clock
        # each running job's part and the (time, fraction) it was seen at as it moved
        self.paces: dict[Job, tuple[str, deque[tuple[float, float]]]] = {}
        self._drawing: dict[Job, tuple[str, float]] | None = None  # (while a grid is drawn)

    def job_progress(self, job: Job) -> tuple[str, float]:
        """A running job's part under way (a collection's: demos, copies or features) and how
        far it has come (0-1); read once per grid drawn (its cells and lines ask it again)."""
        if self._drawing is not None and job in self._drawing:
            return self._drawing[job]
        if job.kind == "collect":
            got = data_stage.data_progress(self.plan, self.out, job.task)
        else:
            got = job.kind, stages.fraction(self.plan, self.out, job.kind, job.task, job.spec)
        if self._drawing is not None:
            self._drawing[job] = got
        return got

    def left_s(self, job: Job, part: str, done: float) -> float | None:
        """Seconds ``job`` has left of ``part`` at its pace over the last ``pace_window_s``
        (a pause, or other work beside it, fades out of the estimate); None until this
        display has seen it there (since ``forget``) for ``pace_after_s`` and moving."""
        now = time.monotonic()
        seen = self.paces.get(job)
        if seen is None or seen[0] != part or done < seen[1][-1][1]:
            self.paces[job] = (part, deque([(now, done)]))
            return None
        samples = seen[1]
        if done > samples[-1][1]:
            samples.append((now, done))
        while len(samples) > 2 and now - samples[1][0] >= self.pace_window_s:
            samples.popleft()  # (the oldest kept is the last one older than the window)
        t0, f0 = samples[0]
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
        self._drawing = {}
        try:
            return self._render(running, failed)
        finally:
            self._drawing = None

    def _render(self, running: set[Job], failed: dict[Job, str]) -> str:
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
