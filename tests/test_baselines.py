"""Diffusion Policy and ACT: their parts (DDIM, U-Net, ensembling, observation windows),
training (overfit, resume), checkpoints and the closed loop through the harness."""

import csv
import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from rmbench.data import layout as L
from rmbench.data.torch_dataset import DemoDataset, RandomFrameSampler
from rmbench.envs.registration import make
from rmbench.policies.act.agent import ACTPolicy, train_act
from rmbench.policies.act.config import ACTConfig
from rmbench.policies.checkpoint import CheckpointError
from rmbench.policies.dp.agent import DPPolicy, train_dp
from rmbench.policies.dp.config import DPConfig
from rmbench.policies.nn.diffusion import DDPMSchedule
from rmbench.policies.nn.unet1d import ConditionalUnet1D
from rmbench.policies.registry import env_options, policy_cameras
from rmbench.training.loop import TrainConfig
from tests.conftest import EXPORTED, keep_exports, roll_out

SMALL = {"cameras": ("head", "left_wrist"), "image_size": (48, 64), "encoder_channels": (8, 16, 16),
         "jitter": (0.0, 0.0, 0.0)}
TINY_DP = DPConfig(**SMALL, dim=16, keypoints=4, down_dims=(16, 32), groups=4, horizon=8,
                   execute=4)
TINY_ACT = ACTConfig(**SMALL, dim=32, heads=2, encoder_layers=1, feedforward=64, latent_dim=8,
                     horizon=8, execute=4, dropout=0.0)
BASELINES = {"dp": (TINY_DP, train_dp, DPPolicy), "act": (TINY_ACT, train_act, ACTPolicy)}


def train_tiny(name, dataset, out, steps=6, cfg=None, **kw):
    base, fit, _ = BASELINES[name]
    args = {"steps": steps, "batch_size": 4, "save_every": 3, "log_every": 1, **kw}
    return fit(dataset, out, cfg or base, TrainConfig(**args), progress=False)


@pytest.fixture(scope="module", params=sorted(BASELINES))
def ckpt(request, dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("ckpt") / request.param
    with keep_exports():
        train_tiny(request.param, dataset, out)
    return request.param, out


# ------------------------------------------------------------------ parts
def test_ddim_with_the_true_noise_recovers_the_sample():
    sched = DDPMSchedule(100)
    x0 = torch.rand(2, 8, 3) * 1.6 - 0.8
    acp = sched.alphas_cumprod

    def oracle(x, k):  # the noise that x holds at step k, given x0
        a = acp[k].float().view(-1, 1, 1)
        return (x - a.sqrt() * x0) / (1 - a).sqrt()

    for steps in (1, 7, 10, 30, 60, 100):  # divisors of the 100 training steps or not
        out = sched.ddim_sample(oracle, x0.shape, steps, torch.Generator().manual_seed(0), "cpu")
        torch.testing.assert_close(out, x0, atol=1e-4, rtol=0)
    with pytest.raises(ValueError, match="DDIM steps"):
        sched.ddim_sample(oracle, x0.shape, 101, None, "cpu")


def test_unet_keeps_the_sequence_shape_and_checks_its_length():
    net = ConditionalUnet1D(14, 10, down_dims=(16, 32, 64), groups=4)
    x = torch.randn(3, 16, 14)
    assert net(x, torch.rand(3), torch.randn(3, 10)).shape == x.shape
    with pytest.raises(ValueError, match="divisible by 4"):
        net(torch.randn(3, 10, 14), torch.rand(3), torch.randn(3, 10))
    with pytest.raises(ValueError, match="multiple of 4"):
        DPConfig(horizon=10)


def test_observation_window_repeats_the_first_frame_before_the_start(dataset):
    frames = DemoDataset(dataset, chunk=4, cameras=["head"], history=2)
    first, second = frames[0], frames[1]
    assert first[L.STATE].shape == (2, 14) and first[L.image_key("head")].shape[:2] == (2, 3)
    assert torch.equal(first[L.STATE][0], first[L.STATE][1])
    assert torch.equal(second[L.STATE][0], first[L.STATE][1])
    assert torch.equal(second[L.image_key("head")][0], first[L.image_key("head")][1])


def test_random_frame_stream_resumes_anywhere(dataset):
    frames = DemoDataset(dataset, chunk=4, cameras=[])
    sampler = RandomFrameSampler(frames, 5, seed=3)
    it = sampler.stream(0)
    head = [next(it) for _ in range(7)]
    resumed = sampler.stream(4)
    assert [next(resumed) for _ in range(3)] == head[4:]
    assert all(0 <= i < len(frames) for b in head for i in b)


def ensembled(policy, chunks) -> list[float]:
    """The first entry of the action an episode's steps 0..5 take, given each step's chunk."""
    slot, out = policy.slots[0], []
    for t in range(6):
        slot.t = t
        out.append(policy.take(slot, next(chunks))[0])
    return out


def test_temporal_ensembling_weights_the_oldest_prediction_most():
    torch.manual_seed(0)
    from rmbench.policies.act.modeling import ACTModel

    cfg = replace(TINY_ACT, horizon=4, temporal_ensemble=0.5)
    policy = ACTPolicy.from_model(ACTModel(cfg))
    chunks = iter([np.full((4, 14), v) for v in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)])
    out = ensembled(policy, chunks)
    w = np.exp(-0.5 * np.arange(4))
    assert out[0] == 1.0
    assert out[1] == pytest.approx((w[:2] @ [1, 2]) / w[:2].sum())
    # at step 5 the chunks of steps 2..5 cover it (step 1's has run out)
    assert out[5] == pytest.approx((w @ [3, 4, 5, 6]) / w.sum())
    assert len(policy.slots[0].ensemble.chunks) == 4


