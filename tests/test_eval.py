"""Evaluation harness: records, policy errors, resume after a kill, worker determinism."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rmbench.eval import EvalConfig, EvalError, evaluate
from rmbench.eval.endings import stage_at_end
from rmbench.eval.events import Events
from rmbench.eval.records import read_records
from rmbench.policies import BasePolicy, UnknownPolicyError, register_policy
from tests.conftest import DATA_TASK as TASK


class Faulty(BasePolicy):
    """Misbehaves differently per seed: raises, NaN, wrong shape; fine (no-op) otherwise."""

    def reset(self, instruction, task_info):
        self.kind = task_info["seed"] % 4

    def act(self, observation):
        if self.kind == 0:
            raise RuntimeError("boom")
        if self.kind == 1:
            return np.full(14, np.nan)
        if self.kind == 2:
            return np.zeros(7)
        return observation["agent_pos"]


register_policy("test_faulty", "raises, NaN, wrong shape, no-op by seed", cameras=())(
    lambda arg, env: Faulty())


def cfg(tmp_path, **kw) -> EvalConfig:
    args = {"episodes": 3, "seed_cache": tmp_path / "seeds", "progress": False, "video": "none",
            **kw}
    return EvalConfig((TASK,), kw.pop("policy", "expert"), tmp_path / "out",
                      **{k: v for k, v in args.items() if k != "policy"})


def records(tmp_path):
    return read_records(tmp_path / "out" / TASK / "episodes.jsonl")


def test_expert_solves_verified_seeds_and_records_everything(tmp_path):
    summary = evaluate(cfg(tmp_path, video="first:1"))
    r = summary["tasks"][TASK]
    assert r["successes"] == 3 and r["success_rate"] == 1.0 and r["mean_progress"] == 1.0
    recs = records(tmp_path)
    assert [x["seed"] for x in recs] == [100000, 100001, 100002]
    assert {"task", "seed", "success", "progress", "steps", "wall_s", "reason", "message"} <= set(recs[0])
    assert recs[0]["video"] == "videos/seed-100000.mp4" and recs[1]["video"] is None
    assert (tmp_path / "out" / TASK / recs[0]["video"]).stat().st_size > 1000
    assert r["success_ci95"] == [0.4385, 1.0]  # Wilson's 95% interval for 3 of 3
    assert "| observe_and_pickup | M(1) | 3 | 100.0% [43.9, 100.0] |" in \
        (tmp_path / "out" / "summary.md").read_text()
    # the events: each subtask's start, in order, and the task's facts where they changed
    subtasks = [(step, v) for step, source, key, v in recs[0]["events"] if key == "subtask"]
    assert subtasks[0] == (0, "watch the reference object") and subtasks[-1][1] == "done"
    assert subtasks[-1][0] == recs[0]["steps"] and [s for s, _ in subtasks] == sorted(s for s, _ in subtasks)
    assert [0, "task", "screen_up", False] in recs[0]["events"]
    cache = json.loads(next((tmp_path / "seeds").glob("*.json")).read_text())
    assert cache["verified"][:3] == [100000, 100001, 100002]


def test_events_keep_discrete_changes_only_and_count_what_the_limit_leaves_out():
    ev = Events(limit=3)
    ev.update(0, "task", {"lamp": "off", "lift": 0.0, "row": (np.int64(0), 1)})
    ev.update(1, "task", {"lamp": "off", "lift": 0.5, "row": [0, 1]})
    ev.update(2, "task", {"lamp": "red"})
    ev.update(2, "policy", {"subtask": "swap"})
    ev.update(3, "task", {"lamp": "off"})
    # past the limit each value's last change is kept: the lamp ended off, the subtask swap
    assert ev.to_list() == [[0, "task", "lamp", "off"], [0, "task", "row", [0, 1]],
                            [2, "task", "lamp", "red"], [2, "policy", "subtask", "swap"],
                            [3, "task", "lamp", "off"], [None, "events", "left_out", 2]]
    assert stage_at_end({"events": Events(limit=1).to_list()}) == ""
    capped = Events(limit=1)
    for step, stage in enumerate(["reach", "grasp", "lift"]):
        capped.update(step, "task", {"subtask": stage})
    assert stage_at_end({"events": capped.to_list()}) == "lift"
    assert json.loads(json.dumps(ev.to_list())) == ev.to_list()


def test_policy_errors_are_recorded_and_the_evaluation_goes_on(tmp_path):
    summary = evaluate(cfg(tmp_path, policy="test_faulty", episodes=4))
    recs = {x["seed"] % 4: x for x in records(tmp_path)}
    assert recs[0]["reason"] == "policy_error" and "RuntimeError: boom" in recs[0]["message"]
    assert recs[1]["reason"] == "policy_error" and "NaN" in recs[1]["message"]
    assert recs[2]["reason"] == "policy_error" and "shape" in recs[2]["message"]
    assert recs[3]["reason"] in ("timeout", "task_failure") and recs[3]["steps"] > 0
    assert summary["tasks"][TASK]["endings"]["policy_error"] == 3


class Untypable(BasePolicy):
    """A complex action, or a status JSON has no value for: each an error of the policy's."""

    def __init__(self, kind):
        self.kind = kind

    def act(self, observation):
        return np.full(14, 0.1 + 1j) if self.kind == "complex" else observation["agent_pos"]

    def status(self):
        return {"subtask": {"a", "b"}} if self.kind == "set" else {}


