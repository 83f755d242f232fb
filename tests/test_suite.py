"""``rmbench table`` (rmbench.suite) and benchmarks/learning.py over it: the plan's columns and
folders, the jobs a table still needs, a toy table end to end (resumed, a corrupt checkpoint
failing its cell alone) and the tables it writes."""

import argparse
import io
import json
import shlex
from pathlib import Path

import pytest

from rmbench.cli.main import main as cli
from rmbench.data.reader import Dataset
from rmbench.eval.chance import chance
from rmbench.eval.intervals import wilson
from rmbench.files import read_json_or
from rmbench.machine import describe, short
from rmbench.policies.mem0.config import Mem0Config
from rmbench.suite import (
    backends,
    cell_rows,
    clock,
    data_stage,
    runner,
    schedule,
    stages,
    tables,
    versions,
)
from rmbench.suite.plan import (
    ALL_POLICIES,
    COLUMNS,
    Plan,
    applies,
    bounded,
    check_sets,
    config_for,
    executor_spec,
    memory_of,
    parse_policy,
    run_name,
    trained_spec,
)
from rmbench.suite.progress import Progress, column
from rmbench.suite.recipes import GENERIC, RECIPES, add_recipe_arguments, recipe_of
from rmbench.tasks import TASKS, get_task
from rmbench.tasks.registry import UnknownTaskError
from tests.conftest import load_script


def test_policy_specs_and_their_columns():
    assert parse_policy("mem0:no_anchor+gt_classifier") == ("mem0", ("no_anchor",), ("gt_classifier",))
    assert parse_policy("dp") == ("dp", (), ())
    assert trained_spec("mem0:gt_classifier") == "mem0"
    for bad, match in (("pi0", "unknown policy"), ("act:no_memory", "only Mem-0"),
                       ("mem0:no_brain", "unknown ablation")):
        with pytest.raises(ValueError, match=match):
            parse_policy(bad)
    # no_key and gt_classifier concern the planner and classifier an M(1) task lacks
    assert not applies("mem0:no_key", "M(1)") and applies("mem0:no_key", "M(n)")
    assert applies("mem0:no_anchor", "M(1)")
    plan = Plan("state", ("press_button", "put_back_block"), ("mem0", "mem0:no_key", "dp"))
    assert plan.cells() == [("put_back_block", "mem0"), ("put_back_block", "dp"),
                            ("press_button", "mem0"), ("press_button", "mem0:no_key"),
                            ("press_button", "dp")]
    gt = Plan("state", ("press_button",), ("mem0", "mem0:gt_classifier"))
    out, task = Path("/t"), "press_button"
    assert gt.train_dir(out, task, "mem0:gt_classifier") == gt.train_dir(out, task, "mem0")
    assert gt.eval_dir(out, task, "mem0:gt_classifier") != gt.eval_dir(out, task, "mem0")
    assert gt.eval_policy(out, task, "mem0:gt_classifier").endswith("?ablation=gt_classifier")
    assert Plan.from_dict(json.loads(json.dumps(gt.to_dict()))) == gt
    with pytest.raises(ValueError, match="obs must be"):
        Plan("depth", ("press_button",))
    with pytest.raises(Exception, match="unknown task"):
        Plan("state", ("no_such_task",))
    # where the cells train names no folder: a run started on a GPU is the same cell
    on_gpu = Plan("state", ("press_button",), ("mem0",), device="cuda:0")
    assert on_gpu.train_dir(out, task, "mem0") == Plan("state", ("press_button",)).train_dir(
        out, task, "mem0")
    with pytest.raises(ValueError, match="device must be"):
        Plan("state", ("press_button",), device="gpu")


def test_set_reaches_only_the_configs_with_the_field():
    sets = ["head_layers=2", "execute=10", "obs_steps=3"]
    mem0 = config_for("mem0:no_anchor", "state", sets)
    assert (mem0.head_layers, mem0.execute, mem0.observation) == (2, 10, "state")
    assert mem0.ablations == ("no_anchor",)
    dp = config_for("dp", "state", sets)
    assert (dp.execute, dp.obs_steps) == (10, 3)  # DP has no head_layers: left alone
    check_sets(sets)
    # a value one policy's config refuses is a one-line error naming the policy
    with pytest.raises(ValueError, match="dp with execute=20: execute"):
        config_for("dp", "state", ["execute=20"])
    with pytest.raises(ValueError, match="dp with execute=20"):
        Plan("state", ("put_back_block",), ("mem0", "dp"), sets=("execute=20",))
    # POLICY.FIELD=VALUE reaches that policy alone
    plan = Plan("state", ("put_back_block",), ("mem0", "dp"), sets=("mem0.execute=20", "execute=4"))
    assert config_for("mem0", "state", plan.sets).execute == 4  # the later item wins
    assert config_for("mem0", "state", ["execute=4", "mem0.execute=20"]).execute == 20
    assert config_for("dp", "state", plan.sets).execute == 4
    with pytest.raises(ValueError, match="POLICY.FIELD"):
        check_sets(["dp.head_layers=2"])
    with pytest.raises(ValueError, match="no_such_field"):
        check_sets(["no_such_field=1"])
    with pytest.raises(ValueError, match="FIELD=VALUE"):
        check_sets(["head_layers"])


def table_recipe(argv: list[str], obs: str = "state") -> dict:
    parser = argparse.ArgumentParser()
    add_recipe_arguments(parser, defaults="recipe")
    return recipe_of(parser.parse_args(argv), RECIPES[obs])


def test_the_state_recipe_is_the_state_tables_default(tmp_path):
    # the state table's command as its cells were made, every item spelled out
    spelled = table_recipe(
        "--demos 50 --steps 18000 --batch 128 --episodes 100 --noise 0.02 --noise-kind white "
        "--set mem0.head_layers=2 --set mem0.execute=20 --set relative_actions=false "
        "--set mem0.action_patch=3 --set state_noise=0.02 --set state_noise_on=[\"mat_\"] "
        "--set grasp_pose_input=true --set layout_copies=16 --set layout_shift=0.04 "
        "--set mem0.sample_noise=0".split())
    assert table_recipe([]) == spelled  # the same cells, in the same folders
    plan = Plan("state", ("put_back_block",), ("mem0",), **table_recipe([]))
    assert config_for("mem0", "state", plan.sets).head_layers == 2
    # an option replaces the recipe's item for its field, and the rest stays
    changed = table_recipe(["--steps", "900", "--set", "mem0.execute=8"])
    assert changed["steps"] == 900 and "mem0.execute=8" in changed["sets"]
    assert "mem0.execute=20" not in changed["sets"] and "layout_copies=16" in changed["sets"]
    assert config_for("mem0", "state", changed["sets"]).execute == 8
    # outside a table (benchmarks/learning.py) the options start from the generic defaults
    parser = argparse.ArgumentParser()
    add_recipe_arguments(parser)
    assert recipe_of(parser.parse_args([])) == {**GENERIC, "sets": (), "task_sets": {}}


