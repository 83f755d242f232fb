"""rmbench.eval.rows and the probes that keep their rows with it: a row given again replaces its
own, the others stay, and a file that is not a results file is refused before anything is
written."""

import importlib.util
import json
from pathlib import Path

import pytest

from rmbench.eval.rows import put_row

ROOT = Path(__file__).resolve().parents[1]


def test_a_row_replaces_the_row_of_its_key_and_keeps_the_others(tmp_path):
    out = tmp_path / "r.json"
    put_row(out, {"label": "a", "n": 1}, key=("label",))
    put_row(out, {"label": "b", "n": 2}, key=("label",))
    rows = put_row(out, {"label": "a", "n": 3}, key=("label",))
    assert rows == [{"label": "b", "n": 2}, {"label": "a", "n": 3}]
    assert json.loads(out.read_text()) == {"rows": rows}


def test_a_file_that_is_not_a_results_file_is_refused_and_kept(tmp_path):
    out = tmp_path / "r.json"
    for text in ('{"rows": [', '{"other": []}', '{"rows": 3}'):
        out.write_text(text)
        with pytest.raises(ValueError, match="not a results file of 'rows' rows"):
            put_row(out, {"label": "a"}, key=("label",))
        assert out.read_text() == text
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def _loops():
    spec = importlib.util.spec_from_file_location("loops", ROOT / "benchmarks" / "put_back_loops.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_put_backs_read_the_places_the_task_declares(tmp_path):
    """A cube out of tray 1 and back in tray 1 is a put-back, out of 1 into 2 a move; a
    predicate the task does not declare as a place (the hidden empty tray) is never read."""
    loops = _loops()
    events = [[0, "task", "subtask", "pick"], [0, "task", "first_cube_tray", 1],
              [0, "task", "empty_tray", 2],
              [10, "task", "first_cube_tray", -1], [16, "task", "first_cube_tray", 1],
              [20, "task", "empty_tray", -1], [25, "task", "empty_tray", 2],
              [30, "task", "subtask", "place"],
              [40, "task", "first_cube_tray", -1], [130, "task", "first_cube_tray", 2]]
    places = ("first_cube_tray", "second_cube_tray")
    out, back, moved = loops.put_backs({"events": events}, places)
    assert (dict(out), back, moved) == ({"pick": 1}, [6], [90])
    folder = tmp_path / "ev"
    (folder / "put_back_block").mkdir(parents=True)
    (folder / "run.json").write_text(json.dumps({"policy": "expert", "seed": 0}))
    (folder / "put_back_block" / "episodes.jsonl").write_text(
        json.dumps({"success": True, "events": events, "reason": "success", "message": ""}) + "\n")
    with pytest.raises(SystemExit, match="put_back_block declares no place predicates"):
        loops.run_row("x", folder, loop=2)
