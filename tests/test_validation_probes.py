"""benchmarks/validation_probes.py: a validation evaluation becomes one row of the probes'
results; test episodes and unfinished runs are refused in one line."""

import json
from pathlib import Path

import pytest

from tests.conftest import load_script


@pytest.fixture
def probes():
    return load_script("benchmarks/validation_probes.py")


def _eval(folder: Path, split="validation", done=100, successes=79, obs="state") -> Path:
    folder.mkdir(parents=True)
    # one checkpoint per observation, shared by the evaluations: what it reads says which
    # table the probe is for
    ckpt = folder.parent / f"ckpt-{obs}"
    ckpt.mkdir(exist_ok=True)
    (ckpt / "config.json").write_text(json.dumps({"config": {"observation": obs}}))
    (folder / "run.json").write_text(json.dumps(
        {"policy": f"mem0:{ckpt}?sample_noise=1", "seed": 0, "episodes": 100, "split": split}))
    (folder / "summary.json").write_text(json.dumps({"tasks": {"put_back_block": {
        "episodes": done, "successes": successes, "success_rate": successes / 100,
        "success_ci95": [0.7, 0.86], "endings": {"success": successes}}}}))
    return folder


def test_a_probe_is_recorded_once_per_task_policy_and_change(probes, tmp_path):
    out = tmp_path / "probes.json"
    a = _eval(tmp_path / "a")
    b = _eval(tmp_path / "b", successes=66)
    assert probes.main(["--probe", f"noise 1={a}", "--out", str(out)]) == 0
    assert probes.main(["--probe", f"noise 1={b}", "--out", str(out)]) == 0  # replaces it
    (row,) = json.loads(out.read_text())["probes"]
    assert (row["task"], row["change"], row["successes"]) == ("put_back_block", "noise 1", 66)
    assert "--split validation" in row["command"]


def test_test_episodes_and_unfinished_runs_are_refused(probes, tmp_path):
    with pytest.raises(SystemExit, match="test episodes, not the validation ones"):
        probes.probe_row("x", _eval(tmp_path / "t", split="test"))
    with pytest.raises(SystemExit, match="60 of 100 episodes so far"):
        probes.probe_row("x", _eval(tmp_path / "u", done=60))
    with pytest.raises(SystemExit, match="give CHANGE=FOLDER"):
        probes.main(["--probe", str(tmp_path / "t"), "--out", str(tmp_path / "o.json")])


def test_a_change_may_hold_an_equals_sign_and_a_training_command(probes, tmp_path):
    out = tmp_path / "probes.json"
    a = _eval(tmp_path / "a", successes=72)
    assert probes.main(["--probe", f"mem0.sliding_window=16={a}", "--out", str(out),
                        "--trained-by", "rmbench table --set mem0.sliding_window=16"]) == 0
    (row,) = json.loads(out.read_text())["probes"]
    assert (row["change"], row["successes"]) == ("mem0.sliding_window=16", 72)
    assert row["trained_by"] == "rmbench table --set mem0.sliding_window=16"


def test_a_probe_keeps_the_stage_its_failures_ended_in(probes, tmp_path):
    folder = _eval(tmp_path / "a", successes=99)
    (folder / "put_back_block").mkdir()
    events = [[0, "task", "subtask", "move the block to the centre"],
              [90, "task", "subtask", "put the block back on its original mat"]]
    (folder / "put_back_block" / "episodes.jsonl").write_text("\n".join(json.dumps(r) for r in (
        {"seed": 1, "success": True, "events": events[:1], "reason": "success", "message": "",
         "progress": 1.0},
        {"seed": 2, "success": False, "events": events, "reason": "task_failure",
         "message": "button pressed more than once", "progress": 0.5})) + "\n")
    row = probes.probe_row("x", folder)
    assert row["failed_at"] == {"put the block back on its original mat":
                                {"button pressed more than once": 1}}
    assert probes.probe_row("x", _eval(tmp_path / "b"))["failed_at"] is None  # no records kept


def test_a_probe_keeps_the_planner_s_choices_where_the_policy_reports_its_subtask(probes, tmp_path):
    """The choice at an end declared on time is judged against the plan's next subtask
    (eval/decisions.py); records without a policy subtask keep none."""
    folder = _eval(tmp_path / "a", successes=0)
    (folder / "put_back_block").mkdir()
    events = [[0, "task", "subtask", "move"], [0, "task", "subtask_step", 0],
              [0, "policy", "subtask", "move"], [0, "policy", "subtask_ends", 0],
              [90, "task", "subtask", "put back"], [90, "task", "subtask_step", 1],
              [95, "policy", "subtask", "press"], [95, "policy", "subtask_ends", 1]]
    (folder / "put_back_block" / "episodes.jsonl").write_text(json.dumps(
        {"seed": 1, "success": False, "events": events, "reason": "timeout", "message": "",
         "progress": 0.5, "steps": 500}) + "\n")
    assert probes.probe_row("x", folder)["decisions"] == {
        "judged": 1, "right": 0,
        "by_next": {"put back": {"right": 0, "of": 1, "chose_instead": {"press": 1}}}}
    assert probes.probe_row("x", _eval(tmp_path / "b"))["decisions"] is None


def test_a_probe_says_which_table_its_checkpoint_reads_for(probes, tmp_path):
    assert probes.probe_row("x", _eval(tmp_path / "s"))["obs"] == "state"
    assert probes.probe_row("x", _eval(tmp_path / "p", obs="pixels"))["obs"] == "pixels"
    # a config from before the field existed is a camera checkpoint's, as the policies read it
    old = _eval(tmp_path / "old")
    (tmp_path / "ckpt-state" / "config.json").write_text(json.dumps({"config": {}}))
    assert probes.probe_row("x", old)["obs"] == "pixels"
    folder = _eval(tmp_path / "gone")
    (tmp_path / "ckpt-state" / "config.json").unlink()
    with pytest.raises(SystemExit, match="not a trained checkpoint whose config can be read"):
        probes.probe_row("x", folder)


def test_a_probe_names_a_checkpoint_of_the_same_weights_and_no_other(probes, tmp_path):
    out = tmp_path / "probes.json"
    a = _eval(tmp_path / "a")
    (tmp_path / "ckpt-state" / "model.safetensors").write_bytes(b"weights")
    twin = tmp_path / "table" / "mem0-s100"
    twin.mkdir(parents=True)
    (twin / "model.safetensors").write_bytes(b"weights")
    assert probes.main(["--probe", f"x={a}", "--same-weights-as", str(twin),
                        "--out", str(out)]) == 0
    (row,) = json.loads(out.read_text())["probes"]
    assert row["policy"] == f"mem0:{twin}?sample_noise=1"
    assert row["evaluated_as"] == f"mem0:{tmp_path / 'ckpt-state'}?sample_noise=1"
    assert str(tmp_path / "ckpt-state") in row["command"]  # the command as it ran
    (twin / "model.safetensors").write_bytes(b"other weights")
    with pytest.raises(SystemExit, match="its weights are not those of"):
        probes.main(["--probe", f"x={a}", "--same-weights-as", str(twin), "--out", str(out)])
    with pytest.raises(SystemExit, match="one --probe"):
        probes.main(["--probe", f"x={a}", "--probe", f"y={a}", "--same-weights-as", str(twin),
                     "--out", str(out)])
