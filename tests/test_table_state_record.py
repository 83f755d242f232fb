"""benchmarks/table_state.py: recording a table run's cells in the committed state table
replaces each cell and keeps every replaced measurement of other data under ``superseded``."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def table_state(monkeypatch):
    spec = importlib.util.spec_from_file_location("table_state", ROOT / "benchmarks" / "table_state.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    # the cells' records read evaluation folders; the rows here stand for them
    monkeypatch.setattr(module, "cell_record", lambda row, task: dict(row))
    return module


def _doc():
    return {"cells": {"press_button": {"mem0": {"successes": 2}, "dp": {"successes": 2}}},
            "chance": {"press_button": {"rate": 0.011}}, "superseded": []}


def _run(k=36):
    return {"command": "rmbench table ...", "chance": {"press_button": {"rate": 0.011}},
            "cells": {"press_button": {"mem0": {"successes": k}}}}


def test_a_cell_of_other_data_moves_to_superseded(table_state):
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    assert doc["cells"]["press_button"]["mem0"] == {"successes": 36, "dataset": "rmbench/2",
                                                     "command": "rmbench table ..."}
    assert doc["cells"]["press_button"]["dp"] == {"successes": 2}  # untouched
    assert doc["superseded"] == [{"why": "format 1", "cells": {"press_button": {"mem0": {"successes": 2}}}}]


def test_a_cell_of_the_same_data_is_replaced_without_a_copy(table_state):
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    doc = table_state.record(doc, _run(40), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    assert doc["cells"]["press_button"]["mem0"]["successes"] == 40
    assert doc["superseded"][0]["cells"]["press_button"]["mem0"] == {"successes": 2}
    assert len(doc["superseded"]) == 1


def test_a_cell_not_evaluated_is_a_one_line_error(table_state):
    with pytest.raises(SystemExit, match="press_button mem0:no_key is not evaluated yet"):
        table_state.record(_doc(), _run(), ["press_button"], ["mem0:no_key"], "rmbench/2", "x", "t")