register_policy("test_untypable", "a complex action (complex) or a set in its status (set)",
                needs_argument=True, cameras=())(lambda arg, env: Untypable(arg))


@pytest.mark.parametrize("kind, message", [("complex", "real numbers, got dtype complex128"),
                                           ("set", "TypeError: set is not a JSON value")])
def test_an_answer_json_or_the_arms_cannot_take_is_the_policy_s_error(tmp_path, kind, message):
    summary = evaluate(cfg(tmp_path, policy=f"test_untypable:{kind}", episodes=1))
    (rec,) = records(tmp_path)  # recorded, so a resume goes on past it
    assert rec["reason"] == "policy_error" and message in rec["message"] and rec["steps"] == 0
    assert summary["tasks"][TASK]["endings"]["policy_error"] == 1


def test_resume_keeps_complete_records_and_drops_a_torn_one(tmp_path):
    evaluate(cfg(tmp_path, policy="random"))
    path = tmp_path / "out" / TASK / "episodes.jsonl"
    full = records(tmp_path)
    lines = path.read_text().splitlines(keepends=True)
    path.write_text(lines[0] + lines[1][:20])  # killed while writing the second record
    evaluate(cfg(tmp_path, policy="random"))
    again = records(tmp_path)
    strip = [{k: v for k, v in r.items() if k != "wall_s"} for r in again]
    assert [r["seed"] for r in again] == [r["seed"] for r in full]
    assert strip == [{k: v for k, v in r.items() if k != "wall_s"} for r in full]


def test_a_folder_is_evaluated_by_one_process_and_a_seed_counts_once(tmp_path):
    from rmbench.eval.harness import LOCK
    from rmbench.files import lock

    summary = evaluate(cfg(tmp_path, policy="random"))
    out = tmp_path / "out"
    with lock(out / LOCK), pytest.raises(EvalError, match=r"out is being evaluated by another "
                                                           r"process \(\d+\)"):
        evaluate(cfg(tmp_path, policy="random"))
    path = out / TASK / "episodes.jsonl"
    lines = path.read_text().splitlines(keepends=True)
    twice = json.loads(lines[0])  # a seed recorded twice (an older folder), told apart
    twice["success"], twice["reason"] = not twice["success"], "timeout"
    path.write_text("".join(lines) + json.dumps(twice) + "\n")
    again = evaluate(cfg(tmp_path, policy="random"))
    assert again["tasks"][TASK]["episodes"] == summary["tasks"][TASK]["episodes"]
    assert again["tasks"][TASK]["successes"] == summary["tasks"][TASK]["successes"]
    assert read_records(path)[0] == json.loads(lines[0])  # the first, for every reader


