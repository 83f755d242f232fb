"""A training killed at any instant of its final save resumes to the checkpoint an
uninterrupted run writes; one found done with its checkpoint missing or torn writes it again."""

import itertools
import json

import pytest
import torch
from safetensors.torch import load_file
from torch import nn

from rmbench import files
from rmbench.policies import checkpoint
from rmbench.policies.checkpoint import save_checkpoint, saved_step
from rmbench.training import curve, loop
from rmbench.training.loop import TrainConfig, train

STEPS, SAVE_EVERY = 6, 4  # saves at 4 and 6: a kill in the final save resumes from 4


class Line(nn.Module):
    """A linear regression: a model the loop trains in milliseconds."""

    def __init__(self):
        super().__init__()
        torch.manual_seed(0)
        self.lin = nn.Linear(3, 1)

    def forward(self, batch):
        return ((self.lin(batch["x"]) - batch["y"]) ** 2).mean(), {}

    def param_groups(self):
        return [{"name": "all", "params": list(self.parameters()), "lr": 1e-2, "min_lr": 1e-3}]


def batches(start, rank, world):
    for step in itertools.count(start):  # a function of the step, as the loop requires
        x = torch.randn(8, 3, generator=torch.Generator().manual_seed(step))
        yield {"x": x, "y": x.sum(1, keepdim=True)}


def run(out):
    return train(Line(), batches, TrainConfig(steps=STEPS, save_every=SAVE_EVERY, log_every=1),
                 out, {"policy": "line"}, progress=False, write_checkpoint=save_checkpoint,
                 checkpoint_step=saved_step)


class Killed(BaseException):
    """What a SIGKILL leaves: the files as they are at that instant, nothing after."""


def checkpoint_of(out):
    return load_file(out / "model.safetensors"), json.loads((out / "config.json").read_text())


def same_checkpoint(a, b):
    (wa, ca), (wb, cb) = checkpoint_of(a), checkpoint_of(b)
    assert ca == cb and wa.keys() == wb.keys()
    assert all(torch.equal(wa[k], wb[k]) for k in wa)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("final") / "uninterrupted"
    run(out)
    return out


def final_save_writes(monkeypatch, die_after: int | None, at: int = STEPS) -> list[str]:
    """Patches the loop so that its save of step ``at`` (the final one) dies after
    ``die_after`` of its file writes (None: never), leaving the dying write's temporary file
    as a SIGKILL inside its rename would; returns the list that save's writes are named in."""
    writes: list[str] = []
    final = {"on": False}
    save, write = loop._save, loop.write_atomic

    def tracked_save(out, model, opt, identity, kept, *args):
        final["on"] = kept.step == at
        save(out, model, opt, identity, kept, *args)

    def tracked_write(path, data):
        if final["on"] and die_after is not None and len(writes) == die_after:
            (path.parent / f".{path.name}.999999999.tmp").write_bytes(data[:10])
            raise Killed
        write(path, data)
        if final["on"]:
            writes.append(path.name)

    monkeypatch.setattr(loop, "_save", tracked_save)
    monkeypatch.setattr(loop, "write_atomic", tracked_write)
    monkeypatch.setattr(curve, "write_atomic", tracked_write)  # loss.csv, loss.png
    monkeypatch.setattr(checkpoint, "write_atomic", tracked_write)
    monkeypatch.setattr(files, "write_atomic", tracked_write)  # write_json's writes
    return writes


def test_the_final_save_writes_the_checkpoint_before_the_state(tmp_path, monkeypatch):
    writes = final_save_writes(monkeypatch, None)
    run(tmp_path / "r")
    assert writes.index("config.json") < writes.index("state.pt")
    assert writes.index("model.safetensors") < writes.index("state.pt")


@pytest.mark.parametrize("die_after", range(6))  # loss.csv, weights, config, state, loss.png
def test_a_kill_inside_the_final_save_resumes_to_the_uninterrupted_checkpoint(
        reference, tmp_path, monkeypatch, die_after):
    out = tmp_path / "killed"
    writes = final_save_writes(monkeypatch, die_after)
    if die_after < 5:
        with pytest.raises(Killed):
            run(out)
        assert len(writes) == die_after  # killed inside the final save, its work unfinished
    else:
        run(out)
    monkeypatch.undo()
    result = run(out)
    assert result["resumed_from"] == (STEPS if die_after >= 4 else SAVE_EVERY)
    same_checkpoint(out, reference)
    assert saved_step(out) == STEPS


@pytest.mark.parametrize("damage", ["missing weights", "missing config", "torn pair"])
def test_a_finished_training_rewrites_a_missing_or_torn_checkpoint(reference, tmp_path, damage):
    import shutil

    out = tmp_path / "done"
    shutil.copytree(reference, out)
    if damage == "missing weights":
        (out / "model.safetensors").unlink()
    elif damage == "missing config":
        (out / "config.json").unlink()
    else:  # the weights of the save before beside the final config, as the old order left
        weights = load_file(out / "model.safetensors")
        from safetensors.torch import save_file
        save_file({k: v + 1 for k, v in weights.items()}, out / "model.safetensors",
                  metadata={"step": str(SAVE_EVERY)})
    assert saved_step(out) is None
    assert run(out)["resumed_from"] == STEPS  # nothing is trained again
    same_checkpoint(out, reference)


