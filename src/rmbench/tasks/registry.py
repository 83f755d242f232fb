"""Task registry: a decorator fills it and refuses duplicates."""

from __future__ import annotations

from rmbench.tasks.base import Task

TASKS: dict[str, type[Task]] = {}


class UnknownTaskError(KeyError):
    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


def register(cls: type[Task]) -> type[Task]:
    for attr in ("name", "gym_id", "tmc", "step_limit", "subtasks", "instructions_seen",
                 "instructions_unseen", "aliasing_point", "aliasing_stage"):
        if not hasattr(cls, attr):
            raise TypeError(f"task {cls.__name__} does not declare {attr}")
    if cls.tmc not in ("M(1)", "M(n)"):
        raise ValueError(f"task {cls.name}: TMC label must be M(1) or M(n), got {cls.tmc}")
    for key in (cls.name, cls.gym_id):
        if key in TASKS or any(t.gym_id == key for t in TASKS.values()):
            raise ValueError(f"task {key!r} is already registered")
    TASKS[cls.name] = cls
    return cls


def ordered() -> list[type[Task]]:
    """Tasks in the benchmark's order: M(1) before M(n), then by name."""
    return sorted(TASKS.values(), key=lambda c: (c.tmc != "M(1)", c.name))


# Records made before datasets, checkpoints and evaluations kept their task's gym id: the
# version they were made on, where that is not the current one (CHANGELOG.md, 2026-11-28 and
# 2026-11-29).
UNRECORDED_VERSIONS = {"battery_try": "rmbench/BatteryTry-v1", "swap_blocks": "rmbench/SwapBlocks-v1",
                       "rearrange_blocks": "rmbench/RearrangeBlocks-v1",
                       "cover_blocks": "rmbench/CoverBlocks-v1"}


def recorded_gym_id(task: str, record: dict) -> str:
    """The task version a record (a dataset's metadata, a checkpoint's config, a cell) was made
    on: its ``gym_id``, or for one made before versions were kept, the version then."""
    cls = get_task(task)
    return record.get("gym_id") or UNRECORDED_VERSIONS.get(cls.name, cls.gym_id)


def on_current_version(task: str, record: dict) -> bool:
    """Whether a record was made on ``task``'s current version (``recorded_gym_id``)."""
    return recorded_gym_id(task, record) == get_task(task).gym_id


def get_task(name: str) -> type[Task]:
    """A task class by name (``put_back_block``) or gym id (``rmbench/PutBackBlock-v1``)."""
    if name in TASKS:
        return TASKS[name]
    for cls in TASKS.values():
        if cls.gym_id == name:
            return cls
    known = ", ".join(sorted(TASKS))
    raise UnknownTaskError(f"unknown task {name!r}; known tasks: {known}")