def test_sigkill_and_resume_gives_exactly_n_unique_episodes(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "rmbench.cli.main", "eval", "--task", TASK, "--policy",
           "expert", "--episodes", "4", "--out", str(out), "--video", "none", "--json"]
    env = {**os.environ, "RMBENCH_CACHE": str(tmp_path / "cache")}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    path = out / TASK / "episodes.jsonl"
    deadline = time.time() + 120
    while not (path.exists() and path.read_text().count("\n") >= 1) and time.time() < deadline:
        assert proc.poll() is None, "the evaluation ended before it was killed"
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    assert proc.wait(timeout=30) == -signal.SIGKILL  # killed, not finished
    # killed with its work unfinished: a resume has episodes to add
    assert 1 <= path.read_text().count("\n") < 4
    assert subprocess.run(cmd, capture_output=True, env=env, timeout=300).returncode == 0
    seeds = [r["seed"] for r in read_records(path)]
    assert len(seeds) == 4 and len(set(seeds)) == 4


def test_results_do_not_depend_on_the_worker_count(tmp_path):
    one = evaluate(cfg(tmp_path / "a", policy="random", episodes=4))
    two = evaluate(cfg(tmp_path / "b", policy="random", episodes=4, workers=2))
    assert one == two
    strip = [{k: v for k, v in r.items() if k != "wall_s"} for r in records(tmp_path / "a")]
    assert strip == [{k: v for k, v in r.items() if k != "wall_s"} for r in records(tmp_path / "b")]


def test_other_arguments_on_the_same_folder_are_refused(tmp_path):
    evaluate(cfg(tmp_path, policy="noop", episodes=1))
    with pytest.raises(EvalError, match=r"other arguments \(policy 'noop' there, 'random' asked"):
        evaluate(cfg(tmp_path, policy="random", episodes=1))


def test_a_task_folder_of_another_task_version_is_not_resumed(tmp_path):
    summary = evaluate(cfg(tmp_path, policy="noop", episodes=1))
    version = tmp_path / "out" / TASK / "version.json"
    gym_id = json.loads(version.read_text())["gym_id"]
    assert summary["tasks"][TASK]["gym_id"] == gym_id
    version.write_text(json.dumps({"gym_id": gym_id + "-old"}))
    with pytest.raises(EvalError, match=rf"holds episodes of {gym_id}-old, this rmbench's"):
        evaluate(cfg(tmp_path, policy="noop", episodes=1))
    assert len(records(tmp_path)) == 1


def test_episodes_recorded_before_versions_were_kept_count_as_that_version(tmp_path):
    from rmbench.eval.folder import check_version
    from rmbench.tasks.registry import recorded_gym_id

    assert recorded_gym_id("battery_try", {}) == "rmbench/BatteryTry-v1"
    assert recorded_gym_id("swap_blocks", {}) == "rmbench/SwapBlocks-v1"
    assert recorded_gym_id("cover_blocks", {}) == "rmbench/CoverBlocks-v1"  # (DP, ACT: before v2)
    assert recorded_gym_id("swap_blocks", {"gym_id": "rmbench/SwapBlocks-v2"}) == "rmbench/SwapBlocks-v2"
    (tmp_path / "episodes.jsonl").write_text('{"seed": 1, "success": false, "reason": "timeout", '
                                              '"progress": 0.0}\n')
    with pytest.raises(EvalError, match="holds episodes of rmbench/BatteryTry-v1, this"):
        check_version(tmp_path, "battery_try")
    assert not (tmp_path / "version.json").exists()
    check_version(tmp_path, TASK)  # a task whose version then is the current one
    assert (tmp_path / "version.json").exists()


def test_replay_of_a_dataset_succeeds_on_its_own_seeds(dataset, tmp_path):
    summary = evaluate(cfg(tmp_path, policy=f"replay:{dataset}"))
    assert summary["tasks"][TASK]["successes"] == 3
    assert [r["seed"] for r in records(tmp_path)] == [0, 1, 2]


