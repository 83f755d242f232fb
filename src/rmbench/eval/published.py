"""The paper's success rates (arXiv 2603.01229, 100 rollouts after 50 demonstrations per
task), as ``published.json`` keeps them: its main results table (DP, ACT, Pi0.5, X-VLA and
Mem-0 on the nine tasks) and its ablations table (Mem-0 and its variants, per task). Every
published number rmbench prints (``rmbench report --published``, ``rmbench table``'s
table.md, the docs' tables) comes from here.

An average the paper states is kept as stated (``averages``); any other is the mean of the
column's tasks (``average``).
"""

from __future__ import annotations

import json
from functools import cache
from importlib.resources import files
from typing import Any

GROUPS = ("M(1)", "M(n)")


@cache
def data() -> dict[str, Any]:
    """``published.json``: the paper, its protocol, the tasks' TMC groups and its tables."""
    return json.loads(files("rmbench.eval").joinpath("published.json").read_text())


def arxiv() -> str:
    return data()["paper"]["arxiv"]


def rollouts() -> int:
    """The rollouts behind each published rate."""
    return data()["protocol"]["rollouts"]


def columns(table: str) -> dict[str, dict[str, float]]:
    """A table's (``main``, ``ablations``) columns by the paper's names: task -> rate (%); a
    column lacks the tasks the paper gives no number for (``w/o Key`` on M(1) tasks)."""
    return data()["tables"][table]["columns"]


def table_name(table: str) -> str:
    """The paper's name for a table: 'main results', 'ablations'."""
    return data()["tables"][table]["table"]


def ablation_names() -> dict[str, str]:
    """rmbench's policy spec of each ablations column -> the paper's name for it
    (``mem0:no_anchor`` -> ``w/o Anchor``)."""
    return {spec: name for name, spec in data()["tables"]["ablations"]["specs"].items()}


def stated(table: str, column: str, group: str = "") -> float | None:
    """The average the paper states for a column over ``group``'s tasks (``M(1)``, ``M(n)``;
    "" for all nine); None where it states none."""
    return data()["tables"][table].get("averages", {}).get(column, {}).get(group or "all")


def average(table: str, column: str, group: str = "") -> float | None:
    """A column's average over ``group``'s tasks: the paper's where it states one, else the
    mean of its tasks; None where the column lacks one of them."""
    given = stated(table, column, group)
    return given if given is not None else mean(columns(table)[column], group)


def mean(rates: dict[str, float], group: str = "") -> float | None:
    """The mean of ``rates`` over ``group``'s tasks ("" for all nine); None where one is
    missing."""
    tasks = [t for t, g in data()["tasks"].items() if not group or g == group]
    if any(t not in rates for t in tasks):
        return None
    return sum(rates[t] for t in tasks) / len(tasks)
