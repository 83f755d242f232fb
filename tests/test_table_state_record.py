"""benchmarks/table_state.py: recording a table run's cells in the committed state table
replaces each cell and keeps every replaced measurement of other data under ``superseded``."""

import json

import pytest

from tests.conftest import load_script


@pytest.fixture
def table_state(monkeypatch):
    module = load_script("benchmarks/table_state.py")
    # the cells' records read evaluation folders; the rows here stand for them
    monkeypatch.setattr(module, "cell_record", lambda row, task: dict(row))
    return module


def _doc():
    return {"cells": {"press_button": {"mem0": {"successes": 2}, "dp": {"successes": 2}}},
            "chance": {"press_button": {"rate": 0.011}}, "superseded": []}


def _run(k=36):
    return {"command": "rmbench table ...", "chance": {"press_button": {"rate": 0.011}},
            "cells": {"press_button": {"mem0": {"successes": k}}}}


def test_a_table_that_ran_another_seed_alone_is_not_recorded_as_the_cell(table_state):
    """A table whose Mem-0 column is seed 1 alone holds no seed-0 cell to replace the
    recorded one with: it is recorded with --seed 1, into the pool."""
    run = {**_run(), "plan": {"obs": "state", "policies": ["mem0@1"]}}
    with pytest.raises(SystemExit, match=r"its mem0 column is \['mem0@1'\], without seed 0"):
        table_state.record(_doc(), run, ["press_button"], ["mem0"], "rmbench/2", "why", "t")


def test_a_cell_of_other_data_moves_to_superseded(table_state):
    from rmbench.suite.records import unstated_conditions

    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    # its walls' conditions unstated until its record says them (suite/records.py)
    assert doc["cells"]["press_button"]["mem0"] == {
        "conditions": unstated_conditions("mem0"), "successes": 36, "dataset": "rmbench/2",
        "command": "rmbench table ..."}
    assert unstated_conditions("mem0:gt_classifier")["train"] == []  # Mem-0's checkpoint
    assert doc["cells"]["press_button"]["dp"] == {"successes": 2}  # untouched
    assert doc["superseded"] == [{"why": "format 1", "cells": {"press_button": {"mem0": {"successes": 2}}}}]


def test_a_column_of_two_seeds_keeps_each_seeds_conditions(table_state):
    """A table trained with --train-seeds 0,1 is recorded in one call: each seed's record
    keeps its walls' conditions, data and command, as one recorded with --seed does."""
    run = {**_run(), "plan": {"obs": "state", "policies": ["mem0", "mem0@1"]},
           "cells": {"press_button": {"mem0": {"successes": 60, "seeds": {
               "0": {"successes": 36}, "1": {"successes": 24}}}}}}
    doc = table_state.record(_doc(), run, ["press_button"], ["mem0"], "rmbench/2", "format 1",
                             "t", conditions={"machine": "cpu", "threads": 1})
    cell = doc["cells"]["press_button"]["mem0"]
    for seed, k in (("0", 36), ("1", 24)):
        r = cell["seeds"][seed]
        assert r["successes"] == k and r["conditions"] == cell["conditions"]
        assert r["conditions"]["train"][0]["machine"] == "cpu"
        assert (r["dataset"], r["command"]) == ("rmbench/2", "rmbench table ...")


