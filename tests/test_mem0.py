"""Mem-0: memory semantics, the end rule, the planner, training (overfit, resume), checkpoints
and the closed loop."""

import json
import math
import shutil
from dataclasses import replace

import numpy as np
import pytest
import torch

from rmbench.data.reader import Dataset
from rmbench.envs.registration import make
from rmbench.policies.checkpoint import CheckpointError, read_config
from rmbench.policies.mem0.agent import Mem0Policy
from rmbench.policies.mem0.classifier import Debounce, end_labels, event_labels
from rmbench.policies.mem0.config import Mem0Config
from rmbench.policies.mem0.memory import MemoryStore
from rmbench.policies.mem0.planner import Planner, planner_examples, runs
from rmbench.policies.mem0.train import check_executor_source, executor_digest, train_mem0
from rmbench.policies.registry import env_options, policy_cameras
from rmbench.training.loop import TrainConfig
from rmbench.training.state import TrainingError
from tests.conftest import EXPORTED, keep_exports, roll_out

TINY = Mem0Config(cameras=("head", "left_wrist"), planner_cameras=("head",), image_size=(48, 64),
                  dim=32, encoder_channels=(8, 16, 16), keypoints=4, heads=2, head_layers=1,
                  horizon=8, execute=4, sliding_window=3, memory_every=2, flow_steps=2,
                  planner_steps=30, planner_batch=4, end_window=3)


def train_tiny(dataset, out, steps=6, cfg=TINY, **kw):
    args = {"steps": steps, "batch_size": 4, "save_every": 3, "log_every": 1, **kw}
    return train_mem0(dataset, out, cfg, TrainConfig(**args), progress=False)