def test_an_ensemble_window_averages_only_the_latest_chunks():
    torch.manual_seed(0)
    from rmbench.policies.act.modeling import ACTModel

    cfg = replace(TINY_ACT, horizon=4, temporal_ensemble=0.5, ensemble_window=2)
    policy = ACTPolicy.from_model(ACTModel(cfg))
    chunks = iter([np.full((4, 14), v) for v in (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)])
    out = ensembled(policy, chunks)
    w = np.exp(-0.5 * np.arange(2))
    # at step 5 only the chunks of steps 4 and 5 vote; those of steps 2 and 3 still cover it
    assert out[5] == pytest.approx((w @ [5, 6]) / w.sum())
    for window in (-1, 5):
        with pytest.raises(ValueError, match="ensemble_window"):
            replace(TINY_ACT, horizon=4, ensemble_window=window)


# ------------------------------------------------------------------ training
def sampled_action_error(policy, dataset) -> float:
    """Mean |predicted - demonstrated| over the first ``execute`` actions of every frame,
    through the policy's own observation path and window."""
    cfg = policy.cfg
    frames = DemoDataset(dataset, chunk=cfg.horizon, cameras=list(cfg.cameras),
                         image_size=cfg.image_size)
    errors = []
    with torch.no_grad():
        for e in range(len(frames.lengths)):
            policy.reset("", {"seed": e})
            for t in range(int(frames.lengths[e])):
                item = frames[int(frames.starts[e]) + t]
                state = item[L.STATE][None]
                features = policy.model.observe([item[L.image_key(c)][None] for c in cfg.cameras],
                                                state)
                slot = policy.slots[0]
                slot.window = (slot.window or [features] * cfg.obs_steps)[1:] + [features]
                if t % cfg.execute == 0:
                    chunk = policy.chunks(state, [0])[0][:cfg.execute]
                    errors.append(np.abs(chunk - item[L.ACTION][:cfg.execute].numpy()).mean())
    return float(np.mean(errors))


# (steps, config changes, loss ratio, action-error ratio). DP's noise-prediction loss falls
# more slowly per step than ACT's L1 (measured on this dataset: 1.07 -> 0.34 in 400 steps with
# the default U-Net widths, against ACT's 5.3 -> 0.12 in 300), so it gets more steps, the
# default widths and looser ratios.
OVERFIT = {"dp": (400, {"down_dims": (64, 128, 256)}, 0.5, 0.9),
           "act": (300, {}, 0.3, 0.5)}