def test_the_camera_recipe_fits_the_planner_longer_on_the_m_n_rows_alone(tmp_path):
    """The M(1) rows have no planner: their camera cells keep the configs and folders of the
    recipe without the planner item; each M(n) row's Mem-0 fits its planner 15,000 steps."""
    recipe = table_recipe([], obs="pixels")
    plan = Plan("pixels", ("put_back_block", "press_button"), ("mem0",), **recipe)
    without = Plan("pixels", ("put_back_block", "press_button"), ("mem0",),
                   **{**recipe, "task_sets": {}})
    for task in TASKS:
        planner_steps = config_for("mem0", "pixels", plan.sets_of(task)).planner_steps
        assert planner_steps == (15000 if get_task(task).tmc == "M(n)"
                                 else Mem0Config().planner_steps), task
    assert plan.train_dir(tmp_path, "put_back_block", "mem0") == \
        without.train_dir(tmp_path, "put_back_block", "mem0")
    assert plan.train_dir(tmp_path, "press_button", "mem0") != \
        without.train_dir(tmp_path, "press_button", "mem0")


def test_task_sets_reach_their_task_alone(tmp_path):
    """A plan's task_sets add items to one task's cells: its configs and folders change, the
    other tasks' stay those of the plan without them; the items survive the job's JSON, an
    option for the same field replaces them, and an unknown task or field is refused."""
    shuffle = 'mem0.shuffle_entities=["object"]'
    tasks, policies = ("observe_and_pickup", "put_back_block"), ("mem0", "dp")
    plain = Plan("state", tasks, policies, sets=("mem0.execute=20",))
    plan = Plan("state", tasks, policies, sets=("mem0.execute=20",),
                task_sets={"observe_and_pickup": (shuffle,)})
    assert plan.sets_of("observe_and_pickup") == ("mem0.execute=20", shuffle)
    assert plan.sets_of("put_back_block") == plain.sets_of("put_back_block")
    assert config_for("mem0", "state", plan.sets_of("observe_and_pickup")).shuffle_entities \
        == ("object",)
    assert config_for("dp", "state", plan.sets_of("observe_and_pickup")).shuffle_entities == ()
    for folder in ("train_dir", "eval_dir"):
        for task, same in (("put_back_block", True), ("observe_and_pickup", False)):
            mine, theirs = (getattr(p, folder)(tmp_path, task, "mem0") for p in (plan, plain))
            assert (mine == theirs) is same
    assert Plan.from_dict(json.loads(json.dumps(plan.to_dict()))) == plan
    assert Plan.from_dict({k: v for k, v in plain.to_dict().items() if k != "task_sets"}) == plain
    # an option for the same field replaces the recipe's task item, as it does a shared one
    parser = argparse.ArgumentParser()
    add_recipe_arguments(parser, defaults="recipe")
    base = {**GENERIC, "task_sets": {"observe_and_pickup": (shuffle,)}}
    assert recipe_of(parser.parse_args([]), base)["task_sets"] == base["task_sets"]
    assert recipe_of(parser.parse_args(["--set", "mem0.shuffle_entities=[]"]), base)["task_sets"] == {}
    # --task-set: one task's items, replacing the recipe's item for that field on that task alone
    given = recipe_of(parser.parse_args(["--task-set", "observe_and_pickup:mem0.shuffle_entities=[]",
                                         "--task-set", "rmbench/PutBackBlock-v1:execute=8"]), base)
    assert given["task_sets"] == {"observe_and_pickup": ("mem0.shuffle_entities=[]",),
                                  "put_back_block": ("execute=8",)}
    for bad, says in (("execute=8", "TASK:"), ("no_such_task:execute=8", "no_such_task"),
                      ("put_back_block:", "TASK:")):
        with pytest.raises((ValueError, UnknownTaskError), match=says):
            recipe_of(parser.parse_args(["--task-set", bad]), base)
    with pytest.raises(UnknownTaskError, match="unknown task"):
        Plan("state", tasks, policies, task_sets={"no_such_task": (shuffle,)})
    with pytest.raises(ValueError, match="FIELD=VALUE"):
        Plan("state", tasks, policies, task_sets={"put_back_block": ("no_such_field=1",)})


def test_a_long_recipe_gets_a_folder_name_the_file_system_takes(tmp_path):
    # the state table's M(n) recipe: 12 --set items
    sets = ["mem0.head_layers=2", "mem0.execute=20", "relative_actions=false",
            "mem0.action_patch=3", "state_noise=0.02", 'state_noise_on=["mat_"]',
            "grasp_pose_input=true", "layout_copies=16", "layout_shift=0.04",
            "mem0.sample_noise=0", "mem0.end_classifier=event", "mem0.planner_key_delay=12"]
    plan = Plan(obs="state", tasks=("press_button",), policies=("mem0:no_key",), sets=tuple(sets))
    other = Plan(obs="state", tasks=("press_button",), policies=("mem0:no_key",),
                 sets=tuple(sets[:-1] + ["mem0.planner_key_delay=8"]))
    for make in (plan.train_dir, plan.eval_dir):
        folder = make(tmp_path, "press_button", "mem0:no_key")
        assert len(folder.name.encode()) <= 255
        folder.mkdir(parents=True)  # the file system takes it
        assert folder != (other.train_dir if make == plan.train_dir else other.eval_dir)(
            tmp_path, "press_button", "mem0:no_key")  # names stay distinct
    # a name that fits keeps its old form
    assert bounded("mem0-s18000-b128") == "mem0-s18000-b128"


def test_run_names_and_memory_in_words():
    plain = run_name("mem0:no_memory", 12000, 128)
    assert plain == "mem0-no_memory-s12000-b128"
    tagged = run_name("mem0:no_memory", 12000, 128, ["head_layers=2", 'observation="x"'])
    assert tagged.startswith(plain) and tagged != plain
    assert "/" not in run_name("mem0", 1, 1, ["cameras=[\"a/b\"]"])
    no_sliding = config_for("mem0:no_sliding", "state")
    assert "sliding" not in memory_of("mem0:no_sliding", "M(1)", no_sliding)
    window = config_for("mem0", "state", ["sliding_window=4"])
    assert "4 x 5 steps" in memory_of("mem0", "M(1)", window)
    assert "simulator" in memory_of("mem0:gt_classifier", "M(n)", config_for("mem0", "state"))


def test_jobs_wait_for_what_they_read(tmp_path):
    plan = Plan("state", ("press_button",), ("mem0", "mem0:gt_classifier", "dp"))
    needs = schedule.plan_jobs(plan, tmp_path)
    J = schedule.Job
    collect, train = J("collect", "press_button"), J("train", "press_button", "mem0")
    assert needs[collect] == () and needs[train] == (collect,)
    # the classifier ablation evaluates Mem-0's checkpoint: one training job for both
    assert needs[J("eval", "press_button", "mem0:gt_classifier")] == (train,)
    assert sorted(j.kind for j in needs) == ["collect", "eval", "eval", "eval", "train", "train"]
    # no_key takes Mem-0's executor (of its own training seed): that training first, even when
    # the table does not ask for Mem-0's column
    needs = schedule.plan_jobs(Plan("state", ("press_button",), ("mem0:no_key@1",)), tmp_path)
    mem0, no_key = J("train", "press_button", "mem0@1"), J("train", "press_button", "mem0:no_key@1")
    assert needs[mem0] == (collect,) and needs[no_key] == (collect, mem0)
    assert executor_spec("mem0:no_key@1") == "mem0@1" and executor_spec("mem0:no_anchor") is None
    assert executor_spec("mem0:no_anchor+no_key") == "mem0:no_anchor"
    # the M(n) memoryless control takes no_memory's executor, and is no M(1) column
    both = Plan("state", ("press_button", "put_back_block"), ("mem0:no_memory+no_key",))
    needs = schedule.plan_jobs(both, tmp_path)
    executor = J("train", "press_button", "mem0:no_memory")
    assert needs[J("train", "press_button", "mem0:no_memory+no_key")] == (collect, executor)
    assert not any(j.task == "put_back_block" for j in needs)


