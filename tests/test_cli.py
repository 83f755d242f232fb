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


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    return err.splitlines()[-1]


def test_bad_input_is_refused_before_anything_is_written(tmp_path, capsys):
    """Each refusal is one line, before a folder is made or a user's files are touched."""
    import importlib.util

    out = tmp_path / "t"
    assert main(["table", "--obs", "state", "--tasks", "put_back_block", "--policies", "dp",
                 "--video", "first", "--out", str(out)]) == 2  # read hours in, checked now
    assert "video must be first:K, failures or none" in _one_line(capsys)
    assert main(["table", "--obs", "state", "--tasks", "put_back_block", "--policies", "dp",
                 "--train-seeds", "abc", "--out", str(out)]) == 2
    assert "--train-seeds takes whole numbers" in _one_line(capsys)
    out.mkdir()
    assert main(["table", "--obs", "state", "--tasks", "put_back_block", "--policies", "dp",
                 "--report-only", "--out", str(out)]) == 2
    assert "no table at" in _one_line(capsys) and not list(out.iterdir())
    import pytest

    with pytest.raises(SystemExit) as stop:  # (argparse's own refusal)
        main(["serve", "--policy", "random", "--task", "put_back_block", "--port", "99999"])
    assert stop.value.code == 2 and "99999 is above 65535" in _one_line(capsys)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "summary.json").write_text("{}")  # a user's file, not an evaluation's
    assert main(["eval", "--task", "put_back_block", "--policy", "noop", "--episodes", "1",
                 "--out", str(mine)]) == 2
    assert "holds a summary but no run.json" in _one_line(capsys)
    assert sorted(p.name for p in mine.iterdir()) == ["summary.json"]
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "notes.txt").write_text("mine")
    assert main(["collect", "put_back_block", "--episodes", "1", "--out", str(notes)]) == 2
    assert sorted(p.name for p in notes.iterdir()) == ["notes.txt"]  # (no lock left behind)
    if importlib.util.find_spec("ray") is None:
        for cmd in (["collect", "put_back_block", "--episodes", "1"],
                    ["eval", "--task", "put_back_block", "--policy", "noop", "--episodes", "1"]):
            assert main(cmd + ["--out", str(tmp_path / "ray"), "--backend", "ray"]) == 2
            assert "needs Ray" in _one_line(capsys) and not (tmp_path / "ray").exists()


def test_open_loop_refuses_a_policy_that_reads_the_simulator(dataset, capsys):
    assert main(["open-loop", "--policy", "expert", "--dataset", str(dataset)]) == 2
    assert "reads the simulator, which open-loop does not run" in _one_line(capsys)
    assert main(["open-loop", "--policy", "random", "--dataset", str(dataset), "--json"]) == 0


def test_sizes_are_width_by_height_everywhere(tmp_path, capsys):
    """``--resolution`` and ``--frame-max`` read the same ``WxH``; a size that is not two
    positive whole numbers is argparse's one-line refusal before a folder is made."""
    import argparse

    import pytest

    from rmbench.cli.common import width_height

    assert width_height("320x240") == (320, 240) and width_height("640X480") == (640, 480)
    for bad in ("-5x3", "0x240", "320", "320x", "x240", "3.5x2", "320x240x3", "\u00b2x3"):
        with pytest.raises(argparse.ArgumentTypeError, match="expected WIDTHxHEIGHT"):
            width_height(bad)
    with pytest.raises(SystemExit):
        main(["collect", "put_back_block", "--episodes", "1", "--resolution=-320x240",
              "--out", str(tmp_path / "d")])
    assert "expected WIDTHxHEIGHT" in capsys.readouterr().err and not (tmp_path / "d").exists()


def test_serve_gives_the_server_its_frame_max_as_height_by_width(monkeypatch):
    """``--frame-max 640x360`` (WxH, as on every command) reaches the server as the frames'
    array shape (360, 640)."""
    import rmbench.serve.server as server

    seen = {}

    class Recorded:
        def __init__(self, *args, frame_max, **kwargs):
            seen["frame_max"] = frame_max

        def serve_forever(self):
            return None

    monkeypatch.setattr(server, "PolicyServer", Recorded)
    assert main(["serve", "--policy", "random", "--task", "put_back_block",
                 "--frame-max", "640x360"]) == 0
    assert tuple(seen["frame_max"]) == (360, 640)