@pytest.mark.slow  # hundreds of pixel training steps: minutes of a shared CPU per policy
@pytest.mark.parametrize("name", sorted(BASELINES))
def test_baseline_overfits_a_tiny_dataset(name, dataset, tmp_path):
    base, _, policy_cls = BASELINES[name]
    steps, changes, loss_ratio, error_ratio = OVERFIT[name]
    cfg = replace(base, **changes)
    train_tiny(name, dataset, tmp_path / "init", steps=1, cfg=cfg)
    train_tiny(name, dataset, tmp_path / "fit", steps=steps, cfg=cfg, batch_size=16,
               save_every=steps, log_every=10)
    rows = list(csv.DictReader(open(tmp_path / "fit" / "training" / "loss.csv")))
    first, last = float(rows[0]["loss"]), np.mean([float(r["loss"]) for r in rows[-5:]])
    assert last < loss_ratio * first, (first, last)
    before = sampled_action_error(policy_cls(str(tmp_path / "init")), dataset)
    after = sampled_action_error(policy_cls(str(tmp_path / "fit")), dataset)
    assert after < error_ratio * before, (before, after)


def test_resume_gives_the_weights_of_an_uninterrupted_run(ckpt, dataset, tmp_path,
                                                          interrupt_training):
    from safetensors.torch import load_file

    name, _ = ckpt
    # ACT with dropout on, so that every draw from the global RNG must line up as well
    cfg = replace(TINY_ACT, dropout=0.1) if name == "act" else None
    train_tiny(name, dataset, tmp_path / "a", steps=6, cfg=cfg)
    # killed right after the step-3 checkpoint
    interrupt_training(lambda: train_tiny(name, dataset, tmp_path / "b", steps=6, cfg=cfg))
    assert train_tiny(name, dataset, tmp_path / "b", steps=6, cfg=cfg)["resumed_from"] == 3
    a, b = load_file(tmp_path / "a" / "model.safetensors"), load_file(tmp_path / "b" / "model.safetensors")
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_run_saved_on_a_gpu_elsewhere_resumes_on_the_cpu_here(dataset, tmp_path,
                                                                 interrupt_training):
    from safetensors.torch import load_file

    train_tiny("act", dataset, tmp_path / "a", steps=6)
    interrupt_training(lambda: train_tiny("act", dataset, tmp_path / "b", steps=6))
    # the state a run on a lent GPU machine leaves: its dataset in another folder there, and
    # (as runs saved before the device was left out of a run's identity do) the device named
    path = tmp_path / "b" / "training" / "state.pt"
    state = torch.load(path, weights_only=True)
    identity = json.loads(state["identity"])
    identity["train"]["device"] = "cuda:0"
    identity["describe"]["dataset"]["path"] = "/tmp/t/put_back_block/data"
    torch.save({**state, "identity": json.dumps(identity, sort_keys=True)}, path)
    assert train_tiny("act", dataset, tmp_path / "b", steps=6)["resumed_from"] == 3
    a, b = load_file(tmp_path / "a" / "model.safetensors"), load_file(tmp_path / "b" / "model.safetensors")
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_training_killed_and_resumed_keeps_the_wall_time_of_its_saved_steps(
        dataset, tmp_path, interrupt_training):
    from rmbench.machine import describe

    interrupt_training(lambda: train_tiny("act", dataset, tmp_path / "b", steps=12))
    path = tmp_path / "b" / "training" / "state.pt"
    state = torch.load(path, weights_only=True)
    assert state["step"] == 3 and state["wall_s"] > 0  # the killed piece's saved steps
    result = train_tiny("act", dataset, tmp_path / "b", steps=12)  # three saves in this piece
    assert result["train_wall_from_step"] == 0 and result["machines"] == [describe()]
    assert state["wall_s"] <= result["train_wall_s"] <= state["wall_s"] + result["wall_s"] + 0.1
    # a state saved before wall times were kept: they count from the step it resumes at
    interrupt_training(lambda: train_tiny("act", dataset, tmp_path / "c", steps=6))
    path = tmp_path / "c" / "training" / "state.pt"
    state = torch.load(path, weights_only=True)
    torch.save({k: v for k, v in state.items() if k not in ("wall_s", "wall_from", "machines")},
               path)
    result = train_tiny("act", dataset, tmp_path / "c", steps=6)
    assert result["train_wall_from_step"] == 3 and result["train_wall_s"] <= result["wall_s"] + 0.1