def test_a_stage_s_clock_is_kept_while_it_runs(tmp_path):
    """A stage killed after hours keeps its time: the clock is written as the stage runs."""
    import time

    from rmbench.suite.clock import TIMING, timed

    with timed(tmp_path, "copies_wall_s", every=0.01):
        deadline = time.monotonic() + 5
        while not read_json_or(tmp_path / TIMING, {}).get("copies_wall_s"):  # (0.0 at the start)
            assert time.monotonic() < deadline, "nothing written while the stage ran"
            time.sleep(0.01)
    first = read_json_or(tmp_path / TIMING, {})["copies_wall_s"]
    with timed(tmp_path, "copies_wall_s"):  # a resumption adds on
        pass
    timing = read_json_or(tmp_path / TIMING, {})
    assert timing["copies_wall_s"] >= first > 0 and len(timing["machines"]) == 1


def test_a_task_s_cells_start_before_the_next_task_s_data():
    J = schedule.Job
    plan = Plan("pixels", ("put_back_block", "press_button"), ("mem0", "mem0:no_memory"))
    order = schedule.start_order(schedule.plan_jobs(plan, Path("/nonexistent")))
    assert order[0] == J("collect", "put_back_block")
    kinds = [(j.task, j.kind) for j in order]
    assert kinds.index(("put_back_block", "train")) < kinds.index(("press_button", "collect"))
    assert kinds.index(("put_back_block", "eval")) < kinds.index(("put_back_block", "train"))


@pytest.fixture(scope="module")
def toy_table(tmp_path_factory):
    """A toy table, two jobs at a time: 2 demonstrations, 6 training steps, 1 episode."""
    out = tmp_path_factory.mktemp("table")
    args = ["table", "--obs", "state", "--tasks", "observe_and_pickup", "--policies", "mem0,dp",
            "--demos", "2", "--steps", "6", "--batch", "4", "--episodes", "1", "--out", str(out),
            "--jobs", "2", "--no-recipe"]
    assert cli(args) == 0
    return out, args


def test_toy_table_end_to_end_and_resumed(toy_table, capsys):
    out, args = toy_table
    res = json.loads((out / "table.json").read_text())
    cells = res["cells"]["observe_and_pickup"]
    assert set(cells) == {"mem0", "dp"}
    for row in cells.values():
        assert row["episodes"] == 1 and 0 <= row["success_rate"] <= 1 and row["train_wall_s"] > 0
        # each wall time says where it was measured: this machine, once
        assert row["machines"] == {"train": [describe()], "eval": [describe()]}
    # each checkpoint says the resolution of its training frames, which evaluation renders at
    collected = Dataset(out / "observe_and_pickup" / "data").rmbench["collection"]["resolution"]
    configs = list((out / "observe_and_pickup" / "train").glob("*/config.json"))
    assert configs and all(json.loads(c.read_text())["dataset"]["resolution"] == collected
                           for c in configs)
    text = (out / "table.md").read_text()
    assert "| observe_and_pickup | M(1) |" in text and "(published)" in text
    assert f"stages ran on {short(describe())}." in text
    # each task's chance level beside the published numbers, and what it assumes
    # eval/chance.py's level (tested there), as the table shows it
    level = chance("observe_and_pickup").rate
    assert "chance (no memory) |" in text and f"- observe_and_pickup: {100 * level:.1f}%" in text
    assert res["chance"]["observe_and_pickup"]["rate"] == level
    # a re-run finds every cell done: no job runs, nothing is rewritten but the tables
    checkpoint = out / "observe_and_pickup" / "train" / "mem0-s6-b4" / "model.safetensors"
    mtime = checkpoint.stat().st_mtime_ns
    plan = Plan.from_dict(res["plan"])
    assert schedule.plan_jobs(plan, out) == {}
    assert cli(args) == 0
    assert checkpoint.stat().st_mtime_ns == mtime
    assert "0 jobs to run" in capsys.readouterr().err


def test_a_corrupt_checkpoint_fails_its_cell_alone(toy_table, tmp_path, capsys):
    import shutil

    out, args = toy_table
    copy = tmp_path / "table"
    shutil.copytree(out, copy)
    plan = Plan.from_dict(json.loads((out / "table.json").read_text())["plan"])
    shutil.rmtree(plan.eval_dir(copy, "observe_and_pickup", "mem0"))
    shutil.rmtree(plan.eval_dir(copy, "observe_and_pickup", "dp"))
    (plan.train_dir(copy, "observe_and_pickup", "mem0") / "model.safetensors").write_bytes(b"junk")
    args = [a if a != str(out) else str(copy) for a in args]
    assert cli(args) == 1
    err = capsys.readouterr().err
    assert "FAILED eval observe_and_pickup mem0" in err and "1 job(s) failed" in err
    assert "model.safetensors" in json.loads((copy / "table.json").read_text())["failed"][
        "eval observe_and_pickup mem0"]  # the job's error, not just its exit status
    log = (copy / "logs" / "eval_observe_and_pickup_mem0.log").read_text()
    assert "model.safetensors" in log.strip().splitlines()[-1]  # the one-line error, in its log
    res = json.loads((copy / "table.json").read_text())
    assert res["cells"]["observe_and_pickup"]["mem0"] is None  # "—" in the tables
    assert res["cells"]["observe_and_pickup"]["dp"]["episodes"] == 1  # the other cell went on
    assert "eval observe_and_pickup mem0" in res["failed"]


