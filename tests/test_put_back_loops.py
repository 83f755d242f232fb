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


def test_a_row_set_back_in_its_own_order_is_a_put_back_and_a_new_order_a_move():
    """blocks_ranking_try's place is its row: empty while a cube is held or off the slots, so
    a cube lifted and set back leaves the order as it was (a put-back) and a swap changes it
    (a move); the task declares it."""
    from rmbench.tasks import get_task

    loops = _loops()
    places = get_task("blocks_ranking_try").place_predicates
    assert places == ("row",)
    events = [[0, "task", "subtask", "swap the middle and right blocks"],
              [0, "task", "row", [2, 0, 1]], [0, "task", "presses", 1],
              [80, "task", "row", []], [95, "task", "row", [2, 0, 1]],
              [120, "task", "row", []], [500, "task", "row", [2, 1, 0]],
              [520, "task", "subtask", "press the button to check the order"],
              [600, "task", "row", []]]
    out, back, moved = loops.put_backs({"events": events}, places)
    assert (dict(out), back, moved) == ({"swap the middle and right blocks": 1}, [15], [380])