# ------------------------------------------------------------------ checkpoints and the loop
def round_trip(policy_cls, path, env):
    """The actions of the checkpoint at ``path`` loaded, and of the model its training held in
    memory when it saved it, over the same steps."""
    from rmbench.policies.checkpoint import read_config

    trained = policy_cls.from_model(EXPORTED[path], read_config(path))
    return [np.stack(roll_out(env, p, seed=100001, steps=6)[1])
            for p in (trained, policy_cls(str(path), env))]


def test_checkpoint_round_trip_gives_identical_actions(ckpt):
    name, path = ckpt
    policy_cls = BASELINES[name][2]
    env = make("observe_and_pickup", cameras=("head", "left_wrist"), width=64, height=48)
    # an untrained policy may fail the task at once: roll_out stops where the episode ends
    runs = round_trip(policy_cls, path, env)
    env.close()
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0].shape[1] == 14 and np.isfinite(runs[0]).all()


def test_dp_checkpoint_holds_the_ema_weights(dataset, tmp_path):
    from safetensors.torch import load_file

    train_tiny("dp", dataset, tmp_path / "d", steps=3)
    state = torch.load(tmp_path / "d" / "training" / "state.pt", weights_only=True)["model"]
    exported = load_file(tmp_path / "d" / "model.safetensors")
    k = "unet.final.1.weight"
    assert torch.equal(exported[k], state[f"ema.averaged.{k}"])
    assert not torch.equal(exported[k], state[f"model.{k}"])


def test_bad_arguments_give_one_line_errors(ckpt, tmp_path):
    name, path = ckpt
    policy_cls = BASELINES[name][2]
    other = ACTPolicy if name == "dp" else DPPolicy
    with pytest.raises(CheckpointError, match=f"is a '{name}' checkpoint"):
        other(str(path))
    with pytest.raises(ValueError, match="unknown option 'speed'"):
        policy_cls(f"{path}?speed=2")
    with pytest.raises(CheckpointError, match="execute"):
        policy_cls(f"{path}?execute=99")
    env = make("put_back_block", render=False)
    with pytest.raises(CheckpointError, match="trained on observe_and_pickup"):
        policy_cls(str(path), env)
    env.close()
    # the checkpoint records its demonstrations' task version, and refuses another
    env = make("observe_and_pickup", render=False)
    config = json.loads((path / "config.json").read_text())
    assert config["gym_id"] == env.unwrapped.task.gym_id
    (path / "config.json").write_text(json.dumps({**config, "gym_id": "rmbench/Old-v0"}))
    try:
        with pytest.raises(CheckpointError, match=r"trained on rmbench/Old-v0 demonstrations"):
            policy_cls(str(path), env)
    finally:
        (path / "config.json").write_text(json.dumps(config))
        env.close()


def test_a_run_saved_before_checkpoints_recorded_their_task_version_resumes(
        dataset, tmp_path, interrupt_training):
    name = "dp"
    interrupt_training(lambda: train_tiny(name, dataset, tmp_path / "b", steps=6))
    path = tmp_path / "b" / "training" / "state.pt"
    state = torch.load(path, weights_only=True)
    identity = json.loads(state["identity"])
    del identity["describe"]["gym_id"]  # as runs saved before the field were
    state["identity"] = json.dumps(identity)
    torch.save(state, path)
    assert train_tiny(name, dataset, tmp_path / "b", steps=6)["resumed_from"] == 3