def test_report_only_writes_the_whole_table_from_cells_run_apart(toy_table, tmp_path, capsys):
    import shutil

    out, args = toy_table
    copy = tmp_path / "table"
    shutil.copytree(out, copy)
    # the table widened to a column and a task not run: reported, nothing trained for them
    wide = [a if a != str(out) else str(copy) for a in args]
    wide[wide.index("--policies") + 1] = "mem0,dp,mem0:no_memory"
    wide[wide.index("--tasks") + 1] = "observe_and_pickup,swap_T"
    assert cli([*wide, "--report-only"]) == 0
    assert "jobs to run" not in capsys.readouterr().err
    res = json.loads((copy / "table.json").read_text())
    # the command recorded is the one that makes the cells, which the report only reads
    assert res["command"] == "rmbench " + " ".join(shlex.quote(a) for a in wide)
    # each task's data stages timed once, beside its cells (a task not run has none)
    assert res["wall_s"]["data"]["observe_and_pickup"]["collect_wall_s"] > 0
    assert res["wall_s"]["data"]["swap_T"] == {}
    cells = res["cells"]["observe_and_pickup"]
    assert cells["mem0"]["episodes"] == 1 and cells["dp"]["episodes"] == 1
    assert cells["mem0:no_memory"] is None and res["cells"]["swap_T"]["mem0"] is None
    assert not (copy / "swap_T").exists()
    assert not any("no_memory" in p.name for p in (copy / "observe_and_pickup" / "train").iterdir())
    assert "| swap_T | M(1) | — | — |" in (copy / "table.md").read_text()
    capsys.readouterr()
    assert cli([*[a if a != str(out) else str(tmp_path / "none") for a in args], "--report-only"]) == 2
    assert "rmbench: error: no table at" in capsys.readouterr().err


def test_each_observation_makes_its_own_columns_unless_told(monkeypatch, tmp_path):
    """The camera table leaves out no_anchor and no_sliding; --policies still names any."""
    planned = []

    def record(plan, out, jobs, backend):
        planned.append(plan.policies)
        raise ValueError("planned")

    monkeypatch.setattr(runner, "run", record)
    for obs, more in (("state", []), ("pixels", []), ("pixels", ["--policies", "mem0:no_anchor"])):
        cli(["table", "--obs", obs, "--tasks", "press_button", "--out", str(tmp_path), *more])
    state, pixels, named = planned
    assert state == ALL_POLICIES and pixels == COLUMNS["pixels"] == (
        "mem0", "mem0:no_memory", "dp", "act", "mem0:no_key", "mem0:gt_classifier",
        "mem0:no_memory+no_key")
    assert named == ("mem0:no_anchor",)


def test_learning_benchmark_is_the_table_for_one_task(toy_table, tmp_path):
    """benchmarks/learning.py with the toy table's settings finds its cells done and writes its
    results file from them."""
    out, _ = toy_table
    learning = load_script("benchmarks/learning.py")
    results = tmp_path / "r.json"
    assert learning.main(["--task", "observe_and_pickup", "--obs", "state", "--policies", "mem0,dp",
                          "--demos", "2", "--steps", "6", "--batch", "4", "--episodes", "1",
                          "--out", str(out), "--results", str(results)]) == 0
    res = json.loads(results.read_text())
    table = json.loads((out / "table.json").read_text())["cells"]["observe_and_pickup"]
    for spec_ in ("mem0", "dp"):
        assert res["policies"][spec_]["success_rate"] == table[spec_]["success_rate"]
        k = res["policies"][spec_]["successes"]  # of 1 episode: Wilson's interval
        assert res["policies"][spec_]["success_ci95"] == ([0.2065, 1.0] if k else [0.0, 0.7935])
    assert res["dataset"]["episodes"] == 2 and res["noise"] is None
    with pytest.raises(SystemExit, match="unknown policy"):
        learning.main(["--task", "observe_and_pickup", "--obs", "state", "--policies", "pi0"])


def test_tables_mark_missing_and_absent_cells(tmp_path):
    plan = Plan("state", ("put_back_block", "press_button"), ("mem0", "mem0:no_key"))
    res = tables.results(plan, tmp_path)
    assert res["cells"] == {"put_back_block": {"mem0": None},
                            "press_button": {"mem0": None, "mem0:no_key": None}}
    text = tables.markdown(res)
    assert "| put_back_block | M(1) | — | n/a |" in text
    assert "| **average M(n)** | M(n) | — | — |" in text
    assert "| **average (all)** |  | — | n/a |" in text  # no_key has no M(1) cell to average
    assert "| swap_T |" not in text  # only the plan's tasks
    assert stages.fraction(plan, tmp_path, "train", "put_back_block", "mem0") == 0.0


def test_progress_in_a_log_shows_a_training_between_its_start_and_end(tmp_path):
    """Off a terminal the grid is printed at each event and, between events, when it changed
    at most every every_s: before, a log showed "train 0%" for the hour a training ran."""
    plan = Plan("state", ("put_back_block",), ("mem0",), steps=100)
    curve = plan.train_dir(tmp_path, "put_back_block", "mem0") / stages.CURVE_CSV
    curve.parent.mkdir(parents=True)
    running = {schedule.Job("train", "put_back_block", "mem0")}
    log = io.StringIO()
    progress = Progress(plan, tmp_path, stream=log, every_s=0.0)
    progress.show(running, {}, "started train put_back_block mem0")
    assert "started train" in log.getvalue() and "train 0%" in log.getvalue()
    progress.show(running, {})  # nothing changed: nothing printed
    assert log.getvalue().count("rmbench table") == 1
    curve.write_text("step,loss\n40,0.5\n")
    progress.show(running, {})
    assert log.getvalue().count("rmbench table") == 2 and "train 40%" in log.getvalue()
    quiet = io.StringIO()
    progress = Progress(plan, tmp_path, stream=quiet, every_s=3600.0)
    progress.show(running, {}, "started")
    curve.write_text("step,loss\n80,0.5\n")
    progress.show(running, {})  # changed, but within every_s of the last print
    assert quiet.getvalue().count("rmbench table") == 1


def test_a_running_job_shows_the_time_it_has_left_at_its_pace(tmp_path, monkeypatch):
    plan = Plan("state", ("put_back_block",), ("mem0",), steps=100)
    curve = plan.train_dir(tmp_path, "put_back_block", "mem0") / stages.CURVE_CSV
    curve.parent.mkdir(parents=True)
    curve.write_text("step,loss\n20,0.5\n")
    job = schedule.Job("train", "put_back_block", "mem0")
    clock_s = [1000.0]
    monkeypatch.setattr(runner.time, "monotonic", lambda: clock_s[0])
    progress = Progress(plan, tmp_path, stream=io.StringIO(), pace_after_s=60,
                        pace_window_s=1200)
    assert progress.running_lines({job}) == ["  train put_back_block mem0: train 20%"]
    clock_s[0] += 30
    curve.write_text("step,loss\n30,0.5\n")  # moved, but not for long enough to tell a pace
    assert progress.running_lines({job}) == ["  train put_back_block mem0: train 30%"]
    clock_s[0] += 1170  # 40% of the steps in 20 minutes: 40% more take 20
    curve.write_text("step,loss\n60,0.5\n")
    assert progress.running_lines({job}) == [
        "  train put_back_block mem0: train 60%, about 0:20 left at its pace"]
    clock_s[0] += 3000  # paused: 1% in 50 minutes
    curve.write_text("step,loss\n61,0.5\n")
    assert progress.running_lines({job})[0].endswith("about 32:29 left at its pace")
    for step in (71, 80):  # moving again: the pause leaves the 20-minute window
        clock_s[0] += 600
        curve.write_text(f"step,loss\n{step},0.5\n")
        line = progress.running_lines({job})[0]
    assert line.endswith("train 80%, about 0:21 left at its pace")  # 19% in 20 minutes
    progress.forget(job)  # restarted on more cores: its pace is measured again
    assert progress.running_lines({job}) == ["  train put_back_block mem0: train 80%"]
    assert progress.running_lines(set()) == [] and not progress.paces