def test_a_cell_of_the_same_data_is_replaced_without_a_copy(table_state):
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    doc = table_state.record(doc, _run(40), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    assert doc["cells"]["press_button"]["mem0"]["successes"] == 40
    assert doc["superseded"][0]["cells"]["press_button"]["mem0"] == {"successes": 2}
    assert len(doc["superseded"]) == 1


def test_a_cell_of_another_recipe_moves_to_superseded_on_the_same_data(table_state):
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "format 1", "t")
    doc = table_state.record(doc, _run(40), ["press_button"], ["mem0"], "rmbench/2",
                             "the recipe changed", "t", recipe_changed=True)
    assert doc["cells"]["press_button"]["mem0"]["successes"] == 40
    (moved,) = [g for g in doc["superseded"] if g["why"] == "the recipe changed"]
    assert moved["cells"]["press_button"]["mem0"]["successes"] == 36
    with pytest.raises(SystemExit, match="--why"):
        table_state.record(doc, _run(41), ["press_button"], ["mem0"], "rmbench/2", None, "t",
                           recipe_changed=True)
    # the new recipe's cell recorded again: the cell before the change stays superseded
    doc = table_state.record(doc, _run(42), ["press_button"], ["mem0"], "rmbench/2",
                             "the recipe changed", "t", recipe_changed=True)
    assert doc["cells"]["press_button"]["mem0"]["successes"] == 42
    (moved,) = [g for g in doc["superseded"] if g["why"] == "the recipe changed"]
    assert moved["cells"]["press_button"]["mem0"]["successes"] == 36


def test_a_cell_keeps_its_tasks_recipe_items_and_other_items_do_not_pool(table_state):
    """A table's plan names the items its recipe adds for one task alone: each cell keeps
    those meant for its policy (Mem-0's, not DP's), and a cell of other items is another
    recipe's measurement, so it replaces the recorded one under --why and never pools with
    it as a seed."""
    reach = 'mem0.reach_input=["cube_left"]'
    plan = {"obs": "state", "policies": ["mem0", "dp"],
            "task_sets": {"press_button": [reach, "dp.n_obs_steps=2"]}}
    run = {**_run(), "plan": plan,
           "cells": {"press_button": {"mem0": {"successes": 36}, "dp": {"successes": 3}}}}
    with pytest.raises(SystemExit, match="--why"):
        table_state.record(_doc(), run, ["press_button"], ["mem0"], "rmbench/2", None, "t")
    doc = table_state.record(_doc(), run, ["press_button"], ["mem0", "dp"], "rmbench/2",
                             "reach joints", "t")
    assert doc["cells"]["press_button"]["mem0"]["task_items"] == [reach]
    assert doc["cells"]["press_button"]["dp"]["task_items"] == ["dp.n_obs_steps=2"]
    (moved,) = doc["superseded"]
    assert moved["cells"]["press_button"]["mem0"] == {"successes": 2}
    # a seed trained without the items does not join the cell trained with them
    seed1 = {**_run(24), "plan": {"obs": "state", "policies": ["mem0@1"], "task_sets": {}},
             "cells": {"press_button": {"mem0": {"successes": 24}}}}
    with pytest.raises(SystemExit, match=r"task items \(\)"):
        table_state.record(doc, seed1, ["press_button"], ["mem0"], "rmbench/2", None, "t",
                           seed=1)


def test_a_cell_not_evaluated_is_a_one_line_error(table_state):
    with pytest.raises(SystemExit, match="press_button mem0:no_key is not evaluated yet"):
        table_state.record(_doc(), _run(), ["press_button"], ["mem0:no_key"], "rmbench/2", "x", "t")


def test_a_cell_of_another_task_version_moves_to_superseded(table_state):
    doc = {"cells": {"battery_try": {"mem0": {"successes": 94, "dataset": "rmbench/2",
                                              "gym_id": "rmbench/BatteryTry-v1"}}},
           "chance": {}, "superseded": []}
    run = {"command": "rmbench table ...", "chance": {"battery_try": {"rate": 0.75}},
           "cells": {"battery_try": {"mem0": {"successes": 80, "gym_id": "rmbench/BatteryTry-v2"}}}}
    doc = table_state.record(doc, run, ["battery_try"], ["mem0"], "rmbench/2", "v1", "t")
    assert doc["cells"]["battery_try"]["mem0"]["successes"] == 80
    assert doc["superseded"][0]["cells"]["battery_try"]["mem0"]["successes"] == 94
    # a cell pooling seeds moves whole: a first seed on the new version stands alone
    doc["cells"]["battery_try"]["mem0"] = {"successes": 180, "dataset": "rmbench/2",
                                           "gym_id": "rmbench/BatteryTry-v2", "seeds": {}}
    run["cells"]["battery_try"]["mem0"] = {"successes": 40, "gym_id": "rmbench/BatteryTry-v3"}
    doc = table_state.record(doc, run, ["battery_try"], ["mem0"], "rmbench/2", "v2", "t")
    assert doc["cells"]["battery_try"]["mem0"]["successes"] == 40
    assert doc["superseded"][-1]["cells"]["battery_try"]["mem0"]["successes"] == 180


