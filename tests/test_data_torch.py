"""Training-side access: action chunks, the in-order episode sampler, the frame cache."""

import numpy as np
import pytest
import torch

from rmbench.data import layout as L
from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import DemoDataset, EpisodeOrderSampler


@pytest.fixture(scope="module")
def demos(dataset, tmp_path_factory):
    return DemoDataset(dataset, chunk=30, image_size=(32, 48),
                       cache_dir=tmp_path_factory.mktemp("cache"))


def test_items_hold_action_chunks_padded_at_the_end(demos, dataset):
    ep = Dataset(dataset).episode(0, cameras=[])
    n = len(ep)
    item = demos[0]
    assert item["episode_start"] and item["frame_index"] == 0
    np.testing.assert_array_equal(item[L.ACTION].numpy(), ep.action[:30])
    assert item["observation.images.head"].shape == (3, 32, 48)
    assert item["observation.images.head"].dtype == torch.uint8
    last = demos[n - 5]
    assert last["frame_index"] == n - 5 and not last["episode_start"]
    assert last["action_is_pad"].tolist() == [False] * 5 + [True] * 25
    np.testing.assert_array_equal(last[L.ACTION][5:].numpy(), np.repeat(ep.action[-1:], 25, 0))
    assert demos[n]["episode_index"] == 1 and demos[n]["episode_start"]
    np.testing.assert_array_equal(demos[n - 1][L.STATE].numpy(), ep.state[-1])
    with pytest.raises(IndexError):
        demos[len(demos)]


def test_frame_cache_serves_resized_frames_from_disk(demos):
    cached = sorted(p.name for p in demos.cache.dir.rglob("*.npy"))
    assert cached, "frames were decoded once and cached"
    frames = demos.cache.frames(0, "head")
    assert isinstance(frames, np.memmap) and frames.shape[1:] == (32, 48, 3)
    again = DemoDataset(demos.ds, image_size=(32, 48), cache_dir=demos.cache.dir)
    assert torch.equal(again[3]["observation.images.head"], demos[3]["observation.images.head"])


def test_sampler_walks_each_slot_through_episodes_in_order(demos):
    sampler = EpisodeOrderSampler(demos, batch_size=2, seed=1)
    batches = list(sampler)
    assert len(batches) == len(demos) // 2
    for slot in range(2):
        steps = [demos.locate(b[slot]) for b in batches]
        for (e0, t0), (e1, t1) in zip(steps, steps[1:], strict=False):
            # next frame of the same episode, or frame 0 of another after the last frame
            assert (e1 == e0 and t1 == t0 + 1) or (t1 == 0 and t0 == demos.lengths[e0] - 1)
    assert batches == list(EpisodeOrderSampler(demos, batch_size=2, seed=1))
    sampler.set_epoch(1)
    assert list(sampler) != batches


def test_loader_batches_in_slot_order(demos):
    loader = torch.utils.data.DataLoader(demos, batch_sampler=EpisodeOrderSampler(demos, 2, seed=0))
    batch = next(iter(loader))
    assert batch[L.ACTION].shape == (2, 30, 14) and batch["episode_start"].all()
