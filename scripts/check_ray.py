"""The Ray backends against the local ones, where Ray is installed (the rmbench[ray] extra):
a collection spread over Ray workers gives the dataset a local collection gives, and a toy
table runs its jobs on Ray. Exits 1 naming what differs.

    .venv/bin/pip install -e ".[ray]"
    .venv/bin/python scripts/check_ray.py [--out DIR]

Not part of the test suite, which runs without Ray: Ray's start-up alone takes minutes on two
cores, and its install is the size of the rest together.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import pyarrow.parquet as pq

from rmbench.data import CollectConfig, collect
from rmbench.data import layout as L
from rmbench.data.check import check_dataset
from rmbench.data.reader import Dataset

TASK = "observe_and_pickup"  # the shortest episodes


def contents(root: Path) -> tuple[list, list]:
    """Everything that defines the episodes: frame tables and meta rows."""
    ds = Dataset(root)
    return [pq.read_table(root / L.data_file(e)).to_pydict() for e in range(ds.num_episodes)], \
        ds.episodes


def collection(out: Path, **kw) -> CollectConfig:
    return CollectConfig(TASK, out, episodes=3, seed=0, cameras=("head", "left_wrist"), width=64,
                         height=48, progress=False, **kw)


def check_collection(out: Path) -> list[str]:
    collect(collection(out / "local"))
    collect(collection(out / "ray", workers=2, backend="ray"))
    check_dataset(out / "ray")
    same = contents(out / "ray") == contents(out / "local")
    return [] if same else ["a collection on Ray differs from the local one"]


def check_table(out: Path) -> list[str]:
    from rmbench.cli.main import main

    table = out / "table"
    code = main(["table", "--obs", "state", "--tasks", TASK, "--policies", "dp", "--demos", "2",
                 "--steps", "6", "--batch", "4", "--episodes", "1", "--out", str(table),
                 "--jobs", "2", "--backend", "ray", "--no-recipe"])
    if code != 0:
        return [f"the toy table on Ray exited {code} (logs in {table / 'logs'})"]
    row = json.loads((table / "table.json").read_text())["cells"][TASK]["dp"]
    problems = [] if row["episodes"] == 1 else [f"the toy table's dp cell ran {row['episodes']} "
                                                f"episodes, not 1"]
    if not (table / "logs" / f"train_{TASK}_dp.log").exists():
        problems.append("the toy table on Ray left no training log")
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="work folder (default: a temporary one)")
    args = parser.parse_args()
    try:
        import ray  # noqa: F401
    except ImportError:
        print("check_ray: Ray is not installed (pip install -e '.[ray]')", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        problems = check_collection(out) + check_table(out)
    for problem in problems:
        print(f"check_ray: {problem}", file=sys.stderr)
    if not problems:
        print("check_ray: the Ray backends give what the local ones give")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