def test_a_cell_of_an_earlier_version_is_withdrawn_and_a_current_one_is_refused(table_state,
                                                                                   tmp_path):
    """--withdraw empties a cell run on an earlier task version, keeping it under superseded;
    a cell of the current version stays where it is, with a one-line error."""
    from rmbench.tasks import get_task

    current = get_task("battery_try").gym_id
    doc = {"cells": {"battery_try": {"act": {"successes": 37, "gym_id": "rmbench/BatteryTry-v1"},
                                     "dp": {"successes": 22, "gym_id": current}}},
           "chance": {}, "superseded": []}
    out = tmp_path / "table_state.json"
    out.write_text(json.dumps(doc))
    assert table_state.main(["--withdraw", "--tasks", "battery_try", "--specs", "act",
                             "--why", "run on v1", "--out", str(out)]) == 0
    kept = json.loads(out.read_text())
    assert "act" not in kept["cells"]["battery_try"] and kept["cells"]["battery_try"]["dp"]
    assert kept["superseded"] == [{"why": "run on v1", "cells": {"battery_try": {
        "act": {"successes": 37, "gym_id": "rmbench/BatteryTry-v1"}}}}]
    with pytest.raises(SystemExit, match=f"battery_try dp: ran on {current}, the current"):
        table_state.withdraw(kept, ["battery_try"], ["dp"], "why")
    with pytest.raises(SystemExit, match="--why"):
        table_state.main(["--withdraw", "--tasks", "battery_try", "--specs", "dp",
                          "--out", str(out)])
    assert json.loads(out.read_text()) == kept  # nothing written by a refusal


def test_an_evaluation_folder_gives_one_column_with_its_checkpoints_history(tmp_path):
    """A planner refit's cell names the checkpoint it came from and takes that training's
    wall; the evaluation's wall adds up its episodes'."""
    import json

    from rmbench.suite.records import evaluation_rows

    trained, refit, evals = tmp_path / "trained", tmp_path / "refit", tmp_path / "eval"
    trained.mkdir()
    (trained / "timing.json").write_text(json.dumps({"train_wall_s": 2000.0, "machines": ["m"]}))
    refit.mkdir()
    (refit / "config.json").write_text(json.dumps(
        {"planner_refit": {"from": str(trained), "set": {"planner_key_delay": 12}}}))
    (evals / "press_button").mkdir(parents=True)
    (evals / "run.json").write_text(json.dumps(
        {"policy": f"mem0:{refit}?ablation=gt_classifier", "seed": 0, "episodes": 100}))
    (evals / "summary.json").write_text(json.dumps({"tasks": {"press_button": {
        "successes": 1, "episodes": 2, "success_rate": 0.5, "mean_progress": 0.5,
        "endings": {"success": 1, "timeout": 1}, "gym_id": "rmbench/PressButton-v2"}}}))
    episodes = [{"seed": 1, "success": True, "reason": "success", "message": "", "wall_s": 3.0,
                 "progress": 1.0},
                {"seed": 2, "success": False, "reason": "timeout", "message": "", "wall_s": 4.5,
                 "progress": 0.0}]
    (evals / "press_button" / "episodes.jsonl").write_text(
        "".join(json.dumps(e) + "\n" for e in episodes))
    res = evaluation_rows(evals, "mem0:gt_classifier")
    row = res["cells"]["press_button"]["mem0:gt_classifier"]
    assert row["train_wall_s"] == 2000.0 and row["eval_wall_s"] == 7.5
    assert row["planner_refit"] == {"from": str(trained), "set": {"planner_key_delay": 12}}
    assert row["failure_reasons"] == {"timeout": 1} and row["gym_id"] == "rmbench/PressButton-v2"
    assert row["checkpoint"] == str(refit)
    assert res["command"].startswith("rmbench eval --task press_button --policy mem0:")


