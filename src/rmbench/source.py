"""The rmbench source a process runs, fingerprinted when the package is first imported.

Worker processes are spawned, so each imports rmbench from disk when it starts, which can be
minutes after its parent did. If the files changed in between (an edit, a pull, a checkout),
the workers run other code than the parent and a dataset or an evaluation silently mixes two
versions: a colour edit, say, keeps every state and changes the frames. Measured: a one-line
shelf colour edit landing between a parent's import and ``collect(workers=2)`` gave identical
frame tables and a different head video for every episode. The parent sends its fingerprint
with each job and a worker whose own differs refuses the job (:mod:`rmbench.parallel`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent


class SourceChangedError(RuntimeError):
    """A worker imported other rmbench source than the process that sent it a job."""


def fingerprint(root: Path = PACKAGE) -> dict[str, str]:
    """SHA-1 of every ``.py`` file under ``root``, keyed by its path relative to ``root``."""
    return {p.relative_to(root).as_posix(): hashlib.sha1(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*.py"))}


# Taken once, when ``import rmbench`` runs this module first (about 10 ms for 110 files).
AT_IMPORT: dict[str, str] = fingerprint()


def changed_files(theirs: dict[str, str], ours: dict[str, str]) -> list[str]:
    return sorted(k for k in theirs.keys() | ours.keys() if theirs.get(k) != ours.get(k))


def check_same_source(parent: dict[str, str]) -> None:
    """Raise :class:`SourceChangedError` unless this process imported the source ``parent``
    (the sending process's :data:`AT_IMPORT`) describes."""
    diff = changed_files(parent, AT_IMPORT)
    if diff:
        shown = ", ".join(diff[:5]) + (f" and {len(diff) - 5} more" if len(diff) > 5 else "")
        raise SourceChangedError(
            f"rmbench's source under {PACKAGE} changed after this run started ({shown}): a "
            "worker would run other code than its parent; restart the run")