def test_seeds_of_a_dataset_runs_its_layouts(dataset, tmp_path):
    """--seeds-of: the demonstrations' own seeds (the layouts a policy trained on), named in
    run.json; a dataset of another task is a one-line error."""
    summary = evaluate(cfg(tmp_path / "a", policy="expert", episodes=2, seeds_of=dataset))
    assert summary["tasks"][TASK]["successes"] == 2
    assert [r["seed"] for r in records(tmp_path / "a")] == [0, 1]
    run = json.loads((tmp_path / "a" / "out" / "run.json").read_text())
    assert run["seeds_of"] == str(dataset.resolve())
    with pytest.raises(EvalError, match=f"holds {TASK} demonstrations, not put_back_block"):
        evaluate(EvalConfig(("put_back_block",), "expert", tmp_path / "b", seeds_of=dataset,
                            progress=False, video="none"))


def test_unknown_policy_lists_the_known_ones(tmp_path):
    with pytest.raises(UnknownPolicyError,
                       match=r"unknown policy 'pi0'.*expert.*replay:ARG.*dp:ARG.*act:ARG"):
        cfg(tmp_path, policy="pi0")
    for name in ("replay", "dp", "act", "mem0"):
        with pytest.raises(UnknownPolicyError, match="needs an argument"):
            cfg(tmp_path, policy=name)


def test_a_broken_policy_plugin_leaves_every_other_policy_loadable(monkeypatch):
    from rmbench.policies import registry

    class Broken:  # another package's entry point whose module does not import
        name, value = "broken", "no_such_module_here:register"

        def load(self):
            import no_such_module_here  # noqa: F401

    real = list(registry._plugins())
    monkeypatch.setattr(registry, "_plugins", lambda: [*real, Broken()])
    monkeypatch.setattr(registry, "_loaded", False)
    monkeypatch.setattr(registry, "_failed", {})
    with pytest.warns(RuntimeWarning, match="'broken' failed to import"):
        assert registry.parse_spec("expert")[0].name == "expert"
    with pytest.raises(UnknownPolicyError, match="failed to import: broken: no_such_module_here"):
        registry.parse_spec("theirs")


def test_a_policy_string_splits_into_name_checkpoint_and_options():
    from rmbench.policies.config import parse_argument, split_policy
    from rmbench.policies.mem0.config import Mem0Config

    assert split_policy("mem0:runs/a/ckpt?ablation=no_key&execute=4") == (
        "mem0", "runs/a/ckpt", "ablation=no_key&execute=4")
    assert split_policy("mem0:runs/a/ckpt") == ("mem0", "runs/a/ckpt", "")
    assert split_policy("expert") == ("expert", "", "")
    path, overrides, options = parse_argument("runs/a/ckpt?execute=4&ablation=no_key",
                                              Mem0Config, extra=("ablation",))
    assert (str(path), overrides, options) == ("runs/a/ckpt", {"execute": 4},
                                               {"ablation": "no_key"})


def test_the_registration_alone_says_which_cameras_a_policy_reads():
    from rmbench.policies import registry

    class Carrying(BasePolicy):
        cameras = ()  # what a registration without cameras=() does not know

    register_policy("test_reads_by_argument", "cameras from the argument", needs_argument=True,
                    cameras=lambda arg: tuple(c for c in arg.split(",") if c))(
        lambda arg, env: BasePolicy())
    register_policy("test_carries_cameras", "a cameras attribute beside a default registration")(
        lambda arg, env: Carrying())
    try:
        assert registry.env_options("test_reads_by_argument:head") == {"cameras": ("head",)}
        assert registry.env_options("test_reads_by_argument:,") == {"render": False}
        assert registry.policy_cameras("test_reads_by_argument:head,left_wrist") == (
            "head", "left_wrist")
        assert registry.policy_cameras("test_carries_cameras") == (
            "head", "left_wrist", "right_wrist")  # the station's default set
        with pytest.raises(ValueError, match=r"carries cameras=\(\).*register_policy\("
                                             r"'test_carries_cameras', cameras=\.\.\.\)"):
            registry.make_policy("test_carries_cameras", None)
    finally:
        for name in ("test_reads_by_argument", "test_carries_cameras"):
            registry.POLICIES.pop(name, None)