@pytest.mark.parametrize("run, said", [
    ({"split": "validation"}, "other episodes than the table's"),
    ({"seed": 5}, "other episodes than the table's"),
    ({"seeds_of": "/data"}, "other episodes than the table's"),
    ({"episodes": 50}, "other episodes than the table's"),
    ({"instructions": "unseen"}, "other episodes than the table's"),
    ({"policy": "POLICY"}, "evaluates mem0 .*, not mem0:gt_classifier"),
])
def test_an_evaluation_folder_of_other_episodes_or_another_column_is_refused(tmp_path, run,
                                                                             said):
    """A validation run, a run from another seed or on a dataset's seeds, or a plain Mem-0
    evaluation given as its gt_classifier column: each refused in one line."""
    import json

    from rmbench.suite.records import evaluation_rows

    ckpt, evals = tmp_path / "ckpt", tmp_path / "eval"
    ckpt.mkdir()
    (ckpt / "config.json").write_text(json.dumps({"config": {"ablations": []}}))
    evals.mkdir()
    policy = f"mem0:{ckpt}?ablation=gt_classifier"
    run = {"policy": policy, "seed": 0, "episodes": 100,
           **{k: (f"mem0:{ckpt}" if v == "POLICY" else v) for k, v in run.items()}}
    (evals / "run.json").write_text(json.dumps(run))
    (evals / "summary.json").write_text(json.dumps({"tasks": {}}))
    with pytest.raises(ValueError, match=said):
        evaluation_rows(evals, "mem0:gt_classifier")


def _seed_row(k, **extra):
    return {"successes": k, "episodes": 100, "mean_progress": 0.5,
            "endings": {"success": k, "task_failure": 100 - k},
            "failure_reasons": {"wrong count": 100 - k}, "train_wall_s": 10.0,
            "eval_wall_s": 5.0, "machines": {"train": ["a"], "eval": ["b"]}, **extra}


def test_a_seed_joins_the_recorded_cell_and_the_cell_is_their_pool(table_state):
    """A refit's seed 0 (an evaluation folder, recorded before versions were kept) and a
    table's seed 1 pool into one cell: the mean, both records, both commands."""
    doc = {"cells": {"press_button": {"mem0": {**_seed_row(69), "dataset": "rmbench/2",
                                               "command": "rmbench eval ..."}}},
           "chance": {}, "superseded": []}
    run = {"command": "rmbench table ...", "chance": {"press_button": {"rate": 0.011}},
           "plan": {"policies": ["mem0@1"]},
           "cells": {"press_button": {"mem0": _seed_row(61, gym_id="rmbench/PressButton-v2")}}}
    doc = table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/2", "x", "t", seed=1)
    cell = doc["cells"]["press_button"]["mem0"]
    assert (cell["successes"], cell["episodes"], cell["success_rate"]) == (130, 200, 0.65)
    assert cell["seeds"]["0"]["successes"] == 69 and cell["seeds"]["1"]["successes"] == 61
    assert cell["command"] == "rmbench eval ...; rmbench table ..."
    assert cell["failure_reasons"] == {"wrong count": 70} and doc["superseded"] == []
    # recording the same seed again replaces it rather than pooling it twice
    run["cells"]["press_button"]["mem0"] = _seed_row(70, gym_id="rmbench/PressButton-v2")
    doc = table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/2", "x", "t", seed=1)
    cell = doc["cells"]["press_button"]["mem0"]
    assert (cell["successes"], cell["episodes"], cell["seeds"]["1"]["successes"]) == (139, 200, 70)
    # a cell of one seed does not replace the pool (seed 1 would be lost without a trace)
    with pytest.raises(SystemExit, match=r"pools seeds \['0', '1'\]; give --seed"):
        table_state.record(doc, _run(), ["press_button"], ["mem0"], "rmbench/2", "x", "t")