@pytest.mark.parametrize("die_after", range(3))  # loss.csv, weights, config: no state yet
def test_a_kill_inside_the_first_save_begins_again(reference, tmp_path, monkeypatch, die_after):
    out = tmp_path / "first"
    final_save_writes(monkeypatch, die_after, at=SAVE_EVERY)
    with pytest.raises(Killed):
        run(out)
    assert not (out / loop.STATE).exists() and any(out.rglob(".*.tmp"))
    monkeypatch.undo()
    assert run(out)["resumed_from"] == 0  # this folder's own run, begun again
    same_checkpoint(out, reference)
    assert not list(out.rglob(".*.tmp"))  # the dead writer's leftovers are gone
    # another run's arguments on that folder are still refused
    (out / loop.STATE).unlink()
    with pytest.raises(loop.TrainingError, match="other arguments"):
        train(Line(), batches, TrainConfig(steps=STEPS + 1, save_every=SAVE_EVERY), out,
              {"policy": "line"}, progress=False, write_checkpoint=save_checkpoint)


def test_a_finished_training_redraws_a_stale_curve(reference, tmp_path):
    import os
    import shutil

    out = tmp_path / "done"
    shutil.copytree(reference, out)
    png = out / loop.CURVE_PNG
    png.write_bytes(b"stale")
    os.utime(png, ns=(0, 0))  # older than loss.csv: the run stopped before its plot
    run(out)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_resume_on_another_thread_count_says_so(tmp_path, caplog):
    out = tmp_path / "t"
    train(Line(), batches, TrainConfig(steps=SAVE_EVERY, save_every=SAVE_EVERY), out,
          {"policy": "line"}, progress=False, write_checkpoint=save_checkpoint)
    threads = torch.get_num_threads()
    torch.set_num_threads(threads + 1)
    try:
        with caplog.at_level("WARNING"):
            train(Line(), batches, TrainConfig(steps=SAVE_EVERY, save_every=SAVE_EVERY), out,
                  {"policy": "line"}, progress=False, write_checkpoint=save_checkpoint)
    finally:
        torch.set_num_threads(threads)
    assert f"resumed on {threads + 1} torch threads where it saved on {threads}" in caplog.text


def test_a_resume_on_other_data_is_refused(tmp_path):
    out = tmp_path / "d"

    def on(data):
        return train(Line(), batches, TrainConfig(steps=STEPS, save_every=SAVE_EVERY), out,
                     {"policy": "line"}, progress=False, write_checkpoint=save_checkpoint,
                     data=data)

    on("aaaa")
    with pytest.raises(loop.TrainingError, match=r"on other data \(fingerprint aaaa there, "
                                                 r"bbbb asked\)"):
        on("bbbb")
    assert on("aaaa")["resumed_from"] == STEPS
    # a state saved before fingerprints were kept resumes on any data
    state = torch.load(out / loop.STATE, weights_only=True)
    state["data"] = None
    torch.save(state, out / loop.STATE)
    assert on("bbbb")["resumed_from"] == STEPS


@pytest.mark.parametrize("damage", ["no identity", "another model", "identity not JSON"])
def test_a_state_that_loads_but_is_not_this_runs_is_an_error_naming_it(tmp_path, damage):
    out = tmp_path / "s"
    cfg = TrainConfig(steps=SAVE_EVERY, save_every=SAVE_EVERY)
    train(Line(), batches, cfg, out, {"policy": "line"}, progress=False,
          write_checkpoint=save_checkpoint)
    state = torch.load(out / loop.STATE, weights_only=True)
    if damage == "no identity":
        del state["identity"]
    elif damage == "another model":
        state["model"] = {"other.weight": torch.zeros(2)}
    else:
        state["identity"] = "{not json"
    torch.save(state, out / loop.STATE)
    with pytest.raises(loop.TrainingError, match=r"state\.pt: not a state this training can "
                                                 r"resume from"):
        train(Line(), batches, cfg, out, {"policy": "line"}, progress=False,
              write_checkpoint=save_checkpoint)


def test_a_state_saved_before_the_description_named_the_resolution_resumes():
    from rmbench.training.state import run_differences, run_identity

    cfg = TrainConfig(steps=4)
    now = {"policy": "dp", "dataset": {"path": "/a", "episodes": 2, "resolution": "320x240"}}
    before = {"policy": "dp", "dataset": {"path": "/b", "episodes": 2}}
    assert run_differences(run_identity(before, cfg), run_identity(now, cfg)) == ""
    other = {"policy": "dp", "dataset": {"path": "/a", "episodes": 3, "resolution": "320x240"}}
    assert run_differences(run_identity(other, cfg), run_identity(now, cfg)) != ""


def test_a_run_saved_before_a_config_field_existed_is_compared_as_its_checkpoint_reads_it():
    """A Mem-0 run saved before ``end_classifier`` existed trained the "context" classifier,
    as ``Mem0Config.from_dict`` reads its checkpoint: its resume is that run, not today's
    default's."""
    from rmbench.policies.mem0.config import Mem0Config
    from rmbench.training.state import run_differences, run_identity

    cfg, defaults = TrainConfig(steps=4), Mem0Config.saved_defaults()
    saved = Mem0Config().to_dict()
    del saved["end_classifier"], saved["planner_key_delay"]
    before = run_identity({"policy": "mem0", "config": saved}, cfg)

    def asked(**fields):
        return run_identity({"policy": "mem0", "config": {**Mem0Config().to_dict(), **fields}},
                            cfg)

    assert run_differences(before, asked(end_classifier="context", planner_key_delay=0),
                           defaults) == ""
    assert "end_classifier" in run_differences(before, asked(planner_key_delay=0), defaults)
    assert Mem0Config.from_dict(saved).end_classifier == "context"