def test_a_camera_tables_data_shows_the_part_under_way(tmp_path):
    """A camera table's data job spends most of its hours after the demonstrations: rendering
    their copies, then caching features. The grid names the part and its progress instead of
    "data 100%" for all of them."""
    from rmbench.policies.feature_cache import default_dir

    plan = Plan("pixels", ("put_back_block",), ("mem0", "mem0:no_memory"), demos=4,
                rendered_copies=2, sets=('backbone="efficientnet_lite0"',))
    running = {schedule.Job("collect", "put_back_block")}
    show = lambda: Progress(plan, tmp_path).cell("put_back_block", "mem0", running, {})  # noqa: E731
    data, copies = plan.data_dir(tmp_path, "put_back_block"), plan.train_data_dir(tmp_path, "put_back_block")

    def episodes(root, n):
        (root / "meta").mkdir(parents=True, exist_ok=True)
        (root / "meta" / "info.json").write_text(json.dumps({"total_episodes": n}))

    assert show() == "demos 0%"
    episodes(data, 3)
    assert show() == "demos 75%"
    episodes(data, 4)
    episodes(copies, 6)  # of 4 x (1 + 2)
    assert show() == "copies 50%"
    episodes(copies, 12)
    plan.copies_record(tmp_path, "put_back_block").write_text(
        json.dumps({"source_episodes": 4}))
    cfg = plan.config("put_back_block", "mem0")
    folder = default_dir(copies, cfg.backbone, cfg.backbone_stride, tuple(cfg.image_size))
    assert show() == "features 0%"
    for cam in cfg.cameras:
        (folder / cam).mkdir(parents=True)
        for e in range(6):
            (folder / cam / f"episode-{e:06d}-10-20.npy").write_bytes(b"")
    (folder / cfg.cameras[0] / "episode-000000-11-21.npy").write_bytes(b"")  # (an older one)
    assert show() == "features 50%"
    assert stages.fraction(plan, tmp_path, "collect", "put_back_block") == 0.5


def test_a_job_spends_its_share_of_the_cores(tmp_path, monkeypatch):
    """A job given two threads collects and evaluates with two worker processes."""
    from rmbench.suite.job import run_job, source_digest

    seen = {}
    monkeypatch.setattr(data_stage, "collect_stage", lambda *a, **kw: seen.update(collect=kw))
    monkeypatch.setattr(stages, "eval_stage", lambda *a, **kw: seen.update(eval=kw))
    plan = Plan("state", ("observe_and_pickup",), ("mem0",)).to_dict()
    import torch

    threads = torch.get_num_threads()  # run_job sets this process's: put it back
    try:
        for kind in ("collect", "eval"):
            run_job(plan, str(tmp_path), kind, "observe_and_pickup", "mem0", 2, source_digest())
    finally:
        torch.set_num_threads(threads)
    assert seen == {"collect": {"workers": 2}, "eval": {"workers": 2}}


def test_the_collect_job_solves_the_layout_copies_the_trainings_read(dataset, tmp_path):
    import shutil

    from tests.conftest import DATA_TASK as TASK

    plan = Plan("state", (TASK,), ("mem0", "dp"), demos=3, steps=2, batch=2, episodes=1,
                sets=("layout_copies=2", "layout_shift=0.02"))
    assert data_stage.layout_copy_sets(plan, TASK) == [(2, 0.02)]  # one set for both policies
    shutil.copytree(dataset, plan.data_dir(tmp_path, TASK), ignore=shutil.ignore_patterns(".cache"))
    assert data_stage.demos_collected(plan, tmp_path, TASK) and not data_stage.collected(plan, tmp_path, TASK)
    assert schedule.Job("collect", TASK) in schedule.plan_jobs(plan, tmp_path)
    summary = data_stage.collect_stage(plan, tmp_path, TASK)
    assert summary["layout_copies_wall_s"] > 0
    assert data_stage.collected(plan, tmp_path, TASK)
    assert schedule.Job("collect", TASK) not in schedule.plan_jobs(plan, tmp_path)
    # solved once: a second collect job finds them and adds no time
    assert data_stage.collect_stage(plan, tmp_path, TASK)["layout_copies_wall_s"] == summary[
        "layout_copies_wall_s"]


def test_rendered_copies_are_the_training_data_with_their_features_encoded_once(
        tmp_path, monkeypatch):
    """--rendered-copies: the collect job renders the copies and encodes the frozen backbone's
    features (one cache for Mem-0 and DP); training reads them; the folders say so."""
    from dataclasses import replace

    from tests.conftest import DATA_TASK as TASK

    cams = ("head", "left_wrist", "right_wrist")
    monkeypatch.setitem(data_stage.COLLECT_CAMERAS, "pixels", (cams, (64, 48)))
    plan = Plan("pixels", (TASK,), ("mem0", "dp"), demos=1, steps=2, batch=2, episodes=1,
                sets=("backbone=efficientnet_lite0", "backbone_stride=16"),
                rendered_copies=1, rendered_reach=0.02)
    plain = replace(plan, rendered_copies=0)
    assert plan.train_data_dir(tmp_path, TASK).name == "data-copies1-r0.02"
    assert plain.train_data_dir(tmp_path, TASK) == plan.data_dir(tmp_path, TASK)
    assert plan.train_dir(tmp_path, TASK, "mem0") != plain.train_dir(tmp_path, TASK, "mem0")
    assert plan.eval_dir(tmp_path, TASK, "mem0") != plain.eval_dir(tmp_path, TASK, "mem0")
    assert schedule.Job("collect", TASK) in schedule.plan_jobs(plan, tmp_path)

    summary = data_stage.collect_stage(plan, tmp_path, TASK)
    assert summary["episodes"] == 1 and summary["rendered_copies"]["episodes"] == 2
    (cache, wanted), = data_stage.feature_caches(plan, tmp_path, TASK)
    assert wanted == ([0, 1], sorted(cams)) and cache.missing(*wanted) == []
    assert data_stage.collected(plan, tmp_path, TASK)
    assert schedule.Job("collect", TASK) not in schedule.plan_jobs(plan, tmp_path)
    encoded = {p: p.stat().st_mtime_ns for p in cache.dir.rglob("*.npy")}
    assert len(encoded) == 6
    ckpt = stages.train_stage(plan, tmp_path, TASK, "mem0")
    assert {p: p.stat().st_mtime_ns for p in cache.dir.rglob("*.npy")} == encoded
    assert json.loads((ckpt / "config.json").read_text())["step"] == 2
    # a killed rendering (no summary written) is finished by the next collect job
    plan.copies_record(tmp_path, TASK).unlink()
    assert not data_stage.collected(plan, tmp_path, TASK)
    assert data_stage.collect_stage(plan, tmp_path, TASK)["rendered_copies"]["episodes"] == 2

    for bad in ({"rendered_copies": -1}, {"rendered_copies": 1, "rendered_reach": float("nan")}):
        with pytest.raises(ValueError, match="rendered copies"):
            replace(plan, **bad)