def test_a_seed_from_an_evaluation_folder_pools_and_keeps_a_memory_it_knows(table_state):
    """An eval folder's row (no plan, no memory in words) joins a table's seed 0."""
    doc = {"cells": {"press_button": {"mem0": {**_seed_row(69, memory="anchor + window"),
                                               "dataset": "rmbench/2", "command": "t0"}}},
           "chance": {}, "superseded": []}
    run = {"command": "rmbench eval ...", "plan": None,
           "cells": {"press_button": {"mem0": _seed_row(61)}}}
    doc = table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/2", "x", "t", seed=1)
    cell = doc["cells"]["press_button"]["mem0"]
    assert cell["memory"] == "anchor + window" and cell["episodes"] == 200


def test_a_seed_of_other_data_or_a_pooled_column_is_refused(table_state):
    doc = {"cells": {"press_button": {"mem0": {**_seed_row(69), "dataset": "rmbench/1"}}},
           "chance": {}, "superseded": []}
    run = {"command": "c", "plan": {"policies": ["mem0@1"]},
           "cells": {"press_button": {"mem0": _seed_row(61)}}}
    with pytest.raises(SystemExit, match="seed 1 trained on rmbench/2"):
        table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/2", "x", "t", seed=1)
    with pytest.raises(SystemExit, match="no recorded cell to add seed 1 to"):
        table_state.record({"cells": {}, "chance": {}}, run, ["press_button"], ["mem0"],
                           "rmbench/1", "x", "t", seed=1)
    run["plan"] = {"policies": ["mem0", "mem0@1"]}
    with pytest.raises(SystemExit, match=r"column is \['mem0', 'mem0@1'\], not seed 1 alone"):
        table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/1", "x", "t", seed=1)
    run["plan"] = None  # a pooled row from a source that names no plan
    run["cells"]["press_button"]["mem0"] = {**_seed_row(61), "seeds": {"0": {}, "1": {}}}
    with pytest.raises(SystemExit, match=r"pools seeds \['0', '1'\]; record one seed"):
        table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/1", "x", "t", seed=2)


def test_a_seed_of_another_task_version_is_refused(table_state):
    doc = {"cells": {"battery_try": {"mem0": {**_seed_row(94), "dataset": "rmbench/2"}}},
           "chance": {}, "superseded": []}  # recorded before versions were kept: v1
    run = {"command": "c", "plan": None,
           "cells": {"battery_try": {"mem0": _seed_row(99, gym_id="rmbench/BatteryTry-v2")}}}
    with pytest.raises(SystemExit, match=r"\(rmbench/BatteryTry-v2\), the recorded cell on "
                                         r"rmbench/2 \(rmbench/BatteryTry-v1\)"):
        table_state.record(doc, run, ["battery_try"], ["mem0"], "rmbench/2", "x", "t", seed=1)


def test_the_command_line_refuses_a_negative_seed_and_a_missing_why(table_state):
    with pytest.raises(SystemExit, match="a training seed is 0 or more"):
        table_state.main(["--table", "t", "--tasks", "press_button", "--specs", "mem0",
                          "--dataset", "rmbench/2", "--seed", "-1"])
    # --why is asked for only where a cell moves to superseded, and names the cells
    with pytest.raises(SystemExit, match=r"--why: say why .* \(press_button mem0\)"):
        table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", None, "t")
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "f1", "t")
    doc = table_state.record(doc, _run(40), ["press_button"], ["mem0"], "rmbench/2", None, "t")
    assert doc["cells"]["press_button"]["mem0"]["successes"] == 40


