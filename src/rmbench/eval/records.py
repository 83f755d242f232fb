"""An evaluation's episode records (``<task>/episodes.jsonl``, one JSON object a line, appended
as episodes end) read back, and a task's result summed from them."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

from rmbench.eval.episode import ENDINGS
from rmbench.eval.intervals import ci95
from rmbench.tasks import get_task

log = logging.getLogger(__name__)


class EvalError(ValueError):
    """An evaluation that cannot go on as asked (a damaged record, a folder of another
    evaluation or task version): said in one line, nothing in the folder changed."""


# what every episode record holds (eval/episode.py), and what summaries and reports read
RECORD_KEYS = ("seed", "success", "reason", "progress")


def read_records(path: Path, repair: bool = False) -> list[dict]:
    """The episode records of a JSONL file. Its last line may be torn (a writer killed
    mid-line leaves no newline after it): that line is left out, and with ``repair`` (the
    evaluation about to append) cut off the file. Any other line that is not a record is an
    EvalError naming the file and line, and the file is left as it is: a damaged middle is
    never cut away with the complete records after it. A seed is one episode: where a file
    holds it twice (two runs appending before evaluations took a lock), its first record is
    the one read, by every reader alike."""
    if not path.exists():
        return []
    data = path.read_bytes()
    records, good, seen = [], 0, set()
    lines = data.splitlines(keepends=True)
    for n, line in enumerate(lines, 1):
        if not line.endswith(b"\n") and n == len(lines):
            break  # torn
        try:
            record = json.loads(line)
        except (json.JSONDecodeError, UnicodeDecodeError):
            record = None
        if not (isinstance(record, dict) and all(k in record for k in RECORD_KEYS)):
            raise EvalError(f"{path}: line {n} is not an episode record (a record is one JSON "
                            f"object a line with {', '.join(RECORD_KEYS)}); mend or move the "
                            f"file") from None
        wrong = _wrong_types(record)
        if wrong:
            raise EvalError(f"{path}: line {n}: {wrong}; mend or move the file")
        if record["seed"] not in seen:
            seen.add(record["seed"])
            records.append(record)
        good += len(line)
    if good < len(data) and repair:
        log.warning("%s: dropping a torn last record (its writer was stopped)", path)
        with open(path, "r+b") as f:
            f.truncate(good)
    return records


def _wrong_types(record: dict) -> str:
    """What in a record's ``RECORD_KEYS`` has a type no episode writes ('' if nothing): a seed
    given as text would be played again and recorded twice, a success of null summed as 0."""
    number = (int, float)
    checks = (("seed", int, "an integer"), ("success", bool, "true or false"),
              ("reason", str, "a text"), ("progress", number, "a number"))
    for key, kind, what in checks:
        value = record[key]
        if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
            return f"its {key} is {json.dumps(value)[:40]}, not {what}"
    return ""


@dataclass
class TaskResult:
    task: str
    tmc: str
    episodes: int
    successes: int
    success_rate: float
    mean_progress: float
    endings: dict[str, int] = field(default_factory=dict)
    success_ci95: list[float] | None = None  # Wilson 95% interval of success_rate
    memory_reset: dict[str, dict] = field(default_factory=dict)  # probe name -> eval.probe.compare
    gym_id: str = ""  # the task version the episodes ran on


def summarize(task: str, records: list[dict]) -> TaskResult:
    n = len(records)
    ok = sum(r["success"] for r in records)
    endings = {e: sum(r["reason"] == e for r in records) for e in ENDINGS}
    return TaskResult(task, get_task(task).tmc, n, ok, round(ok / n, 4) if n else 0.0,
                      round(sum(r["progress"] for r in records) / n, 4) if n else 0.0, endings,
                      ci95(ok, n),
                      gym_id=get_task(task).gym_id)