def test_a_terminated_table_stops_its_jobs(toy_table, tmp_path):
    """SIGTERM to the runner mid-training: it exits, and so does the training job (a re-run
    then resumes from what the job saved, the training loop's own tests cover that)."""
    import os
    import shutil
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "table"
    shutil.copytree(toy_table[0] / "observe_and_pickup" / "data", out / "observe_and_pickup" / "data")
    proc = subprocess.Popen([sys.executable, "-m", "rmbench.cli.main", "table", "--obs", "state",
                             "--tasks", "observe_and_pickup", "--policies", "dp", "--demos", "2",
                             "--steps", "100000", "--batch", "4", "--episodes", "1", "--out",
                             str(out), "--no-recipe"], stderr=subprocess.DEVNULL, stdout=subprocess.DEVNULL)

    def jobs(kind=b""):
        found = []
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                cmd = open(f"/proc/{pid}/cmdline", "rb").read().split(b"\0")
            except OSError:
                continue
            if b"rmbench.suite.job" in cmd and str(out).encode() in cmd and (not kind or kind in cmd):
                found.append(pid)
        return found

    try:
        deadline = time.monotonic() + 120
        while not jobs(b"train"):
            assert time.monotonic() < deadline and proc.poll() is None, "training never started"
            time.sleep(0.5)
        time.sleep(3)  # into its steps
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 130
        deadline = time.monotonic() + 15
        while jobs():
            assert time.monotonic() < deadline, "a job outlived its runner"
            time.sleep(0.5)
    finally:  # a failed assertion leaves nothing running
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=30)
        for pid in jobs():
            os.kill(int(pid), signal.SIGKILL)


def test_a_stage_resumed_on_another_machine_lists_both(tmp_path, monkeypatch):
    clock.add_time(tmp_path, "eval_wall_s", 60.0)
    clock.add_time(tmp_path, "eval_wall_s", 30.0)  # resumed on the same machine: listed once
    here = describe()
    other = {**here, "cores": here["cores"] + 14}  # unlike this one, whatever this one is
    monkeypatch.setattr(clock, "describe", lambda: other)
    clock.add_time(tmp_path, "eval_wall_s", 10.0)
    timing = read_json_or(tmp_path / clock.TIMING, {})
    assert timing == {"eval_wall_s": 100.0, "machines": [here, other]}


def test_a_machine_with_a_gpu_is_named_with_it():
    machine = {**describe(), "gpu": "NVIDIA H100 80GB HBM3"}
    assert short(machine) == f"{short(describe())}, NVIDIA H100 80GB HBM3"



def test_tables_give_each_rate_its_interval_and_mem0_its_differences():
    from dataclasses import asdict

    from rmbench.eval.chance import chance

    plan = Plan("state", ("put_back_block",), ("mem0", "mem0:no_anchor", "mem0:no_sliding",
                                               "mem0:no_memory"))
    cell = lambda k: {"success_rate": k / 100, "mean_progress": 0.5, "episodes": 100}  # noqa: E731
    cells = {"put_back_block": {"mem0": cell(85), "mem0:no_anchor": cell(80),
                                "mem0:no_sliding": cell(7), "mem0:no_memory": None}}
    diffs = tables.differences(cells)["put_back_block"]
    assert set(diffs) == {"mem0:no_anchor", "mem0:no_sliding"}  # no cell, no difference
    assert diffs["mem0:no_sliding"]["difference"] == 0.78 and diffs["mem0:no_sliding"]["outside_noise"]
    # 85 against 80 of 100 each: inside the noise
    assert not diffs["mem0:no_anchor"]["outside_noise"] and diffs["mem0:no_anchor"]["ci95"][0] < 0
    res = {"plan": plan.to_dict(), "cells": cells, "differences": tables.differences(cells),
           "chance": {"put_back_block": asdict(chance("put_back_block"))}, "failed": {},
           "wall_s": {"table": None, "data": {}}, "machine": describe()}
    text = tables.markdown(res)
    assert "| put_back_block | M(1) | 85.0 [77, 91] | 80.0 [71, 87] | 7.0 [3, 14] | — |" in text
    # the paper's ablations table beside them, task by task (eval/published.json)
    assert ("| Mem-0 (published) | w/o Anchor (published) | w/o Sliding (published) | chance"
            in text and "| — | 90.0 [83, 94] | 35.0 [26, 45] | 78.0 [69, 85] | 25.0 |" in text)
    assert "Published: arXiv 2603.01229, ablations table." in text
    assert "| put_back_block | M(1) | +5 [-6, +16] | +78 [+67, +85]* | — |" in text
    # the option off: the tables as they were
    plain = tables._markdown_table(res, ["mem0"])
    assert "| put_back_block | M(1) | 85.0 | 25.0 |" in plain


def test_training_seeds_are_columns_of_their_own_folders_pooled_into_one_cell(capsys):
    from rmbench.suite.plan import split_seed, with_seed

    assert split_seed("mem0:no_key@1") == ("mem0:no_key", 1) and split_seed("dp") == ("dp", 0)
    assert with_seed("mem0", 0) == "mem0" and with_seed("mem0", 2) == "mem0@2"
    with pytest.raises(ValueError, match="whole number"):
        parse_policy("mem0@x")
    plan = Plan("state", ("press_button",), ("mem0", "mem0@1", "mem0:gt_classifier@1", "dp@0"))
    assert plan.policies == ("mem0", "mem0@1", "mem0:gt_classifier@1", "dp")  # @0 is plain
    out, task = Path("/t"), "press_button"
    # seed 0 keeps the folders a one-seed table has; another seed trains its own checkpoint,
    # which its inference ablation evaluates
    assert plan.train_dir(out, task, "mem0") == Plan("state", (task,)).train_dir(out, task, "mem0")
    assert plan.train_dir(out, task, "mem0@1") != plan.train_dir(out, task, "mem0")
    assert trained_spec("mem0:gt_classifier@1") == "mem0@1"
    assert plan.train_dir(out, task, "mem0:gt_classifier@1") == plan.train_dir(out, task, "mem0@1")
    assert column("mem0:no_key@1") == "no_key@1"
    J = schedule.Job
    needs = schedule.plan_jobs(plan, Path("/nonexistent"))
    assert needs[J("eval", task, "mem0:gt_classifier@1")] == (J("train", task, "mem0@1"),)
    # one cell per column: the seeds' episodes pooled, each seed's row kept
    row = lambda k, p: {"success_rate": k / 100, "successes": k, "episodes": 100,  # noqa: E731
                        "mean_progress": p, "endings": {"success": k, "timeout": 100 - k},
                        "failure_reasons": {"timeout": 100 - k}, "train_wall_s": 10.0,
                        "eval_wall_s": 1.0, "machines": {"train": [], "eval": []},
                        "memory": "m"}
    pooled = cell_rows.pooled_row({0: row(30, 0.5), 1: row(20, 0.3)})
    assert pooled["success_rate"] == 0.25 and pooled["episodes"] == 200
    assert pooled["mean_progress"] == 0.4 and pooled["endings"] == {"success": 50, "timeout": 150}
    assert pooled["success_ci95"] == pytest.approx(wilson(50, 200), abs=1e-4)  # pooled counts
    assert set(pooled["seeds"]) == {"0", "1"} and pooled["train_wall_s"] == 20.0
    assert cell_rows.pooled_row({0: row(30, 0.5), 1: None}) is None  # not until every seed is in
    assert cell_rows.pooled_row({0: row(30, 0.5)}) == row(30, 0.5)
    assert cli(["table", "--obs", "state", "--tasks", "press_button", "--train-seeds", "-1",
                "--report-only", "--out", "/nonexistent"]) != 0
    assert "--train-seeds takes whole numbers" in capsys.readouterr().err