def test_the_camera_table_starts_from_its_first_record(table_state, tmp_path):
    """``--obs pixels`` records into a file of its own, made by the first record; a run of
    the other observation is refused in one line."""
    import json

    run = {**_run(), "plan": {"obs": "pixels", "tasks": ["press_button"]}}
    (tmp_path / "table.json").write_text(json.dumps(run))
    out = tmp_path / "table_pixels.json"
    args = ["--table", str(tmp_path), "--tasks", "press_button", "--specs", "mem0",
            "--dataset", "rmbench/2", "--obs", "pixels", "--out", str(out)]  # nothing replaced
    assert table_state.main(args) == 0
    doc = json.loads(out.read_text())
    assert doc["command"] == table_state.PIXELS_COMMAND and doc["plan"]["obs"] == "pixels"
    assert doc["cells"]["press_button"]["mem0"]["successes"] == 36
    assert doc["chance"]["press_button"] == {"rate": 0.011} and doc["superseded"] == []
    with pytest.raises(SystemExit, match="not state"):
        table_state.main([*args[:-4], "--out", str(out)])  # --obs state by default
    # a task's data walls come with its cells; a note written on them stays on re-recording
    doc["data_walls"] = {"press_button": {"collect_wall_s": 1.0, "note": "in pieces"}}
    out.write_text(json.dumps(doc))
    (tmp_path / "table.json").write_text(json.dumps(
        {**run, "wall_s": {"data": {"press_button": {"collect_wall_s": 2.0, "copies_wall_s": 3.0}}}}))
    assert table_state.main(args) == 0
    assert json.loads(out.read_text())["data_walls"] == {
        "press_button": {"collect_wall_s": 2.0, "copies_wall_s": 3.0, "note": "in pieces"}}
    # --data-note writes (or replaces) that note; for a task without data walls it is refused
    assert table_state.main([*args, "--data-note", "beside tests"]) == 0
    assert json.loads(out.read_text())["data_walls"]["press_button"]["note"] == "beside tests"
    (tmp_path / "table.json").write_text(json.dumps(run))
    doc = json.loads(out.read_text())
    del doc["data_walls"]
    out.write_text(json.dumps(doc))
    with pytest.raises(SystemExit, match="--data-note: press_button has no data walls"):
        table_state.main([*args, "--data-note", "beside tests"])


def test_an_m1_seed_pools_across_dataset_formats_an_mn_seed_does_not(table_state):
    """The dataset format changed how plan steps are cut into subtasks: M(1) Mem-0 reads one
    subtask (the goal), so its seeds pool across formats; an M(n) Mem-0 seed does not."""
    run = {"command": "rmbench table ...", "plan": {"policies": ["mem0@1"]},
           "cells": {"swap_T": {"mem0": _seed_row(70)}, "press_button": {"mem0": _seed_row(61)}}}
    doc = {"cells": {"swap_T": {"mem0": _seed_row(77)}, "press_button": {"mem0": _seed_row(69)}},
           "chance": {}, "superseded": []}  # recorded before cells kept their format
    doc = table_state.record(doc, run, ["swap_T"], ["mem0"], "rmbench/2", "x", "t", seed=1)
    assert doc["cells"]["swap_T"]["mem0"]["successes"] == 147
    with pytest.raises(SystemExit, match="seed 1 trained on rmbench/2"):
        table_state.record(doc, run, ["press_button"], ["mem0"], "rmbench/2", "x", "t", seed=1)


