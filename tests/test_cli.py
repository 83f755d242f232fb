import json

from rmbench.cli.main import main


def test_tasks_json(capsys):
    assert main(["tasks", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    names = [r["name"] for r in rows]
    assert "put_back_block" in names and "press_button" in names
    assert names.index("put_back_block") < names.index("press_button")  # M(1) first


def test_unknown_task_is_a_one_line_error(capsys):
    assert main(["expert", "nope", "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "unknown task 'nope'" in err and "put_back_block" in err


def test_expert_json(capsys):
    assert main(["expert", "put_back_block", "--episodes", "1", "--seed", "100000",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["successes"] == 1 and out["episodes_detail"][0]["seed"] == 100000


def test_quickstart_writes_videos_and_summary(tmp_path, capsys):
    assert main(["quickstart", "--out", str(tmp_path), "--episodes", "1", "--json"]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["all_succeeded"]
    for row in summary["tasks"]:
        assert (tmp_path / f"{row['task']}_seed100000.mp4").stat().st_size > 1000