def test_folders_of_another_task_version_are_moved_aside(tmp_path):
    """A table re-run after a task's version changed makes that task's cells again: its data
    (with the data's clock), checkpoints and evaluations of the old version move aside, named
    by it, and what is of the current version stays."""
    import json

    from rmbench.tasks import get_task

    task, old = "swap_blocks", "rmbench/SwapBlocks-v0"
    plan = Plan("state", (task,), ("mem0", "dp"), steps=10, batch=2, episodes=2)
    data = plan.data_dir(tmp_path, task)
    (data / "meta").mkdir(parents=True)
    (data / "meta" / "rmbench.json").write_text(json.dumps({"gym_id": old}))
    (data.parent / "timing.json").write_text("{}")
    stale, fresh = plan.train_dir(tmp_path, task, "mem0"), plan.train_dir(tmp_path, task, "dp")
    for folder, version in ((stale, old), (fresh, get_task(task).gym_id)):
        folder.mkdir(parents=True)
        (folder / "config.json").write_text(json.dumps({"gym_id": version}))
    evals = plan.eval_dir(tmp_path, task, "mem0") / task
    evals.mkdir(parents=True)
    (evals / "version.json").write_text(json.dumps({"gym_id": old}))
    summary = {"tasks": {task: {"episodes": 2, "success_rate": 0.5}}}
    (evals.parent / "summary.json").write_text(json.dumps(summary))
    # a report (which moves nothing) does not take the old version's cell for this one's
    assert stages.evaluated(plan, tmp_path, task, "mem0") is None
    (evals / "version.json").write_text(json.dumps({"gym_id": get_task(task).gym_id}))
    assert stages.evaluated(plan, tmp_path, task, "mem0") == summary["tasks"][task]
    (evals / "version.json").write_text(json.dumps({"gym_id": old}))
    moved = versions.retire_other_versions(plan, tmp_path, task)
    assert {a.name for a, _ in moved} == {"data", "timing.json", stale.name, evals.parent.name}
    assert all(b.name == f"{a.name}~SwapBlocks-v0" and b.exists() and not a.exists()
               for a, b in moved)
    assert (fresh / "config.json").exists()  # the current version's stays
    assert versions.retire_other_versions(plan, tmp_path, task) == []  # nothing left to move


def test_a_table_refuses_another_tables_demonstrations(toy_table, tmp_path, capsys):
    """A table's folders are named by its training recipe: asking other data of the same OUT
    (fewer demonstrations, another noise) is refused before anything runs or is reported."""
    import shutil

    out = tmp_path / "table"
    shutil.copytree(toy_table[0] / "observe_and_pickup" / "data", out / "observe_and_pickup" / "data")
    base = ["table", "--obs", "state", "--tasks", "observe_and_pickup", "--policies", "dp",
            "--steps", "6", "--batch", "4", "--episodes", "1", "--out", str(out), "--no-recipe"]
    for more, what in ((["--demos", "1"], "2 demonstrations there, 1 asked"),
                       (["--demos", "2", "--noise", "0.02"], "action_noise None there"),
                       (["--demos", "2", "--noise", "0.02", "--report-only"], "action_noise")):
        assert cli(base + more) == 2
        err = capsys.readouterr().err
        assert "holds demonstrations of another table" in err and what in err, err
        assert len(err.strip().splitlines()) == 1
    assert not (out / "observe_and_pickup" / "train").exists()
    assert not (out / "table.json").exists()
    # more demonstrations than cells already trained on the folder's: refused too, since
    # those cells' folders would name the larger table's
    shutil.copytree(toy_table[0] / "observe_and_pickup" / "train", out / "observe_and_pickup" / "train")
    assert cli(base + ["--demos", "3"]) == 2
    err = capsys.readouterr().err
    assert "2 demonstrations there and cells trained on them, 3 asked" in err, err
    assert Dataset(out / "observe_and_pickup" / "data").num_episodes == 2


def test_one_table_at_a_time_runs_a_task_in_an_out(tmp_path):
    plan = Plan("state", ("put_back_block", "swap_T"), ("dp",))
    with runner._holding(tmp_path / "swap_T" / runner.LOCK):  # another table's, on swap_T
        with pytest.raises(RuntimeError, match=r"swap_T is in use by another rmbench table "
                                               r"\(process \d+\)"):
            runner.run(plan, tmp_path)
        assert not (tmp_path / "put_back_block" / "data").exists()
        assert (tmp_path / "put_back_block" / runner.LOCK).exists()  # taken, then let go:
        with runner._holding(tmp_path / "put_back_block" / runner.LOCK):  # another task is free
            pass


def test_a_failed_job_reports_the_last_line_of_its_own_run(tmp_path, monkeypatch):
    """A job's log keeps its earlier runs; a run that dies without a word is not reported
    with an earlier run's last line."""
    import subprocess
    import sys
    import time

    log = tmp_path / "job.log"
    log.write_text("RuntimeError: the error of an earlier run\n")
    popen = subprocess.Popen
    monkeypatch.setattr(backends.subprocess, "Popen", lambda cmd, **kw: popen(
        [sys.executable, "-c", "raise SystemExit(9)"], **kw))
    pool = backends.LocalJobs(1)
    job = schedule.Job("collect", "put_back_block")
    pool.start(Plan("state", ("put_back_block",), ("dp",)), tmp_path, job, log)
    deadline = time.monotonic() + 30
    while not (ended := pool.finished()):
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert ended == [(job, "exit 9: no output")]


def test_a_damaged_clock_is_an_error_not_a_fresh_start(tmp_path):
    from rmbench.files import FileFormatError

    clock.add_time(tmp_path, "collect_wall_s", 5.0)
    (tmp_path / clock.TIMING).write_text('{"collect_wall_s": 5.0, "mach')
    with pytest.raises(FileFormatError, match="timing.json"):
        clock.add_time(tmp_path, "collect_wall_s", 1.0)
    assert (tmp_path / clock.TIMING).read_text() == '{"collect_wall_s": 5.0, "mach'