def test_a_checkpoint_is_evaluated_at_the_resolution_it_trained_on(tmp_path):
    from rmbench.policies import registry

    ckpt = tmp_path / "ckpt"
    ckpt.mkdir()
    describe = {"policy": "dp", "config": {"observation": "pixels", "cameras": ["head"]},
                "dataset": {"resolution": "128x96"}}
    (ckpt / "config.json").write_text(json.dumps(describe))
    assert registry.env_options(f"dp:{ckpt}") == {"width": 128, "height": 96,
                                                  "cameras": ("head",)}
    del describe["dataset"]  # a checkpoint from before it was recorded: the env's default
    (ckpt / "config.json").write_text(json.dumps(describe))
    assert registry.env_options(f"dp:{ckpt}") == {"cameras": ("head",)}
    describe["config"]["observation"] = "state"  # nothing rendered, no size
    describe["dataset"] = {"resolution": "128x96"}
    (ckpt / "config.json").write_text(json.dumps(describe))
    assert "width" not in registry.env_options(f"dp:{ckpt}")


def test_report_renders_markdown_and_html(tmp_path):
    from rmbench.eval.report import write_report

    evaluate(cfg(tmp_path, video="first:1", episodes=2))
    md = write_report([tmp_path / "out"], tmp_path / "r.md", ["Mem-0"]).read_text()
    # each rate beside its 95% interval: 2 of 2 here, 4 of the published 100 rollouts
    assert "| observe_and_pickup | M(1) | 100.0 [34, 100] | 4.0 [2, 10] |" in md
    # the published column averages every M(1) task's published rate, evaluated here or not,
    # with the interval of the pooled rollouts (100 per task)
    from rmbench.eval.intervals import wilson
    from rmbench.eval.report import PUBLISHED
    from rmbench.tasks.registry import ordered
    m1 = [PUBLISHED["Mem-0"][t.name] for t in ordered() if t.tmc == "M(1)"]
    low, high = wilson(sum(m1), 100 * len(m1))
    assert len(m1) == 5
    assert (f"| **average M(1)** | M(1) | — | {sum(m1) / len(m1):.1f} "
            f"[{100 * low:.0f}, {100 * high:.0f}] |") in md  # others not evaluated
    assert "| observe_and_pickup | M(1) | 100.0 |\n" in md  # progress: no interval
    page = write_report([tmp_path / "out"], tmp_path / "r.html", []).read_text()
    assert "<svg" in page and "seed-100000.mp4" in page
    with pytest.raises(ValueError, match="no published numbers"):
        write_report([tmp_path / "out"], tmp_path / "r.md", ["GPT"])
    named = write_report([tmp_path / "out"], tmp_path / "n.md", [], ["scripted"]).read_text()
    assert "| task | TMC | scripted |" in named and "scripted: `expert`" in named
    with pytest.raises(ValueError, match="2 labels for 1 evaluation folders"):
        write_report([tmp_path / "out"], tmp_path / "r.md", [], ["a", "b"])


def test_an_analysis_watches_every_step_of_the_evaluated_episode():
    import rmbench
    from rmbench.eval.episode import run_policy_episode

    env = rmbench.make(TASK, render=False, obs_type="environment_state_agent_pos")
    seen = []
    record = run_policy_episode(env, Faulty(), 100003, on_step=lambda step, info: seen.append(
        (step, info["progress"])))
    assert [s for s, _ in seen] == list(range(1, record["steps"] + 1))
    assert max(p for _, p in seen) == record["progress"]
    plain = run_policy_episode(env, Faulty(), 100003)  # watching changes nothing
    assert {k: v for k, v in plain.items() if k != "wall_s"} == \
        {k: v for k, v in record.items() if k != "wall_s"}