def test_the_walls_conditions_are_written_from_the_command_line(table_state):
    from rmbench.suite.records import stated_conditions

    said = {"machine": "cpu", "threads": 1, "workers": 1, "jobs_beside": 2,
            "beside": "a camera-table training", "note": None}
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2",
                             "format 1", "t", conditions=said)
    train, = doc["cells"]["press_button"]["mem0"]["conditions"]["train"]
    ev, = doc["cells"]["press_button"]["mem0"]["conditions"]["eval"]
    # each stage takes the fields it has: threads for the training, workers for the evaluation
    assert train["threads"] == 1 and "workers" not in train
    assert ev["workers"] == 1 and "threads" not in ev
    assert train["jobs_beside"] == ev["jobs_beside"] == 2
    assert train["beside"] == ev["beside"] == "a camera-table training"
    assert train["note"] is None and train["steps"] is None  # not said: unstated
    # a note for the training alone (it ran in pieces) stays off the evaluation's wall
    said = {**said, "note": "shared", "train_note": "in two pieces"}
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2",
                             "format 1", "t", conditions=said)
    train, = doc["cells"]["press_button"]["mem0"]["conditions"]["train"]
    ev, = doc["cells"]["press_button"]["mem0"]["conditions"]["eval"]
    assert (train["note"], ev["note"]) == ("in two pieces", "shared")
    said = {**said, "eval_note": "resumed"}
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2",
                             "format 1", "t", conditions=said)
    train, = doc["cells"]["press_button"]["mem0"]["conditions"]["train"]
    ev, = doc["cells"]["press_button"]["mem0"]["conditions"]["eval"]
    assert (train["note"], ev["note"]) == ("in two pieces", "resumed")
    # what ran beside each stage, where the two differ
    said = {**said, "eval_beside": "the next task's data"}
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2",
                             "format 1", "t", conditions=said)
    train, = doc["cells"]["press_button"]["mem0"]["conditions"]["train"]
    ev, = doc["cells"]["press_button"]["mem0"]["conditions"]["eval"]
    assert (train["beside"], ev["beside"]) == ("a camera-table training", "the next task's data")
    with pytest.raises(ValueError, match="no stage check"):
        stated_conditions("mem0", {"check": {"note": "x"}})
    # gt_classifier evaluates Mem-0's checkpoint: no training piece to state
    assert stated_conditions("mem0:gt_classifier", machine="cpu")["train"] == []
    with pytest.raises(ValueError, match="no condition field wall"):
        stated_conditions("mem0", wall=3)


def test_an_unknown_machine_is_a_one_line_error(table_state, tmp_path):
    import json

    out = tmp_path / "table_state.json"
    out.write_text(json.dumps({**_doc(), "machines": {"cpu": {}}}))
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "table.json").write_text(json.dumps(_run()))
    args = ["--table", str(folder), "--tasks", "press_button", "--specs", "mem0",
            "--dataset", "rmbench/2", "--out", str(out)]
    with pytest.raises(SystemExit, match="--machine: machine 'tpu' is not one of table_state.json"):
        table_state.main([*args, "--machine", "tpu"])
    with pytest.raises(SystemExit, match="--train-piece: machine 'tpu' is not one of"):
        table_state.main([*args, "--train-piece", '{"machine": "tpu", "steps": [0, 10]}'])
    # known machines pass, and --eval-note reaches the evaluation's wall alone
    assert table_state.main([*args, "--machine", "cpu", "--eval-note", "resumed",
                             "--why", "format 1"]) == 0
    cell = json.loads(out.read_text())["cells"]["press_button"]["mem0"]["conditions"]
    assert (cell["train"][0]["note"], cell["eval"][0]["note"]) == (None, "resumed")
    assert cell["train"][0]["machine"] == cell["eval"][0]["machine"] == "cpu"


def test_a_training_run_in_pieces_keeps_each_piece(table_state):
    from rmbench.suite.records import stated_conditions

    gpu = {"machine": "h200", "steps": [0, 17500], "wall_s": 442.3, "jobs_beside": 1}
    cpu = {"machine": "cpu", "steps": [17500, 18000], "wall_s": 519.6}
    doc = table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "x", "t",
                             conditions={"jobs_beside": 3, "workers": 1}, train_pieces=[gpu, cpu])
    train, (ev,) = (doc["cells"]["press_button"]["mem0"]["conditions"][k] for k in ("train", "eval"))
    assert [(p["machine"], p["steps"], p["wall_s"]) for p in train] == [
        ("h200", [0, 17500], 442.3), ("cpu", [17500, 18000], 519.6)]
    # a piece's own field stands; the options fill only what it leaves unsaid
    assert [p["jobs_beside"] for p in train] == [1, 3] and ev["jobs_beside"] == 3
    with pytest.raises(SystemExit, match="do not follow one another"):
        table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "x", "t",
                           train_pieces=[gpu, {**cpu, "steps": [17000, 18000]}])
    with pytest.raises(SystemExit, match="training piece 0: no field gpu"):
        table_state.record(_doc(), _run(), ["press_button"], ["mem0"], "rmbench/2", "x", "t",
                           train_pieces=[{**gpu, "gpu": "H200"}])
    with pytest.raises(ValueError, match="trains nothing of its own"):
        stated_conditions("mem0:gt_classifier", train_pieces=[gpu])
    # a --note reaches every piece that leaves it unsaid; steps that are not whole numbers
    # are a one-line error, not a traceback
    stated = stated_conditions("mem0", {"train": {"note": None}}, [gpu, cpu], note="in two runs")
    assert [p["note"] for p in stated["train"]] == ["in two runs", "in two runs"]
    with pytest.raises(ValueError, match=r"training piece 1: steps must be \[from, to\]"):
        stated_conditions("mem0", train_pieces=[gpu, {**cpu, "steps": ["17500", None]}])