def test_baseline_through_the_evaluation_harness(ckpt, tmp_path):
    from rmbench.eval import EvalConfig, evaluate
    from rmbench.eval.records import read_records

    name, path = ckpt
    # the env renders the cameras the checkpoint was trained on, at the resolution of their
    # frames (the test dataset's 64x48), read from its config.json
    assert env_options(f"{name}:{path}") == {"cameras": ("head", "left_wrist"), "width": 64,
                                             "height": 48}
    evaluate(EvalConfig(("observe_and_pickup",), f"{name}:{path}", tmp_path / "e", episodes=1,
                        video="none", progress=False, seed_cache=tmp_path / "seeds"))
    (rec,) = read_records(tmp_path / "e" / "observe_and_pickup" / "episodes.jsonl")
    assert rec["reason"] in ("success", "task_failure", "timeout"), rec


def test_train_cli_for_baselines(dataset, tmp_path, capsys):
    from rmbench.cli.main import main

    base = ["train", "dp", "--dataset", str(dataset), "--out", str(tmp_path / "x")]
    assert main(base + ["--ablation", "no_memory"]) == 2
    assert "Mem-0's" in capsys.readouterr().err
    assert main(base + ["--set", "kl_weight=1"]) == 2  # an ACT field
    assert "unknown config field" in capsys.readouterr().err
    # a value of another type, or one the model cannot take, in one line naming the field
    assert main(base + ["--set", "horizon=x"]) == 2
    assert "horizon must be int, got str 'x'" in capsys.readouterr().err
    act = ["train", "act", "--dataset", str(dataset), "--out", str(tmp_path / "y")]
    assert main(act + ["--set", "heads=0"]) == 2
    assert "must be divisible by heads 0 (>= 1)" in capsys.readouterr().err
    assert main(base + ["--steps", "2", "--batch-size", "2"]) == 2  # 3 cameras asked, 2 recorded
    assert "no ['right_wrist'] camera" in capsys.readouterr().err


# ------------------------------------------------------------------ the state observation
def state_cfg(name):
    return replace(BASELINES[name][0], observation="state", state_hidden=32)


