"""What a table runs and when: its jobs still missing with the jobs each waits for (a task's
collection before its cells' trainings, Mem-0's training before a planner-only ablation's, a
checkpoint before its evaluations), the order free slots take them in, and how many of the
table's slots (``--jobs``) each holds: slots no job can take go to a collection or an
evaluation (``GROWS``) as it starts, or to a running collection, restarted with them (it
resumes), which gives them back when jobs wait. A camera table's last task would otherwise
make its data, for hours, on one slot of two.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rmbench.suite import data_stage, stages
from rmbench.suite.plan import Plan, executor_spec, trained_spec

PRIORITY = {"collect": 0, "eval": 1, "train": 2}  # within a task: unblock others, results early
# kinds whose results do not depend on their number of worker processes and that resume where
# they stopped: idle slots may be given to them (a training's float sums depend on its threads)
GROWS = ("collect", "eval")
# a collection's parts that commit as they go (an episode, a copied demonstration, a camera's
# features): a restart loses little of them (the state's layout-copy solve commits at its end)
RESUMABLE_PARTS = ("demos", "copies", "features")


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
                fresh = not data_stage.collected(plan, out, task)
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


def start_order(needs: dict[Job, tuple[Job, ...]]) -> list[Job]:
    """The jobs in the order a free slot takes the first ready one: task by task in the
    table's order, and within a task collection, then evaluations, then trainings. A task's
    cells thus finish before the next task's data is made, while a slot no earlier task can
    use goes on with a later one (a camera table's data takes hours a task)."""
    tasks = list(dict.fromkeys(j.task for j in needs))
    return sorted(needs, key=lambda j: (tasks.index(j.task), PRIORITY[j.kind]))


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