def test_a_training_piece_on_the_command_line_is_a_json_object(table_state, tmp_path):
    with pytest.raises(SystemExit):
        table_state.main(["--table", str(tmp_path), "--tasks", "press_button", "--specs", "mem0",
                          "--dataset", "rmbench/2", "--train-piece", "[0, 17500]"])
    assert table_state._train_piece('{"steps": [0, 10]}') == {"steps": [0, 10]}
    with pytest.raises(Exception, match="not JSON"):
        table_state._train_piece("{steps: [0, 10]}")


def test_a_rerun_is_kept_beside_the_seed_it_repeats_and_changes_no_cell(table_state):
    """The recorded seed trained again on another machine: kept under reruns, the cell and
    its pool untouched; recording it again replaces it; a seed not recorded, other data or
    a pooled row is refused."""
    cell = {"successes": 51, "episodes": 200, "dataset": "rmbench/2", "command": "c0",
            "seeds": {"0": {**_seed_row(28), "dataset": "rmbench/2"},
                      "1": {**_seed_row(23), "dataset": "rmbench/2"}}}
    doc = {"cells": {"press_button": {"mem0": cell}}, "chance": {}, "superseded": []}
    run = {"command": "rmbench table ... --out elsewhere", "plan": {"policies": ["mem0"]},
           "cells": {"press_button": {"mem0": _seed_row(36)}}}
    doc = table_state.add_rerun(doc, run, ["press_button"], ["mem0"], "rmbench/2", "t", 0,
                                {"machine": "cpu", "train_beside": "another training"})
    assert doc["cells"]["press_button"]["mem0"] == cell and doc["superseded"] == []
    (rerun,) = doc["reruns"]
    assert (rerun["task"], rerun["column"], rerun["seed"], rerun["successes"]) == (
        "press_button", "mem0", 0, 36)
    assert rerun["conditions"]["train"][0]["beside"] == "another training"
    run["cells"]["press_button"]["mem0"] = _seed_row(37)
    doc = table_state.add_rerun(doc, run, ["press_button"], ["mem0"], "rmbench/2", "t", 0)
    assert [r["successes"] for r in doc["reruns"]] == [37]
    with pytest.raises(SystemExit, match="no recorded seed 2 to re-run"):
        table_state.add_rerun(doc, run, ["press_button"], ["mem0"], "rmbench/2", "t", 2)
    with pytest.raises(SystemExit, match="the re-run trained on rmbench/1"):
        table_state.add_rerun(doc, run, ["press_button"], ["mem0"], "rmbench/1", "t", 0)
    run["cells"]["press_button"]["mem0"] = {**_seed_row(36), "seeds": {"0": {}, "1": {}}}
    with pytest.raises(SystemExit, match="a re-run is one seed"):
        table_state.add_rerun(doc, run, ["press_button"], ["mem0"], "rmbench/2", "t", 0)
    with pytest.raises(SystemExit, match="--rerun replaces nothing"):
        table_state.main(["--table", "t", "--tasks", "press_button", "--specs", "mem0",
                          "--dataset", "rmbench/2", "--rerun", "--why", "x"])
