"""A training's loss curve: ``OUT/training/loss.csv``, one row every ``log_every`` steps, and
its plot ``loss.png``, both derived from the saved steps and written atomically."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from rmbench.files import write_atomic

CURVE_CSV = Path("training") / "loss.csv"
CURVE_PNG = Path("training") / "loss.png"


def append_curve(out: Path, rows: list[dict], step: int) -> None:
    """Rows after ``step`` (logged by a run killed before it saved) are replaced."""
    path = out / CURVE_CSV
    old: list[dict] = []
    if path.exists():
        with open(path, newline="") as f:
            first = rows[0]["step"] if rows else step + 1
            old = [r for r in csv.DictReader(f) if int(r["step"]) < first]
    allrows = old + rows
    if not allrows:
        return
    fields = list(dict.fromkeys(k for r in allrows for k in r))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fields)
    writer.writeheader()
    writer.writerows(allrows)
    write_atomic(path, buf.getvalue().encode())


def stale(made: Path, source: Path) -> bool:
    """Whether ``made`` is missing or older than ``source`` (which exists)."""
    return source.exists() and (not made.exists()
                                or made.stat().st_mtime_ns < source.stat().st_mtime_ns)


def plot_curve(out: Path) -> None:
    path = out / CURVE_CSV
    if not path.exists():
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return
    keys = [k for k in rows[0] if k == "loss" or k.startswith("loss/")]
    fig, ax = plt.subplots(figsize=(7, 4))
    steps = [int(r["step"]) for r in rows]
    for k in keys:
        ax.plot(steps, [float(r[k]) for r in rows], label=k, lw=1)
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    write_atomic(out / CURVE_PNG, buf.getvalue())