def test_a_damaged_record_mid_file_is_an_error_that_loses_nothing(tmp_path):
    evaluate(cfg(tmp_path, policy="random"))
    path = tmp_path / "out" / TASK / "episodes.jsonl"
    lines = path.read_text().splitlines(keepends=True)
    for bad in ('{"x": 1\n', "\n", "5\n", '{"task": "x"}\n'):
        damaged = lines[0] + bad + "".join(lines[1:])
        path.write_text(damaged)
        with pytest.raises(EvalError, match=r"episodes.jsonl: line 2 is not an episode record"):
            records(tmp_path)
        with pytest.raises(EvalError, match="line 2 is not an episode record"):
            evaluate(cfg(tmp_path, policy="random"))
        assert path.read_text() == damaged  # neither the reader nor the resume cut it
    # a record of the wrong types: a seed as text would be played and recorded again
    first = json.loads(lines[0])
    for key, value, what in (("seed", str(first["seed"]), "an integer"),
                             ("success", None, "true or false"), ("progress", True, "a number")):
        damaged = json.dumps({**first, key: value}) + "\n" + "".join(lines[1:])
        path.write_text(damaged)
        with pytest.raises(EvalError, match=f"line 1: its {key} is .*, not {what}"):
            evaluate(cfg(tmp_path, policy="random"))
        assert path.read_text() == damaged
    # a torn last line is left out by a reader, and cut only by the evaluation that appends
    path.write_text("".join(lines) + lines[0][:20])
    assert len(records(tmp_path)) == 3 and path.read_text().endswith(lines[0][:20])


def test_a_bad_policy_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(ValueError, match="not a checkpoint"):
        evaluate(cfg(tmp_path, policy=f"mem0:{tmp_path / 'missing'}"))
    with pytest.raises(ValueError, match="missing"):
        evaluate(cfg(tmp_path, policy="noop", seeds_of=str(tmp_path / "missing")))
    assert not (tmp_path / "out").exists()
    # a folder whose run stopped before its first episode is taken over by the next command
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "run.json").write_text(json.dumps({"policy": "random"}))
    assert evaluate(cfg(tmp_path, policy="noop", episodes=1))["policy"] == "noop"
    (tmp_path / "out" / "run.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match=r"run.json: holds a JSON list, not an object"):
        evaluate(cfg(tmp_path, policy="noop", episodes=1))


def test_a_checkpoint_spelled_another_way_resumes_its_evaluation(tmp_path, monkeypatch):
    """A table re-run with its OUT given as an absolute path, or through a link, names the
    same checkpoint folder in other words: its evaluations resume, they are not refused."""
    from rmbench.eval.folder import check_identity, placed

    ckpt = tmp_path / "runs" / "ckpt"
    ckpt.mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "runs")
    monkeypatch.chdir(tmp_path)
    assert placed("mem0:runs/ckpt?ablation=no_key") == f"mem0:{ckpt}?ablation=no_key"
    assert placed("mem0:link/ckpt") == placed(f"mem0:{ckpt}") == f"mem0:{ckpt}"
    assert placed("noop") == "noop" and placed("mem0:no/such/folder") == "mem0:no/such/folder"
    out = tmp_path / "eval"
    check_identity(out, cfg(out, policy="mem0:runs/ckpt").identity())
    (out / TASK).mkdir(parents=True)
    (out / TASK / "episodes.jsonl").write_text('{"seed": 1}\n')  # an episode recorded
    check_identity(out, cfg(out, policy=f"mem0:{tmp_path}/link/ckpt").identity())
    with pytest.raises(EvalError, match="other arguments"):
        check_identity(out, cfg(out, policy="mem0:runs/ckpt?ablation=no_key").identity())


def test_a_rate_reads_its_count_and_falls_back_to_the_rate_alone():
    """A row with a count needs no rate beside it; an older row without one has it back from
    its rate and episodes."""
    from rmbench.eval.report import Rate

    assert (Rate.of({"successes": 36, "episodes": 100}).successes,
            Rate.of({"success_rate": 0.36, "episodes": 100}).successes) == (36, 36)