def test_a_dataset_of_another_task_version_is_moved_aside_not_refused(toy_table, tmp_path):
    """check_data reads only the current version's datasets: an older one is the runner's to
    move aside (and a report's to leave out), not an error."""
    import shutil

    out = tmp_path / "table"
    data = out / "observe_and_pickup" / "data"
    shutil.copytree(toy_table[0] / "observe_and_pickup" / "data", data)
    meta = data / "meta" / "rmbench.json"
    record = json.loads(meta.read_text())
    meta.write_text(json.dumps({**record, "gym_id": "rmbench/ObserveAndPickup-v0"}))
    plan = Plan("state", ("observe_and_pickup",), ("dp",), demos=1)  # asks other data, too
    data_stage.check_data(plan, out)  # not this version's: not read
    moved = versions.retire_other_versions(plan, out, "observe_and_pickup")
    assert [a for a, _ in moved] == [data]


def test_a_table_under_nohup_keeps_sighup_ignored(tmp_path, monkeypatch):
    import signal

    plan = Plan("state", ("put_back_block",), ("dp",))
    monkeypatch.setattr(runner, "plan_jobs", lambda plan, out: {})
    seen = {}
    real = runner.clock.timed

    def timed(folder, key, every=60.0):
        seen["hup"] = signal.getsignal(signal.SIGHUP)
        seen["term"] = signal.getsignal(signal.SIGTERM)
        return real(folder, key, every)

    monkeypatch.setattr(runner.clock, "timed", timed)
    before = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        assert runner.run(plan, tmp_path) == {}
        assert seen == {"hup": signal.SIG_IGN, "term": runner._interrupt}
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN  # as it was
    finally:
        signal.signal(signal.SIGHUP, before)


class _Pool:
    """Jobs that end after a set number of polls, and what was started, stopped and ended."""

    grows = True

    def __init__(self, polls, events):
        self.polls, self.events = polls, events
        self.running, self.slots, self.left = {}, {}, {}

    def held(self):
        return sum(self.slots[j] for j in self.running)

    def start(self, plan, out, job, log, slots=1):
        self.running[job], self.slots[job], self.left[job] = None, slots, self.polls[job]
        self.events.append(("start", job.name, slots))

    def restart(self, plan, out, job, slots, logs):
        del self.running[job]
        self.events.append(("stop", job.name, self.slots[job]))
        self.start(plan, out, job, logs / job.log_name, slots)
        return True

    def finished(self):
        for job in list(self.running):
            self.left[job] -= 1
        ended = [j for j in self.running if self.left[j] <= 0]
        for job in ended:
            del self.running[job]
            self.events.append(("end", job.name, self.slots[job]))
        return [(job, None) for job in ended]

    def stop(self):
        self.running.clear()


def _scheduled(tmp_path, monkeypatch, needs, polls, jobs):
    events = []
    monkeypatch.setattr(runner, "plan_jobs", lambda plan, out: dict(needs))
    monkeypatch.setattr(runner, "LocalJobs", lambda threads: _Pool(polls, events))
    plan = Plan("state", tuple(dict.fromkeys(j.task for j in needs)), ("dp",))
    assert runner.run(plan, tmp_path, jobs=jobs, poll_s=0,
                      progress=Progress(plan, tmp_path, stream=io.StringIO())) == {}
    return events


def test_idle_slots_go_to_a_collection_or_an_evaluation_that_can_use_them(tmp_path, monkeypatch):
    """With two slots: a collection started alone takes both; a running one is restarted on
    the slot another job left when nothing else can start; a training keeps one slot (its
    float sums depend on its threads) and leaves the other idle."""
    J = schedule.Job
    a, b = J("collect", "put_back_block"), J("collect", "press_button")
    train, ev = J("train", "put_back_block", "dp"), J("eval", "put_back_block", "dp")
    needs = {a: (), b: (), train: (a,), ev: (train,)}
    polls = {a: 4, b: 1, train: 2, ev: 1}  # each job's polls until it ends, once started
    events = _scheduled(tmp_path, monkeypatch, needs, polls, jobs=2)
    assert events == [
        ("start", "collect put_back_block", 1), ("start", "collect press_button", 1),
        ("end", "collect press_button", 1),
        ("stop", "collect put_back_block", 1), ("start", "collect put_back_block", 2),
        ("end", "collect put_back_block", 2),
        ("start", "train put_back_block dp", 1),  # one slot idle: nothing may take it
        ("end", "train put_back_block dp", 1),
        ("start", "eval put_back_block dp", 2), ("end", "eval put_back_block dp", 2)]
    # the spare slots go to the first ready job that may have them, in the table's order
    assert schedule.shares([train, a, b], 4, grows=True) == [(train, 1), (a, 2), (b, 1)]
    assert schedule.shares([a, b, train], 2, grows=True) == [(a, 1), (b, 1)]
    assert schedule.shares([a], 2, grows=False) == [(a, 1)]


def test_a_collection_on_several_slots_gives_them_back_when_jobs_wait(tmp_path, monkeypatch):
    """Three slots, two collections: the first takes two. When the second ends, two
    trainings are ready and one slot is free: the first collection is restarted on one slot,
    and the second training starts on the one it gave back."""
    J = schedule.Job
    a, b = J("collect", "put_back_block"), J("collect", "press_button")
    t1, t2 = J("train", "press_button", "dp"), J("train", "press_button", "mem0")
    needs = {a: (), b: (), t1: (b,), t2: (b,)}
    events = _scheduled(tmp_path, monkeypatch, needs, {a: 5, b: 1, t1: 9, t2: 9}, jobs=3)
    assert events[:6] == [
        ("start", "collect put_back_block", 2), ("start", "collect press_button", 1),
        ("end", "collect press_button", 1), ("start", "train press_button dp", 1),
        ("stop", "collect put_back_block", 2), ("start", "collect put_back_block", 1)]
    assert events[6] == ("start", "train press_button mem0", 1)


def test_a_job_restarted_on_more_slots_stops_and_gets_their_threads(tmp_path, monkeypatch):
    import subprocess
    import sys

    popen, started = subprocess.Popen, []

    def fake(cmd, **kw):
        started.append((cmd[cmd.index("--threads") + 1], kw["env"]["OMP_NUM_THREADS"]))
        return popen([sys.executable, "-c", "import time; time.sleep(60)"], **kw)

    monkeypatch.setattr(backends.subprocess, "Popen", fake)
    pool = backends.LocalJobs(3)
    job = schedule.Job("collect", "put_back_block")
    plan = Plan("state", ("put_back_block",), ("dp",))
    pool.start(plan, tmp_path, job, tmp_path / job.log_name)
    first = pool.running[job][0]
    assert pool.restart(plan, tmp_path, job, 2, tmp_path)
    try:
        assert first.poll() is not None  # stopped before its successor started
        assert started == [("3", "3"), ("6", "6")] and pool.held() == 2
    finally:
        pool.stop()
    assert pool.held() == 0
    # a job that has ended is not started again: the next finished() reports it
    monkeypatch.setattr(backends.subprocess, "Popen", lambda cmd, **kw: popen(
        [sys.executable, "-c", "raise SystemExit(3)"], **kw))
    pool.start(plan, tmp_path, job, tmp_path / job.log_name)
    pool.running[job][0].wait()
    assert not pool.restart(plan, tmp_path, job, 2, tmp_path)
    assert [(j, e.split(":")[0]) for j, e in pool.finished()] == [(job, "exit 3")]