@pytest.fixture(scope="module", params=sorted(BASELINES))
def state_ckpt(request, dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("ckpt") / f"{request.param}_state"
    with keep_exports():
        train_tiny(request.param, dataset, out, cfg=state_cfg(request.param))
    return request.param, out


def test_observation_rule():
    from types import SimpleNamespace

    from rmbench.policies.observation import choose

    both = SimpleNamespace(root="d", cameras=["head"], state_names=["x"])
    assert choose("auto", both) == "pixels" and choose("state", both) == "state"
    assert choose("auto", SimpleNamespace(root="d", cameras=[], state_names=["x"])) == "state"
    with pytest.raises(ValueError, match="no observation.environment_state"):
        choose("state", SimpleNamespace(root="d", cameras=["head"], state_names=None))
    with pytest.raises(ValueError, match="no camera videos"):
        choose("pixels", SimpleNamespace(root="d", cameras=[], state_names=["x"]))
    with pytest.raises(ValueError, match="observation must be one of auto, pixels, state"):
        DPConfig(observation="depth")
    # a checkpoint from before the field reads pixels
    assert not ACTConfig.from_dict({}).reads_state and DPConfig().step_tokens == 3


# (steps, loss ratio): ACT's L1 falls fast; DP's noise loss slowly, as with pixels (at these
# widths and 60 steps: 1.11 -> 1.00 from pixels, 1.15 -> 1.00 from the state)
STATE_FIT = {"dp": (60, 0.95), "act": (40, 0.3)}


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_state_baseline_trains_without_frames(name, dataset, tmp_path, monkeypatch):
    from rmbench.data import reader
    from rmbench.data.torch_dataset import FrameCache

    def boom(*args, **kw):
        raise AssertionError("a state policy read a camera frame")

    monkeypatch.setattr(reader, "decode_video", boom)
    monkeypatch.setattr(FrameCache, "frames", boom)
    steps, ratio = STATE_FIT[name]
    train_tiny(name, dataset, tmp_path / "s", steps=steps, cfg=state_cfg(name), batch_size=16,
               save_every=steps)
    rows = [float(r["loss"]) for r in csv.DictReader(open(tmp_path / "s" / "training" / "loss.csv"))]
    assert np.mean(rows[-10:]) < ratio * np.mean(rows[:5]), (rows[:5], rows[-10:])


def test_act_s_decoder_and_latent_read_the_noisy_joints(dataset):
    """With joint_noise, what ACT's decoder and latent encoder are given is the noisy read of
    the joints, the one its observation encoder saw, not the recorded joints."""
    from rmbench.data.reader import Dataset
    from rmbench.policies.act.modeling import ACTModel, ACTTrainer
    from rmbench.training.batches import batch_stream

    ds = Dataset(dataset)
    names = tuple(ds.state_names)
    cfg = replace(state_cfg("act"), joint_noise=0.02)
    model = ACTModel(cfg, len(names))
    frames = DemoDataset(ds, chunk=cfg.horizon, cameras=[], history=cfg.obs_steps,
                         environment_state=True)
    batch = next(batch_stream(frames, RandomFrameSampler(frames, 16, seed=0), 0))
    seen = {}
    real_latent, real_decode = model.latent, model.decode

    def latent(state, *args):
        seen["latent"] = state
        return real_latent(state, *args)

    def decode(tokens, state, z):
        seen["decode"] = state
        return real_decode(tokens, state, z)

    model.latent, model.decode = latent, decode
    ACTTrainer(model, 0, names).forward(batch)
    recorded = batch[L.STATE].reshape(seen["decode"].shape)
    assert torch.equal(seen["latent"], seen["decode"])
    assert float((seen["decode"] - recorded)[:, :6].std()) == pytest.approx(0.02, rel=0.3)


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_state_noise_reaches_the_baselines_encoder(name, dataset):
    """DP and ACT train with Mem-0's state_noise: the encoder reads the environment state's
    chosen position entries moved by about the asked std, every other entry exactly."""
    from rmbench.data.reader import Dataset
    from rmbench.policies.act.modeling import ACTModel, ACTTrainer
    from rmbench.policies.dp.modeling import DiffusionPolicyModel, DPTrainer
    from rmbench.training.batches import batch_stream

    ds = Dataset(dataset)
    names = tuple(ds.state_names)
    cfg = replace(state_cfg(name), state_noise=0.01, state_noise_on=("object0_",))
    model_cls, trainer_cls = {"dp": (DiffusionPolicyModel, DPTrainer),
                              "act": (ACTModel, ACTTrainer)}[name]
    model = model_cls(cfg, len(names))
    frames = DemoDataset(ds, chunk=cfg.horizon, cameras=[], history=cfg.obs_steps,
                         environment_state=True)
    batch = next(batch_stream(frames, RandomFrameSampler(frames, 64, seed=0), 0))
    seen = []
    model.observe = lambda inputs, state: (seen.append(inputs[0]), torch.zeros(len(state), 1))[1]
    trainer_cls(model, 0, names).observe(batch)
    delta = seen[0] - batch[L.ENV_STATE].reshape(seen[0].shape)
    chosen = torch.tensor([n.startswith("object0_") and n.endswith(("_x", "_y", "_z"))
                           for n in names])
    assert chosen.any() and not chosen.all()
    assert torch.equal(delta[..., ~chosen], torch.zeros_like(delta[..., ~chosen]))
    assert float(delta[..., chosen].std()) == pytest.approx(0.01, rel=0.15)
    # shuffle_entities: the objects trade slots, one order per sample across its window
    model = model_cls(replace(cfg, state_noise=0.0, shuffle_entities=("object",)), len(names))
    seen.clear()
    model.observe = lambda inputs, state: (seen.append(inputs[0]), torch.zeros(len(state), 1))[1]
    trainer_cls(model, 0, names).observe(batch)
    recorded = batch[L.ENV_STATE].reshape(len(batch[L.STATE]), -1, len(names))
    read = seen[0].reshape(recorded.shape)
    slots = [[i for i, n in enumerate(names) if n.startswith(f"object{k}_")] for k in range(5)]
    rest = [i for i in range(len(names)) if not any(i in s for s in slots)]
    assert torch.equal(read[..., rest], recorded[..., rest])
    orders = set()
    for row in range(len(read)):
        # where each slot's object came from, at every step of the sample's window
        came_from = {tuple(next(k for k, other in enumerate(slots)
                                if torch.equal(read[row, t, slot], recorded[row, t, other]))
                           for slot in slots) for t in range(read.shape[1])}
        assert len(came_from) == 1  # one order across the window
        (order,) = came_from
        assert sorted(order) == list(range(5))
        orders.add(order)
    assert len(orders) > 1  # and a fresh one per sample
    # joint_noise: the joint state the encoder reads moves, its target's reference does not
    model = model_cls(replace(cfg, joint_noise=0.02), len(names))
    states = []
    model.observe = lambda inputs, state: (states.append(state), torch.zeros(len(state), 1))[1]
    trainer = trainer_cls(model, 0, names)
    _, last = trainer.observe(batch)
    moved = states[0] - batch[L.STATE].reshape(states[0].shape)
    assert float(moved[:, :6].std()) == pytest.approx(0.02, rel=0.15)
    assert torch.equal(moved[:, 6], torch.zeros_like(moved[:, 6]))
    # the heads that read the joints (ACT's decoder and latent) get the same noisy read
    assert torch.equal(last, states[0].reshape(len(last), -1, last.shape[-1])[:, -1])


@pytest.mark.parametrize("name", sorted(BASELINES))
def test_baselines_read_grasp_poses_and_train_on_layout_copies(name, dataset, tmp_path):
    """Mem-0's state recipe is the baselines' too: the grasp poses as input (normalised over
    the examples, copies included) and demonstrations moved across the table."""
    import json

    from rmbench.data.reader import Dataset

    cfg = replace(state_cfg(name), grasp_pose_input=True, layout_copies=2, layout_shift=0.02)
    train_tiny(name, dataset, tmp_path / "g", cfg=cfg)
    describe = json.loads((tmp_path / "g" / "config.json").read_text())
    ds = Dataset(dataset)
    assert 0 < describe["layout_copies_kept"] <= 2 * ds.num_episodes
    policy = BASELINES[name][2](str(tmp_path / "g"))
    encoder = policy.model.encoders
    assert encoder.poses is not None and float(encoder.pose_std.min()) > 0
    joints = torch.tensor(ds.episode(0, cameras=[]).state[:2])
    moved = joints.clone()
    moved[:, 0] += 0.1  # a waist turn moves the left grasp pose, hence the tokens
    env_state = torch.zeros(2, encoder.state_dim)
    assert not torch.allclose(encoder([env_state, joints]), encoder([env_state, moved]))
    with pytest.raises(ValueError, match="layout_copies"):
        replace(BASELINES[name][0], observation="pixels", layout_copies=1, layout_shift=0.01)


def test_state_checkpoint_round_trip_and_the_pixel_observation_error(state_ckpt):
    name, path = state_ckpt
    policy_cls = BASELINES[name][2]
    env = make("observe_and_pickup", obs_type="environment_state_agent_pos")
    runs = round_trip(policy_cls, path, env)
    env.close()
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0].shape[1] == 14 and np.isfinite(runs[0]).all()
    env = make("observe_and_pickup", cameras=("head", "left_wrist"), width=64, height=48)
    policy = policy_cls(str(path), env)
    assert policy_cameras(f"{name}:{path}") == ()  # a state checkpoint: nothing to render
    obs, _ = env.reset(seed=100001)
    with pytest.raises(ValueError, match="no 'environment_state'.*environment_state_agent_pos"):
        policy.act(obs)
    env.close()


def test_state_baseline_through_the_evaluation_harness(state_ckpt, tmp_path):
    from rmbench.eval import EvalConfig, evaluate
    from rmbench.eval.records import read_records

    name, path = state_ckpt
    assert env_options(f"{name}:{path}") == {"obs_type": "environment_state_agent_pos"}
    evaluate(EvalConfig(("observe_and_pickup",), f"{name}:{path}", tmp_path / "e", episodes=1,
                        video="none", progress=False, seed_cache=tmp_path / "seeds"))
    (rec,) = read_records(tmp_path / "e" / "observe_and_pickup" / "episodes.jsonl")
    assert rec["reason"] in ("success", "task_failure", "timeout"), rec
