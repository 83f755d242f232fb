"""benchmarks/put_back_loops.py: put-backs and moves read from the place predicates a task
declares, and a task that declares none refused in one line."""

import json

import pytest

from tests.conftest import load_script


def _loops():
    return load_script("benchmarks/put_back_loops.py")


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
        json.dumps({"seed": 1, "success": True, "events": events, "reason": "success",
                    "message": "", "progress": 1.0}) + "\n")
    with pytest.raises(SystemExit, match="put_back_block declares no place predicates"):
        loops.run_row("x", folder, loop=2)