@pytest.fixture(scope="module")
def mn_ckpt(mn_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("ckpt") / "mn"
    with keep_exports():
        train_tiny(mn_dataset, out)
    return out


# ------------------------------------------------------------------ memory semantics
def test_sliding_window_holds_exactly_the_last_k_in_order():
    m = MemoryStore(slots=2, cameras=1, window=3, dim=1)
    for v in range(1, 6):
        m.push(torch.tensor([[float(v)], [10.0 * v]]))
    assert m.sliding[0, :, 0].tolist() == [3.0, 4.0, 5.0]
    assert m.valid.all()
    m.reset(torch.tensor([True, False]), torch.zeros(2, 1, 1))
    assert not m.valid[0].any() and m.valid[1].all()  # slots are independent
    m.push(torch.tensor([[7.0], [0.0]]), which=torch.tensor([True, False]))
    assert m.valid[0].tolist() == [False, False, True] and m.sliding[0, -1, 0] == 7.0
    assert m.sliding[1, :, 0].tolist() == [30.0, 40.0, 50.0]


def test_anchor_is_the_first_frame_of_the_subtask_and_stays(mn_ckpt):
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    # the simulator's boundary: holding still, no subtask ends on its own
    policy = Mem0Policy(f"{mn_ckpt}?ablation=gt_classifier", env)
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    ex = policy.model.executor
    first_tokens, _ = ex.encode(policy.inputs(obs))
    anchors = []
    for _ in range(5):
        policy.act(obs)
        anchors.append(policy.memories[0].anchor.clone())
        obs, *_ = env.step(np.asarray(obs["agent_pos"]))
    assert torch.allclose(anchors[0][0], first_tokens[0].detach())
    assert all(torch.equal(a, anchors[0]) for a in anchors)
    # a subtask ends: the next step's frame becomes the anchor and the window empties
    policy.subtask_ended(policy.inputs(obs))
    assert len(policy.keys) == 1
    policy.act(obs)
    tokens, _ = ex.encode(policy.inputs(obs))
    assert torch.allclose(policy.memories[0].anchor[0], tokens[0])
    # The window is filled on the subtask's own phase, as training walks it: the subtask's
    # first frame (here the episode's sixth, odd) is pushed, then every memory_every-th.
    assert policy.t == 6 and int(policy.memories[0].valid.sum()) == 1
    filled = []
    for _ in range(4):
        policy.act(obs)
        filled.append(int(policy.memories[0].valid.sum()))
    assert TINY.memory_every == 2 and filled == [1, 2, 2, 3]
    env.close()


def test_debounce_needs_l_consecutive_positives_and_one_run_declares_one_end():
    d = Debounce(3)
    assert [d.update(x) for x in [1, 1, 0, 1, 1, 1, 1]] == [False] * 5 + [True, False]
    # the run that declared goes on: no second end until it breaks
    assert [d.update(x) for x in [1, 1, 1, 1, 0, 1, 1, 1]] == [False] * 7 + [True]
    d.update(True)
    d.reset()  # a new episode re-arms it
    assert [d.update(x) for x in [1, 1, 1]] == [False, False, True]
    with pytest.raises(ValueError):
        Debounce(0)


def test_end_labels_mark_the_last_l_frames_of_each_subtask():
    idx = np.array([0, 0, 0, 0, 1, 1, 2, 2, 2])
    assert end_labels(idx, 2).tolist() == [0, 0, 1, 1, 1, 1, 0, 1, 1]
    assert runs(idx, idx) == [(0, 3), (1, 5), (2, 8)]
    ex = planner_examples(7, idx, idx, done_index=9)
    assert [x.target for x in ex] == [0, 1, 2, 9]
    assert ex[2].keys == ((0, 3), (1, 5)) and ex[2].current == 5


def test_delayed_keys_stay_within_the_delay_and_the_episode():
    from rmbench.policies.mem0.train import delayed

    idx = np.array([0] * 5 + [1] * 5 + [2] * 3)
    rng = np.random.default_rng(0)
    x = planner_examples(0, idx, idx, done_index=9)[3]  # after three steps: keys end 4, 9, 12
    seen = set()
    for _ in range(200):
        y = delayed(x, rng, 3, len(idx))
        assert [s for s, _ in y.keys] == [0, 1, 2] and y.target == x.target
        for (_, f0), (_, f) in zip(x.keys, y.keys, strict=True):
            assert f0 <= f <= min(f0 + 3, len(idx) - 1)
            seen.add(f - f0)
        assert x.current <= y.current <= len(idx) - 1
    assert seen == {0, 1, 2, 3}  # every delay drawn; the last key capped at the episode's end
    with pytest.raises(ValueError, match="planner_key_delay"):
        replace(TINY, planner_key_delay=-1)


def test_event_labels_mark_the_frames_just_after_each_step_ends():
    step = np.array([0, 0, 0, 1, 1, 1, 1, 1, 2, 2])
    assert event_labels(step, 3).tolist() == [0, 0, 0, 1, 1, 1, 0, 0, 1, 1]
    assert TINY.end_span == 4 and Mem0Config().end_span == 12  # 1.5 L: fires once per end


def walk(policy, env, steps: int, after=None) -> list[torch.Tensor]:
    """``steps`` steps of press_button's seed 100000 by ``policy``, the arms nudged a little
    more each step (``after(t, obs)`` after each act); each step's z_img."""
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    zs = []
    for t in range(steps):
        zs.append(policy.model.executor.encode(policy.inputs(obs))[1][0])
        policy.act(obs)
        if after is not None:
            after(t, obs)
        obs, *_ = env.step(np.asarray(obs["agent_pos"]) + 0.01 * (t + 1))
    return zs


def test_a_chunk_drawn_off_the_stride_reads_its_phase_memory(mn_ckpt):
    """Training walks a subtask at the memory stride from a first frame 0 to stride - 1 steps
    in: c_t's anchor is that frame and its newest window entry one stride old. A chunk drawn
    at any step (here every 3 steps, the stride 2) reads such a memory: its phase's."""
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(f"{mn_ckpt}?ablation=gt_classifier&execute=3", env)
    assert TINY.memory_every == 2 and len(policy.memories) == 2
    ex, read = policy.model.executor, []
    context = ex.context

    def spy(z, memory, text):
        read.append({k: v[0].clone() for k, v in memory.state().items()})
        return context(z, memory, text)

    ex.context = spy
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    tokens, zs = [], []
    for t in range(7):
        tok, z = ex.encode(policy.inputs(obs))
        tokens.append(tok[0])
        zs.append(z[0])
        policy.act(obs)
        obs, *_ = env.step(np.asarray(obs["agent_pos"]) + 0.01 * (t + 1))
    assert policy.slots[0].subtask_t == 7  # (no subtask ended: one walk from the first frame)
    for t, memory in enumerate(read):
        phase = t % 2
        torch.testing.assert_close(memory["anchor"], tokens[phase], atol=1e-6, rtol=0)
        frames = list(range(phase, t, 2))  # the phase's frames before this one
        assert int(memory["valid"].sum()) == len(frames)
        if frames:
            torch.testing.assert_close(memory["sliding"][-len(frames):],
                                       torch.stack([zs[f] for f in frames]), atol=1e-6, rtol=0)
    env.close()


def test_event_window_fills_on_the_episode_phase_and_outlives_subtask_ends(mn_ckpt):
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(f"{mn_ckpt}?ablation=gt_classifier", env)

    def end_at_2(t, obs):  # a subtask ends: the sliding memory starts again, the event window not
        if t == 2:
            policy.subtask_ended(policy.inputs(obs))

    zs = walk(policy, env, 7, end_at_2)
    # the episode's first frame fills it, then every memory_every-th step enters: 0, 2, 4, 6
    assert policy.cfg.event_window == 4 and TINY.memory_every == 2
    want = torch.stack([zs[0], zs[2], zs[4], zs[6]])
    assert len(policy.event_windows) == 1
    assert torch.allclose(policy.event_windows[0].entries[0], want, atol=1e-6)
    env.close()


def test_event_windows_by_phase_read_entries_whole_strides_old(mn_ckpt):
    """With event_phases the classifier reads, at every step, entries 1, 2, 3, 4 strides old
    (those of the step's phase), as training's walks at the stride give it; each phase's
    window starts from its own first frame, as a walk starting there does."""
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(f"{mn_ckpt}?event_phases=true", env)
    assert TINY.memory_every == 2 and len(policy.event_windows) == 2
    read = []
    end_logit = policy.model.executor.end_logit

    def spy(c, z, events):
        read.append(events.entries[0].clone())
        return end_logit(c, z, events)

    policy.model.executor.end_logit = spy
    z = torch.stack(walk(policy, env, 9))
    assert torch.allclose(read[8], z[[0, 2, 4, 6]], atol=1e-6)
    assert torch.allclose(read[7], z[[1, 1, 3, 5]], atol=1e-6)
    assert torch.allclose(read[1], z[[1, 1, 1, 1]], atol=1e-6)
    env.close()


def test_end_classifier_choice_and_checkpoints_from_before_it(mn_dataset, tmp_path):
    with pytest.raises(ValueError, match="end_classifier"):
        replace(TINY, end_classifier="clock")
    before = {k: v for k, v in TINY.to_dict().items() if k != "end_classifier"}
    assert Mem0Config.from_dict(before).end_classifier == "context"
    # the published classifier on c_t still trains and runs
    ctx = replace(TINY, end_classifier="context")
    with keep_exports():
        train_tiny(mn_dataset, tmp_path / "ctx", steps=2, cfg=ctx)
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(str(tmp_path / "ctx"), env)
    assert policy.cfg.end_classifier == "context"
    assert policy.model.executor.classifier[0].in_features == 3 * TINY.dim
    roll_out(env, policy, seed=100000, steps=3)
    env.close()


def test_planner_output_depends_on_key_memory():
    torch.manual_seed(0)
    planner = Planner(TINY, ["a", "b", "c", "done"], None).eval()
    first = torch.randn(1, TINY.dim)
    keys = torch.randn(1, 2, TINY.dim)
    valid = torch.ones(1, 2, dtype=torch.bool)
    a = planner(first, keys, torch.tensor([[0, 1]]), valid)
    b = planner(first, keys, torch.tensor([[0, 2]]), valid)
    c = planner(first, keys * 0, torch.tensor([[0, 1]]), valid)
    assert not torch.allclose(a, b) and not torch.allclose(a, c)
    no_key = Planner(replace(TINY, ablations=("no_key",)), ["a", "b", "c", "done"], None).eval()
    no_key.load_state_dict(planner.state_dict())
    assert torch.allclose(no_key(first, keys, torch.tensor([[0, 1]]), valid),
                          no_key(first, keys * 0, torch.tensor([[0, 2]]), valid))


def test_ablations_remove_the_memory_paths():
    from rmbench.policies.mem0.modeling import Executor
    torch.manual_seed(0)
    ex = Executor(replace(TINY, ablations=("no_memory",)), ["goal"], None).eval()
    m = MemoryStore(1, 2, TINY.sliding_window, TINY.dim)
    z = torch.randn(1, TINY.dim)
    c = ex.context(z, m, torch.tensor([0]))
    assert torch.equal(c[:, 0], z) and torch.equal(c[:, 1], z)
    with pytest.raises(ValueError, match="unknown ablation"):
        Mem0Config(ablations=("no_brain",))


# ------------------------------------------------------------------ training
def sampled_action_error(model, dataset) -> float:
    """Mean |sampled - demonstrated| over the first D actions, walking each episode with the
    memory the policy would build."""
    from rmbench.data import layout as L
    from rmbench.data.reader import Dataset
    from rmbench.policies.mem0.train import Mem0Frames

    cfg, ex = model.cfg, model.executor
    frames = Mem0Frames(Dataset(dataset), cfg, False, len(ex.text.texts) - 1)
    errors = []
    with torch.no_grad():
        for e in range(len(frames.lengths)):
            memory = MemoryStore(1, len(cfg.cameras), cfg.sliding_window, cfg.dim)
            for t in range(0, int(frames.lengths[e]), cfg.memory_every):
                item = frames[int(frames.starts[e]) + t]
                tokens, z = ex.encode([item[L.image_key(c)][None] for c in cfg.cameras])
                if t == 0:
                    memory.reset(torch.ones(1, dtype=torch.bool), tokens)
                c = ex.context(z, memory, item["text_index"][None])
                memory.push(z)
                chunk = ex.head.sample(ex.condition(c, item[L.STATE][None]), cfg.flow_steps,
                                       torch.Generator().manual_seed(t))
                err = (ex.normalizer.unaction(chunk, item[L.STATE][None])[0, :cfg.execute]
                       - item[L.ACTION][:cfg.execute])
                errors.append(err.abs().mean().item())
    return float(np.mean(errors))


@pytest.mark.slow  # 300 pixel training steps: minutes of a shared CPU
def test_executor_overfits_a_tiny_dataset(dataset, tmp_path):
    import csv

    from rmbench.policies.mem0.agent import load_mem0
    cfg = replace(TINY, jitter=(0.0, 0.0, 0.0), lr_head=1e-3, lr_backbone=1e-3, flow_steps=10)
    train_tiny(dataset, tmp_path / "init", steps=1, cfg=cfg)
    train_tiny(dataset, tmp_path / "c", steps=300, cfg=cfg, batch_size=16, save_every=300,
               log_every=10)
    rows = list(csv.DictReader(open(tmp_path / "c" / "training" / "loss.csv")))
    first, last = float(rows[0]["loss/action"]), float(rows[-1]["loss/action"])
    assert last < 0.4 * first, (first, last)
    before = sampled_action_error(load_mem0(tmp_path / "init")[0], dataset)
    after = sampled_action_error(load_mem0(tmp_path / "c")[0], dataset)
    assert after < 0.8 * before, (before, after)


def test_planner_learns_the_demonstrated_order(mn_dataset, tmp_path):
    # press_button's order is a count: after k pushes of the left button the next is another
    # push while k < d1 (the tile's digit, in the state observation), so the planner must count
    # its key memory's entries.
    cfg = replace(TINY_STATE, planner_steps=600, planner_lr=3e-3)
    train_tiny(mn_dataset, tmp_path / "p", steps=1, cfg=cfg)
    report = json.loads((tmp_path / "p" / "training" / "planner.json").read_text())
    assert report["train_accuracy"] >= 0.9, report


def test_no_key_beside_mem0s_executor_is_the_checkpoint_a_full_run_writes(mn_dataset, tmp_path,
                                                                         interrupt_training):
    """no_key changes the planner alone: its checkpoint, made from Mem-0's executor and a
    planner fitted anew, is the one its own full training writes, bit for bit."""
    from safetensors.torch import load_file

    mem0 = replace(TINY, ema=True)  # the export averages weights: the frozen planner's stay
    no_key = replace(mem0, ablations=("no_key",))
    run = TrainConfig(steps=4, batch_size=4, save_every=4, log_every=1)
    train_mem0(mn_dataset, tmp_path / "full", no_key, run, progress=False)
    train_mem0(mn_dataset, tmp_path / "mem0", mem0, run, progress=False)
    result = train_mem0(mn_dataset, tmp_path / "beside", no_key, run, progress=False,
                        executor_from=tmp_path / "mem0")
    assert result["executor_from"] == str((tmp_path / "mem0").resolve())
    full = load_file(tmp_path / "full" / "model.safetensors")
    beside = load_file(tmp_path / "beside" / "model.safetensors")
    assert full.keys() == beside.keys()
    for k in full:
        assert torch.equal(full[k], beside[k]), k
    config = read_config(tmp_path / "beside")
    assert config.pop("executor_from") == result["executor_from"]
    source = load_file(tmp_path / "mem0" / "model.safetensors")
    assert config.pop("executor_sha256") == executor_digest(source) == executor_digest(beside)
    assert config == read_config(tmp_path / "full")
    planner = [json.loads((tmp_path / r / "training" / "planner.json").read_text())
               for r in ("full", "beside")]
    assert planner[0] == planner[1]
    # another seed's run, an unfinished one, an ablation that changes the executor, or a
    # folder holding a run of its own: refused
    with pytest.raises(TrainingError, match="holds a training run of its own"):
        train_mem0(mn_dataset, tmp_path / "full", no_key, run, progress=False,
                   executor_from=tmp_path / "mem0")
    with pytest.raises(TrainingError, match="not the executor run"):
        train_mem0(mn_dataset, tmp_path / "x", no_key, replace(run, seed=1), progress=False,
                   executor_from=tmp_path / "mem0")
    longer = replace(run, steps=8)
    interrupt_training(lambda: train_mem0(mn_dataset, tmp_path / "part", mem0, longer,
                                          progress=False))
    with pytest.raises(TrainingError, match="has trained 4 of 8 steps"):
        train_mem0(mn_dataset, tmp_path / "y", no_key, longer, progress=False,
                   executor_from=tmp_path / "part")
    with pytest.raises(ValueError, match="trains its own"):
        train_mem0(mn_dataset, tmp_path / "z", replace(mem0, ablations=("no_anchor",)), run,
                   progress=False, executor_from=tmp_path / "mem0")
    # the derived checkpoint stays tied to its source: a source trained again is caught
    check_executor_source(tmp_path / "beside")
    check_executor_source(tmp_path / "full")  # a run of its own: nothing to check
    train_mem0(mn_dataset, tmp_path / "mem0b", mem0, replace(run, seed=2), progress=False)
    for f in ("model.safetensors", "config.json"):
        shutil.copyfile(tmp_path / "mem0b" / f, tmp_path / "mem0" / f)
    with pytest.raises(CheckpointError, match="trained again since"):
        check_executor_source(tmp_path / "beside")


def test_resume_gives_the_weights_of_an_uninterrupted_run(mn_dataset, tmp_path,
                                                          interrupt_training):
    from safetensors.torch import load_file

    train_tiny(mn_dataset, tmp_path / "a", steps=6)
    # killed right after the step-3 checkpoint
    interrupt_training(lambda: train_tiny(mn_dataset, tmp_path / "b", steps=6))
    result = train_tiny(mn_dataset, tmp_path / "b", steps=6)
    assert result["resumed_from"] == 3
    # the planner was fitted before the interruption: its report comes back with the state
    report = [json.loads((tmp_path / r / "training" / "planner.json").read_text()) for r in "ab"]
    assert report[0] == report[1] and report[1]["decisions"] > 0
    a, b = load_file(tmp_path / "a" / "model.safetensors"), load_file(tmp_path / "b" / "model.safetensors")
    # same batches, optimiser, RNGs and memory store: bit for bit
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    rows = (tmp_path / "b" / "training" / "loss.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == [str(i) for i in range(1, 7)]
    with pytest.raises(TrainingError, match="other arguments"):
        train_tiny(mn_dataset, tmp_path / "b", steps=6, seed=1)



def test_checkpoint_holds_the_ema_weights(dataset, tmp_path):
    from safetensors.torch import load_file

    train_tiny(dataset, tmp_path / "e", steps=3, cfg=replace(TINY, ema=True))
    state = torch.load(tmp_path / "e" / "training" / "state.pt", weights_only=True)["model"]
    exported = load_file(tmp_path / "e" / "model.safetensors")
    k = "executor.head.out.weight"
    assert torch.equal(exported[k], state[f"ema.averaged.{k}"])
    assert not torch.equal(exported[k], state[f"model.{k}"])


def test_action_patches_carry_consecutive_actions():
    from rmbench.policies.mem0.action_head import FlowMatchingHead

    torch.manual_seed(0)
    # a token must be wide enough to carry its patch's noisy actions (3 x 14 here)
    head = FlowMatchingHead(64, horizon=6, action_dim=14, layers=1, heads=2, patch=3)
    assert head.pos.shape == (2, 64) and head.inp.in_features == 3 * 14  # 6 actions, 2 tokens
    # the chunk comes back in order: a patched head fits one chunk with a ramp along time
    cond = torch.randn(1, 2, 64)
    target = torch.linspace(-1, 1, 6)[None, :, None].expand(1, 6, 14)
    opt = torch.optim.Adam(head.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(0)
    for _ in range(300):
        loss = head.loss(cond.expand(64, -1, -1), target.expand(64, -1, -1),
                         torch.zeros(64, 6, dtype=torch.bool), gen)
        opt.zero_grad()
        loss.backward()
        opt.step()
    chunk = head.sample(cond, steps=10, generator=gen)
    assert chunk.shape == (1, 6, 14)
    assert (chunk - target).abs().max() < 0.2, chunk[0, :, 0]
    with pytest.raises(ValueError, match="action_patch"):
        Mem0Config(horizon=30, action_patch=4)


def test_a_run_from_before_a_config_field_resumes_with_its_default(dataset, tmp_path,
                                                                   interrupt_training):
    interrupt_training(lambda: train_tiny(dataset, tmp_path / "r", steps=6))
    path = tmp_path / "r" / "training" / "state.pt"
    state = torch.load(path, weights_only=True)
    identity = json.loads(state["identity"])
    del identity["describe"]["config"]["ema"]  # as a run saved before the field existed
    state["identity"] = json.dumps(identity, sort_keys=True)
    torch.save(state, path)
    with pytest.raises(TrainingError, match=r"\(describe.config.ema False there, True asked\)"):
        train_tiny(dataset, tmp_path / "r", steps=6, cfg=replace(TINY, ema=True))
    assert train_tiny(dataset, tmp_path / "r", steps=6)["resumed_from"] == 3

# ------------------------------------------------------------------ checkpoints and the loop
def round_trip(path, env):
    """The actions of the checkpoint at ``path`` loaded, and of the model its training held in
    memory when it saved it, over the same steps."""
    loaded = Mem0Policy(str(path), env)
    trained = Mem0Policy.from_model(EXPORTED[path], read_config(path, "mem0"), env)
    return [np.stack(roll_out(env, p, seed=100001, steps=6)[1]) for p in (trained, loaded)]


def test_checkpoint_round_trip_gives_identical_actions(mn_ckpt):
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    runs_ = round_trip(mn_ckpt, env)
    env.close()
    np.testing.assert_array_equal(runs_[0], runs_[1])
    assert runs_[0].shape == (6, 14) and np.isfinite(runs_[0]).all()
    # its env renders the cameras the checkpoint was trained on, at their frames' resolution
    # (the test dataset's 64x48), read from its config.json
    assert env_options(f"mem0:{mn_ckpt}") == {"cameras": TINY.cameras, "width": 64, "height": 48}


def test_bad_checkpoints_give_one_line_errors(mn_ckpt, tmp_path):
    import shutil
    bad = tmp_path / "bad"
    shutil.copytree(mn_ckpt, bad)
    data = (bad / "model.safetensors").read_bytes()
    (bad / "model.safetensors").write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt weights"):
        Mem0Policy(str(bad))
    with pytest.raises(CheckpointError, match="not a checkpoint"):
        Mem0Policy(str(tmp_path / "nothing"))
    with pytest.raises(CheckpointError, match="trained without no_anchor"):
        Mem0Policy(f"{mn_ckpt}?ablation=no_anchor")
    with pytest.raises(ValueError, match="unknown option 'speed'; options: ablation, execute, flow_steps"):
        Mem0Policy(f"{mn_ckpt}?speed=2")
    with pytest.raises(ValueError, match="unknown ablation"):
        Mem0Policy(f"{mn_ckpt}?ablation=no_brain")
    with pytest.raises(CheckpointError, match="execute"):
        Mem0Policy(f"{mn_ckpt}?execute=99")
    env = make("press_button", render=False)
    cfg = Mem0Policy(f"{mn_ckpt}?execute=2&flow_steps=3&ablation=gt_classifier", env).cfg
    assert (cfg.execute, cfg.flow_steps, cfg.gt_classifier) == (2, 3, True)
    env.close()
    env = make("put_back_block", render=False)
    with pytest.raises(CheckpointError, match="trained on press_button"):
        Mem0Policy(str(mn_ckpt), env)
    env.close()


def test_mem0_through_the_evaluation_harness(mn_ckpt, tmp_path):
    from rmbench.eval import EvalConfig, evaluate
    from rmbench.eval.records import read_records

    out = []
    for name in ("a", "b"):
        evaluate(EvalConfig(("press_button",), f"mem0:{mn_ckpt}?ablation=gt_classifier",
                            tmp_path / name, episodes=1, video="none", progress=False,
                            seed_cache=tmp_path / "seeds"))
        (rec,) = read_records(tmp_path / name / "press_button" / "episodes.jsonl")
        rec.pop("wall_s")
        out.append(rec)
    assert out[0] == out[1] and out[0]["reason"] != "policy_error", out[0]
    # its status, the subtask it is on, is recorded from the first step: the planner's choice
    texts = json.loads((mn_ckpt / "config.json").read_text())["executor_texts"]
    first = next(e for e in out[0]["events"] if e[1] == "policy")
    assert first[:3] == [0, "policy", "subtask"] and first[3] in texts


def test_train_cli_errors(mn_dataset, tmp_path, capsys):
    from rmbench.cli.main import main
    base = ["train", "mem0", "--dataset", str(mn_dataset), "--out", str(tmp_path / "x")]
    assert main(base + ["--ablation", "gt_classifier"]) == 2
    assert "not a training ablation" in capsys.readouterr().err
    assert main(base + ["--set", "nope=1"]) == 2
    assert "unknown config field" in capsys.readouterr().err
    assert main(base + ["--set", "dim=x"]) == 2
    assert "dim must be int, got str 'x'" in capsys.readouterr().err
    assert main(base + ["--set", "heads=0"]) == 2
    assert "must be divisible by heads 0 (>= 1)" in capsys.readouterr().err
    assert main(["train", "mem0", "--dataset", str(tmp_path / "none"), "--out", str(tmp_path / "y")]) == 2


def test_vlm_planner_backend_trains_with_lora(mn_dataset, tmp_path):
    """The upgrade path on a tiny random Llama: LoRA adapters train, the base stays frozen,
    and the checkpoint round-trips into a working policy."""
    pytest.importorskip("peft")
    # keys on their end frames: 40 steps are too few to also learn late ones
    cfg = replace(TINY, planner_backend="vlm", planner_steps=40, planner_lr=3e-3, planner_key_delay=0)
    train_tiny(mn_dataset, tmp_path / "v", steps=1, cfg=cfg)
    report = json.loads((tmp_path / "v" / "training" / "planner.json").read_text())
    # above what no learning reaches: the best constant answer's accuracy on these decisions,
    # and the loss of a uniform guess over the candidates
    ds = Dataset(mn_dataset)
    episodes = [ds.episode(e, cameras=[]) for e in range(ds.num_episodes)]
    targets = [x.target for e, ep in enumerate(episodes)
               for x in planner_examples(e, ep.subtask_index, ep.subtask_step, -1)]
    constant = max(targets.count(t) for t in set(targets)) / len(targets)
    candidates = len(json.loads((tmp_path / "v" / "config.json").read_text())["planner_texts"])
    assert report["decisions"] == len(targets)
    assert report["train_accuracy"] > constant, (report, constant)
    assert report["final_loss"] < math.log(candidates), report
    from rmbench.policies.mem0.agent import load_mem0
    model, _, _ = load_mem0(tmp_path / "v")
    lm = model.planner.lm
    trainable = {n for n, p in lm.named_parameters() if p.requires_grad}
    assert trainable and all("lora_" in n for n in trainable)
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(str(tmp_path / "v"), env)
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    assert policy.act(obs).shape == (14,)
    env.close()


def test_open_loop_error_walks_the_agent_over_recorded_frames(mn_ckpt, mn_dataset, dataset):
    from rmbench.eval.open_loop import open_loop_error

    hold = open_loop_error("noop", str(mn_dataset), [0, 1])
    # holding still is its own reference, frame for frame
    assert hold["error"] == pytest.approx(hold["hold_error"], abs=1e-12) and hold["error"] > 0
    assert [r["frames"] for r in hold["episodes"]] == [
        len(Dataset(mn_dataset).episode(e, cameras=[]).action) for e in (0, 1)]
    mem0 = open_loop_error(f"mem0:{mn_ckpt}", str(mn_dataset), [1])
    assert mem0["hold_error"] == hold["episodes"][1]["hold_error"]
    assert np.isfinite(mem0["error"]) and mem0["error"] != mem0["hold_error"]
    with pytest.raises(ValueError, match="episode 5 is not in"):
        open_loop_error("noop", str(mn_dataset), [5])
    other = Dataset(dataset).task  # another task's demonstrations are refused
    assert other != Dataset(mn_dataset).task
    with pytest.raises(ValueError, match=f"was trained on {Dataset(mn_dataset).task}, not {other}"):
        open_loop_error(f"mem0:{mn_ckpt}", str(dataset), [0])


# ------------------------------------------------------------------ the state observation
TINY_STATE = replace(TINY, observation="state", state_hidden=32)


@pytest.fixture
def no_frames(monkeypatch):
    """Any frame decoded or read from the frame cache fails the test."""
    from rmbench.data import reader
    from rmbench.data.torch_dataset import FrameCache

    def boom(*args, **kw):
        raise AssertionError("a state policy read a camera frame")

    monkeypatch.setattr(reader, "decode_video", boom)
    monkeypatch.setattr(FrameCache, "frames", boom)


@pytest.fixture(scope="module")
def mn_state_ckpt(mn_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("ckpt") / "mn_state"
    with keep_exports():
        train_tiny(mn_dataset, out, cfg=TINY_STATE)
    return out


def test_state_executor_trains_without_frames(dataset, tmp_path, no_frames):
    import csv

    train_tiny(dataset, tmp_path / "s", steps=60, cfg=TINY_STATE, batch_size=16, save_every=60)
    rows = [float(r["loss/action"]) for r in csv.DictReader(open(tmp_path / "s" / "training" / "loss.csv"))]
    assert np.mean(rows[-10:]) < 0.8 * np.mean(rows[:5]), (rows[:5], rows[-10:])
    describe = json.loads((tmp_path / "s" / "config.json").read_text())
    assert describe["config"]["observation"] == "state"
    assert describe["state_names"] == Dataset(dataset).state_names


def test_state_planner_and_memories_hold_state_embeddings(mn_state_ckpt, mn_dataset):
    report = json.loads((mn_state_ckpt / "training" / "planner.json").read_text())
    # one decision per plan step (d1 + d2 pushes and the confirm) and the final "done"
    hidden = [ep["rmbench/hidden"] for ep in Dataset(mn_dataset).episodes]
    assert report["decisions"] == sum(h["d1"] + h["d2"] + 2 for h in map(json.loads, hidden))
    env = make("press_button", obs_type="environment_state_agent_pos")
    policy = Mem0Policy(f"{mn_state_ckpt}?ablation=gt_classifier", env)
    assert policy_cameras(f"mem0:{mn_state_ckpt}") == ()  # the env need not render
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    model, inputs = policy.model, policy.inputs(obs)
    assert [x.shape for x in inputs] == [(1, len(Dataset(mn_dataset).state_names)), (1, 14)]
    policy.act(obs)
    tokens, _ = model.executor.encode(inputs)
    assert policy.memories[0].anchor.shape == (1, TINY_STATE.state_tokens, TINY_STATE.dim)
    assert torch.allclose(policy.memories[0].anchor[0], tokens[0])  # the subtask's first step
    torch.testing.assert_close(policy.first, model.planner.embed(inputs))  # o_0 for the planner
    obs, *_ = env.step(np.asarray(obs["agent_pos"]))
    policy.subtask_ended(policy.inputs(obs))  # a key memory entry: the end frame's state
    torch.testing.assert_close(policy.keys[-1][1], model.planner.embed(policy.inputs(obs))[0])
    env.close()


def test_state_checkpoint_round_trip_and_the_pixel_observation_error(mn_state_ckpt):
    env = make("press_button", obs_type="environment_state_agent_pos")
    runs_ = round_trip(mn_state_ckpt, env)
    env.close()
    np.testing.assert_array_equal(runs_[0], runs_[1])
    assert runs_[0].shape == (6, 14) and np.isfinite(runs_[0]).all()
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(str(mn_state_ckpt), env)
    obs, _ = env.reset(seed=100001)
    with pytest.raises(ValueError, match="no 'environment_state'.*environment_state_agent_pos"):
        policy.act(obs)
    env.close()


def test_inference_runs_on_one_thread_whatever_the_process_has(mn_state_ckpt):
    """A thread count changes a float reduction's order, and a closed loop turns the last bit
    into another episode: act() runs on INFERENCE_THREADS and gives the caller's count back."""
    from rmbench.policies.nn.inference import INFERENCE_THREADS

    env = make("press_button", obs_type="environment_state_agent_pos")
    policy = Mem0Policy(str(mn_state_ckpt), env)
    obs, info = env.reset(seed=100001)
    env.close()
    policy.reset(info["instruction"], {"seed": 100001})
    seen = []
    encode = policy.model.executor.encode
    policy.model.executor.encode = lambda inputs: (seen.append(torch.get_num_threads()),
                                                   encode(inputs))[1]
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        policy.act(obs)
        assert seen == [INFERENCE_THREADS] and torch.get_num_threads() == 2
        policy.model.executor.encode = lambda inputs: 1 / 0
        with pytest.raises(ZeroDivisionError):
            policy.act(obs)
        assert torch.get_num_threads() == 2  # restored on an error too
    finally:
        torch.set_num_threads(before)


def test_state_mem0_through_the_evaluation_harness(mn_state_ckpt, tmp_path):
    from rmbench.eval import EvalConfig, evaluate
    from rmbench.eval.records import read_records

    spec = f"mem0:{mn_state_ckpt}?ablation=gt_classifier"
    assert env_options(spec) == {"obs_type": "environment_state_agent_pos"}
    evaluate(EvalConfig(("press_button",), spec, tmp_path / "e", episodes=1, video="none",
                        progress=False, seed_cache=tmp_path / "seeds"))
    (rec,) = read_records(tmp_path / "e" / "press_button" / "episodes.jsonl")
    assert rec["reason"] in ("success", "task_failure", "timeout"), rec


def state_training_batch(dataset):
    """A state dataset's names, the ``describe`` a Mem-0 model is built with, and one
    episode-ordered training batch of 64 frames."""
    from rmbench.data.torch_dataset import EpisodeOrderSampler
    from rmbench.policies.mem0.train import Mem0Frames, goal_text
    from rmbench.training.batches import batch_stream

    ds = Dataset(dataset)
    names = ds.state_names
    texts = list(ds.subtasks) + [goal_text(ds.task)]
    describe = {"executor_texts": texts, "planner_texts": list(ds.subtasks) + ["done"],
                "text_encoder": "learned", "state_names": names}
    frames = Mem0Frames(ds, TINY_STATE, False, len(texts) - 1)
    return names, describe, next(batch_stream(frames, EpisodeOrderSampler(frames, 64, seed=0), 0))


def test_state_noise_moves_object_positions_only(dataset):
    """state_noise perturbs the environment state's *_x/_y/_z entries of what the encoder reads
    in training, nothing else, by about the asked std; without it the inputs are untouched."""
    from rmbench.data import layout as L
    from rmbench.policies.mem0.modeling import Mem0Trainer
    from rmbench.policies.mem0.train import build_model

    names, describe, batch = state_training_batch(dataset)
    position = torch.tensor([n.endswith(("_x", "_y", "_z")) for n in names])
    assert position.any() and not position.all()
    for noise in (0.0, 0.01):
        cfg = replace(TINY_STATE, state_noise=noise)
        model = build_model(cfg, describe)
        seen = []
        encode = model.executor.encode
        model.executor.encode = lambda inputs, encode=encode, seen=seen: (seen.append(inputs),
                                                                       encode(inputs))[1]
        Mem0Trainer(model, 64, False, 0, names)(batch)
        delta = seen[0][0] - batch[L.ENV_STATE]
        assert torch.equal(seen[0][1], batch[L.STATE])
        assert torch.equal(delta[:, ~position], torch.zeros_like(delta[:, ~position]))
        assert float(delta[:, position].std()) == pytest.approx(noise, rel=0.1, abs=1e-9)
    with pytest.raises(ValueError, match="state_noise"):
        replace(TINY_STATE, state_noise=-0.01)
    # state_noise_on narrows it to the entries with those name prefixes
    model = build_model(replace(TINY_STATE, state_noise=0.01, state_noise_on=("object0_",)), describe)
    trainer = Mem0Trainer(model, 64, False, 0, names)
    chosen = torch.tensor([n.startswith("object0_") for n in names]) & position
    assert chosen.any() and (position & ~chosen).any()
    assert torch.equal(trainer.noise_scale != 0, chosen)
    # joint_noise moves the twelve arm joints the encoder reads, not the grippers
    model = build_model(replace(TINY_STATE, joint_noise=0.02), describe)
    seen = []
    encode = model.executor.encode
    model.executor.encode = lambda inputs: (seen.append(inputs), encode(inputs))[1]
    Mem0Trainer(model, 64, False, 0, names)(batch)
    delta = seen[0][1] - batch[L.STATE]
    assert torch.equal(delta[:, [6, 13]], torch.zeros_like(delta[:, [6, 13]]))
    joints = delta[:, [k for k in range(14) if k not in (6, 13)]]
    assert float(joints.std()) == pytest.approx(0.02, rel=0.1)
    assert torch.equal(seen[0][0], batch[L.ENV_STATE])
    with pytest.raises(ValueError, match="joint_noise"):
        replace(TINY_STATE, joint_noise=-1.0)
    # memory_noise blurs the chosen positions of what the anchor and the sliding window store,
    # the current step's input exact
    model = build_model(replace(TINY_STATE, memory_noise=0.01, memory_noise_on=("object0_",)),
                        describe)
    seen = []
    encode = model.executor.encode
    model.executor.encode = lambda inputs: (seen.append(inputs), encode(inputs))[1]
    trainer = Mem0Trainer(model, 64, False, 0, names)
    trainer(batch)
    assert len(seen) == 2 and torch.equal(seen[0][0], batch[L.ENV_STATE])
    delta = seen[1][0] - batch[L.ENV_STATE]
    assert torch.equal(delta[:, ~chosen], torch.zeros_like(delta[:, ~chosen]))
    assert float(delta[:, chosen].std()) == pytest.approx(0.01, rel=0.15)
    anchor, _ = encode(seen[1])
    torch.testing.assert_close(trainer.memory.anchor, anchor)  # every slot starts an episode
    with pytest.raises(ValueError, match="memory_noise"):
        replace(TINY, memory_noise=0.01)  # pixels


def test_shuffle_entities_trades_whole_objects_between_slots(dataset):
    """shuffle_entities: what the encoder reads in training holds the same five objects, each
    with all of its entries, in a new slot order per frame; every other entry stays exact;
    nothing moves without it, and a stem that names no entities is a one-line error."""
    from rmbench.data import layout as L
    from rmbench.policies.mem0.modeling import Mem0Trainer
    from rmbench.policies.mem0.train import build_model

    names, describe, batch = state_training_batch(dataset)
    state = batch[L.ENV_STATE]
    slots = [[i for i, n in enumerate(names) if n.startswith(f"object{k}_")] for k in range(5)]
    rest = [i for i in range(len(names)) if not any(i in s for s in slots)]
    assert len({len(s) for s in slots}) == 1 and rest
    model = build_model(replace(TINY_STATE, shuffle_entities=("object",)), describe)
    seen = []
    encode = model.executor.encode
    model.executor.encode = lambda inputs: (seen.append(inputs), encode(inputs))[1]
    Mem0Trainer(model, 64, False, 0, names)(batch)
    read = seen[0][0]
    assert torch.equal(read[:, rest], state[:, rest])
    moved = 0
    for row in range(len(state)):
        came_from = []
        for slot in slots:
            match = [k for k, other in enumerate(slots)
                     if torch.equal(read[row, slot], state[row, other])]
            assert match, "an object's entries were split or changed"
            came_from.append(match[0])
        assert sorted(came_from) == list(range(5))
        moved += came_from != list(range(5))
    assert moved > len(state) // 2  # a fresh order per frame, mostly not the recorded one
    assert Mem0Trainer(build_model(TINY_STATE, describe), 64, False, 0, names).exchange is None
    with pytest.raises(ValueError, match="'cube' names 0 entities"):
        Mem0Trainer(build_model(replace(TINY_STATE, shuffle_entities=("cube",)), describe),
                    64, False, 0, names)
    with pytest.raises(ValueError, match="shuffle_entities"):
        replace(TINY, observation="pixels", shuffle_entities=("object",))


def test_relabel_one_hots_renames_a_value_in_every_entity_of_the_frame(dataset):
    """relabel_one_hots: per frame, one renaming of the colours applied to the five objects and
    the reference alike, so which objects share a colour with the reference is kept; every
    other entry is exact; a category with no entries is a one-line error."""
    from rmbench.policies.observation import exchange_groups, shuffle_groups

    ds = Dataset(dataset)
    names = list(ds.state_names)
    state = torch.as_tensor(np.concatenate([ds.episode(i, []).environment_state for i in range(2)]))
    colours = ("red", "green", "blue", "yellow")
    owners = [f"object{k}" for k in range(5)] + ["reference"]
    cells = [[names.index(f"{o}_colour_{c}") for c in colours] for o in owners]
    groups = exchange_groups(replace(TINY_STATE, relabel_one_hots=("colour",)), names)
    read = shuffle_groups(state, groups, torch.Generator().manual_seed(0))
    rest = [i for i in range(len(names)) if not any(i in row for row in cells)]
    assert torch.equal(read[:, rest], state[:, rest])
    renamed = 0
    for before, after in zip(state, read, strict=True):
        rename = {}
        for row in cells:
            old, new = before[row], after[row]
            assert old.sum() == new.sum()  # a shown colour stays shown, a hidden one hidden
            if old.sum():
                a, b = int(old.argmax()), int(new.argmax())
                assert rename.setdefault(a, b) == b  # one renaming for the whole frame
        assert len(set(rename.values())) == len(rename)
        renamed += any(a != b for a, b in rename.items())
    assert renamed > len(state) // 2
    with pytest.raises(ValueError, match="'size' names 0 entities"):
        exchange_groups(replace(TINY_STATE, relabel_one_hots=("size",)), names)


def test_ee_actions_train_and_run_as_joint_targets(dataset, tmp_path):
    """action_space "ee": the head predicts 20-number grasp poses, the policy hands the env 14
    joint targets, and a joint-relative setting is refused."""
    with pytest.raises(ValueError, match="relative_actions"):
        Mem0Config(action_space="ee")
    cfg = replace(TINY_STATE, action_space="ee", relative_actions=False)
    train_tiny(dataset, tmp_path / "ee", cfg=cfg)
    policy = Mem0Policy(str(tmp_path / "ee"))
    assert policy.model.executor.normalizer.action_min.shape == (20,)
    env = make(Dataset(dataset).task, obs_type="environment_state_agent_pos")
    obs, info = env.reset(seed=100000)
    env.close()
    policy.reset(info["instruction"], {"seed": 100000})
    actions = np.stack([policy.act(obs) for _ in range(5)])  # two chunks of execute=4
    assert actions.shape == (5, 14) and np.isfinite(actions).all()
    low, high = policy.ee.kin.low["left"], policy.ee.kin.high["left"]
    assert np.all(actions[:, :6] >= low) and np.all(actions[:, :6] <= high)


def test_sample_noise_zero_samples_one_chunk_whatever_the_generator():
    from rmbench.policies.mem0.action_head import FlowMatchingHead

    torch.manual_seed(0)
    head = FlowMatchingHead(16, 6, 14, layers=1, heads=2).eval()
    cond = torch.randn(1, 3, 16)
    draws = [head.sample(cond, 3, torch.Generator().manual_seed(s), noise=n)
             for n in (0.0, 1.0) for s in (1, 2)]
    torch.testing.assert_close(draws[0], draws[1])
    assert not torch.allclose(draws[2], draws[3])
    with pytest.raises(ValueError, match="sample_noise"):
        Mem0Config(sample_noise=-1.0)


def test_temporal_ensemble_averages_the_chunks_that_cover_a_step(mn_state_ckpt):
    """temporal_ensemble: a chunk every ensemble_every steps (not every execute), each step the
    exp(-m i)-weighted mean of the chunks covering it; a new subtask starts afresh."""
    env = make("press_button", obs_type="environment_state_agent_pos")
    policy = Mem0Policy(f"{mn_state_ckpt}?temporal_ensemble=0.5&ensemble_every=3", env)
    obs, info = env.reset(seed=100000)
    env.close()
    policy.reset(info["instruction"], {"seed": 100000})
    horizon = policy.cfg.horizon
    asked = []

    def chunks(c, observations, due, length):
        asked.extend((policy.t, length) for _ in due)
        return {i: np.full((length, 14), float(len(asked))) for i in due}

    policy.chunks = chunks
    policy.end_probabilities = lambda c, z: torch.zeros(len(z))
    out = [policy.act(obs)[0] for _ in range(horizon + 1)]
    assert asked == [(t, horizon) for t in range(0, horizon + 1, 3)]
    w = np.exp(-0.5 * np.arange(3))
    assert out[0] == out[1] == out[2] == 1.0
    assert out[3] == pytest.approx((w[:2] @ [1, 2]) / w[:2].sum())
    # at step 8 (the horizon) the chunk of step 0 has run out; those of steps 3 and 6 cover it
    assert out[horizon] == pytest.approx((w[:2] @ [2, 3]) / w[:2].sum())
    policy.start_subtask = True
    assert policy.act(obs)[0] == float(len(asked)) and asked[-1][0] == horizon + 1
    with pytest.raises(ValueError, match="ensemble_every"):
        replace(TINY_STATE, ensemble_every=TINY_STATE.horizon + 1)
    with pytest.raises(ValueError, match="temporal_ensemble"):
        replace(TINY_STATE, temporal_ensemble=-1.0)


def test_reach_input_reads_positions_as_the_arms_reach_joints(dataset, tmp_path):
    """reach_input: the named positions of the environment state enter the encoder as both
    arms' top-down reach joints, normalised over the dataset; a name without _x/_y entries
    is a one-line error, and pixels refuse the option."""
    from rmbench.policies.nn.state import reach_joints

    cfg = replace(TINY_STATE, reach_input=("object1", "object0"))
    train_tiny(dataset, tmp_path / "r", cfg=cfg)
    policy = Mem0Policy(str(tmp_path / "r"))
    encoder = policy.model.executor.encoders
    names = Dataset(dataset).state_names
    assert encoder.reach_index.tolist() == [[names.index("object1_x"), names.index("object1_y")],
                                            [names.index("object0_x"), names.index("object0_y")]]
    ds = Dataset(dataset)
    env = np.concatenate([ds.episode(e, cameras=[]).environment_state
                          for e in range(ds.num_episodes)])
    joints = reach_joints(env[:, encoder.reach_index.numpy()])
    assert joints.shape == (len(env), 2 * 12)
    torch.testing.assert_close(encoder.reach_mean, torch.as_tensor(joints.mean(0)), atol=1e-5,
                               rtol=1e-5)
    state = torch.as_tensor(env[:2])
    agent = torch.zeros(2, 14)
    moved = state.clone()
    moved[:, names.index("object0_x")] += 0.05
    assert not torch.allclose(encoder([state, agent]), encoder([moved, agent]))
    with pytest.raises(ValueError, match=r"reach_input \['lamp'\] has no _x/_y"):
        train_tiny(dataset, tmp_path / "bad", cfg=replace(TINY_STATE, reach_input=("lamp",)))
    with pytest.raises(ValueError, match="reach_input"):
        Mem0Config(observation="pixels", reach_input=("cube",))


def test_grasp_pose_input_reads_the_joints_forward_kinematics(dataset, tmp_path):
    from rmbench.policies.action_space import EEActions

    cfg = replace(TINY_STATE, action_space="ee", relative_actions=False, grasp_pose_input=True)
    train_tiny(dataset, tmp_path / "g", cfg=cfg)
    policy = Mem0Policy(str(tmp_path / "g"))
    encoder = policy.model.executor.encoders
    ds = Dataset(dataset)
    state = np.concatenate([ds.episode(e, cameras=[]).state for e in range(ds.num_episodes)])
    poses = EEActions().from_joints(state)  # over the whole dataset
    torch.testing.assert_close(encoder.pose_mean, torch.as_tensor(poses.mean(0)), atol=1e-5,
                               rtol=1e-5)
    env_state = torch.zeros(2, encoder.state_dim)
    joints = torch.as_tensor(state[:2])
    moved = joints.clone()
    moved[:, 0] += 0.1  # a waist turn moves the left grasp pose, hence the tokens
    assert not torch.allclose(encoder([env_state, joints]), encoder([env_state, moved]))
    with pytest.raises(ValueError, match="grasp_pose_input"):
        Mem0Config(observation="pixels", grasp_pose_input=True)
    # without the option the weights are those of a checkpoint from before it existed
    from rmbench.policies.nn.state import StateEncoder

    assert not any("pose" in k for k in StateEncoder(4, 8).state_dict())


def test_layout_copies_train_on_demonstrations_moved_across_the_table(dataset, tmp_path):
    """A shifted copy moves every x/y entry of the environment state by the shift and each
    grasp site's path with it (scaled down near the rest pose), turns the wrist with the
    reach direction rather than rolling the forearm, and keeps the grippers; training reads
    the copies beside the demonstrations."""
    from rmbench.data.layout_shift import REST_RADIUS, LayoutShift, xy_columns
    from rmbench.sim.kinematics import GraspKinematics
    from rmbench.sim.station import HOME_ARM

    ds = Dataset(dataset)
    ep = ds.episode(0, cameras=[])
    delta = np.array([0.02, -0.015])
    moved = LayoutShift(ds.state_names).shift(ep, delta)
    xs, ys = xy_columns(ds.state_names)
    np.testing.assert_allclose(moved.environment_state[:, xs] - ep.environment_state[:, xs],
                               delta[0], atol=1e-6)
    np.testing.assert_allclose(moved.environment_state[:, ys] - ep.environment_state[:, ys],
                               delta[1], atol=1e-6)
    kin = GraspKinematics()
    for k, side in enumerate(("left", "right")):
        rest = kin.forward(side, np.asarray(HOME_ARM[side], float))[0]
        cols = slice(7 * k, 7 * k + 6)
        for t in range(0, len(ep), 7):
            before = kin.forward(side, ep.action[t, cols])[0]
            after = kin.forward(side, moved.action[t, cols])[0]
            w = np.clip(np.linalg.norm(before - rest) / REST_RADIUS - 1, 0, 1)
            np.testing.assert_allclose(after - before, [*(w * delta), 0.0], atol=3e-3)
        assert np.abs(moved.action[:, 7 * k + 3] - ep.action[:, 7 * k + 3]).max() < 0.02
    np.testing.assert_array_equal(moved.action[:, [6, 13]], ep.action[:, [6, 13]])
    assert LayoutShift(ds.state_names).shift(ep, (5.0, 0.0)) is None  # out of reach: no copy

    cfg = replace(TINY_STATE, layout_copies=2, layout_shift=0.02)
    train_tiny(dataset, tmp_path / "s", cfg=cfg)
    describe = json.loads((tmp_path / "s" / "config.json").read_text())
    assert 0 < describe["layout_copies_kept"] <= 2 * ds.num_episodes
    with pytest.raises(ValueError, match="layout_copies"):
        Mem0Config(observation="pixels", layout_copies=1, layout_shift=0.01)
    with pytest.raises(ValueError, match="layout_copies"):
        replace(TINY_STATE, layout_copies=-1)


def test_the_executor_digest_reads_the_executor_alone_scalars_included():
    weights = {"executor.scale": torch.tensor(1.5), "executor.w": torch.zeros(2, 3),
               "executor.empty": torch.zeros(0), "planner.w": torch.ones(2)}
    digest = executor_digest(weights)
    weights["planner.w"] += 1  # the planner is the ablation's own
    assert executor_digest(weights) == digest
    weights["executor.scale"] += 1
    assert executor_digest(weights) != digest


def test_a_dataset_of_one_plan_step_per_episode_is_refused(mn_dataset, tmp_path, monkeypatch):
    """An M(n) dataset whose task counted none of its steps (battery_try-v3 under action
    noise) leaves the planner nothing to decide: a one-line error, not a trained planner."""
    read = Dataset.episode

    def one_step(self, *args, **kwargs):
        ep = read(self, *args, **kwargs)
        return replace(ep, subtask_index=np.zeros_like(ep.subtask_index),
                       subtask_step=np.zeros_like(ep.subtask_step))

    monkeypatch.setattr(Dataset, "episode", one_step)
    with pytest.raises(ValueError, match="every episode holds one step of its task's plan"):
        train_tiny(mn_dataset, tmp_path / "p", steps=1, cfg=TINY_STATE)


def test_codec_frames_read_the_cameras_through_one_codec_stream_per_episode(mn_ckpt):
    env = make("press_button", cameras=("head", "left_wrist"), width=64, height=48)
    policy = Mem0Policy(f"{mn_ckpt}?codec_frames=true", env)
    seen = []
    inputs = policy.inputs
    policy.inputs = lambda observation: seen.append(observation["pixels"]) or inputs(observation)
    obs, info = env.reset(seed=100000)
    policy.reset(info["instruction"], {"seed": 100000})
    raw = []
    for _ in range(3):
        raw.append(obs["pixels"])
        policy.act(obs)
        obs, *_ = env.step(np.asarray(obs["agent_pos"]))
    codecs = policy.slots[0].codecs
    assert set(codecs) == set(policy.cfg.cameras) and codecs["head"]._pts == 3
    for frames, rendered in zip(seen, raw, strict=True):
        for cam in policy.cfg.cameras:
            assert frames[cam].shape == rendered[cam].shape
            assert not np.array_equal(frames[cam], rendered[cam])  # what the codec keeps
            assert np.abs(frames[cam].astype(int) - rendered[cam].astype(int)).mean() < 8
    policy.reset(info["instruction"], {"seed": 100000})
    assert policy.slots[0].codecs == {}  # a new episode, new streams
    env.close()


def test_codec_frames_is_refused_for_a_state_checkpoint(mn_state_ckpt):
    with pytest.raises(ValueError, match="codec_frames passes camera frames"):
        Mem0Policy(f"{mn_state_ckpt}?codec_frames=true")


def test_a_config_edited_into_another_type_is_an_error_naming_the_checkpoint(mn_ckpt, tmp_path):
    import shutil

    from rmbench.policies.checkpoint import CheckpointError
    from rmbench.policies.mem0.agent import load_mem0

    ckpt = tmp_path / "ckpt"
    shutil.copytree(mn_ckpt, ckpt)
    describe = json.loads((ckpt / "config.json").read_text())
    describe["config"]["heads"] = "4"
    (ckpt / "config.json").write_text(json.dumps(describe))
    with pytest.raises(CheckpointError, match=f"{ckpt}: heads must be int, got str '4'"):
        load_mem0(ckpt)
