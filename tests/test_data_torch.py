"""Training-side access: action chunks, the in-order episode sampler, the frame cache."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from torch.utils.data._utils.collate import default_collate

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
    # another size given the same folder is decoded anew, never served the stored one
    other = DemoDataset(demos.ds, image_size=(16, 24), cache_dir=demos.cache.dir)
    assert other.cache.frames(0, "head").shape[1:] == (16, 24, 3)
    assert demos.cache.frames(0, "head").shape[1:] == (32, 48, 3)  # (its open map)


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


def reference_item(d: DemoDataset, i: int) -> dict[str, torch.Tensor]:
    """Item ``i`` read off its episode one field at a time: what a batch must hold per row."""
    k = int(np.searchsorted(d.starts, i, side="right") - 1)
    t = i - int(d.starts[k])
    ep, n = d.low_dim[k], len(d.low_dim[k])
    seen = np.maximum(np.arange(t - d.history + 1, t + 1), 0) if d.history > 1 else t
    item = {L.STATE: torch.from_numpy(ep.state[seen].copy()),
            L.ACTION: torch.from_numpy(ep.action[np.minimum(np.arange(t, t + d.chunk), n - 1)]),
            "action_is_pad": torch.from_numpy(np.arange(t, t + d.chunk) >= n),
            L.SUBTASK_INDEX: torch.tensor(int(ep.subtask_index[t])),
            L.SUBTASK_END: torch.tensor(bool(ep.subtask_end[t])),
            L.SUBTASK_STEP: torch.tensor(int(ep.subtask_step[t])),
            "task_index": torch.tensor(d.task_index[k]), "episode_index": torch.tensor(ep.index),
            "frame_index": torch.tensor(t), "episode_start": torch.tensor(t < d.stride)}
    if d.environment_state:
        item[L.ENV_STATE] = torch.from_numpy(ep.environment_state[seen].copy())
    for cam in d.cameras:
        frame = np.array(d.cache.frames(d.episode_ids[k], cam)[seen])
        item[L.image_key(cam)] = torch.from_numpy(frame).movedim(-1, -3).contiguous()
    return item


def assert_batch_is_items(d: DemoDataset, indices: list[int]) -> None:
    batch = d.batch(indices)
    expected = default_collate([reference_item(d, i) for i in indices])
    assert batch.keys() == expected.keys()
    for key, value in expected.items():
        assert batch[key].dtype == value.dtype and torch.equal(batch[key], value), key


@pytest.mark.parametrize("options", [{}, {"history": 3, "stride": 4, "environment_state": True}])
def test_a_batch_gathers_what_its_items_hold(demos, options, tmp_path):
    """One gather over the concatenated episodes builds the batch the items would, bit for
    bit, in any order, episode ends and starts included."""
    d = DemoDataset(demos.ds, chunk=12, image_size=(32, 48), cache_dir=demos.cache.dir, **options)
    n0 = int(d.lengths[0])
    edges = [0, n0 - 1, n0, n0 - 12, len(d) - 1]
    assert_batch_is_items(d, edges + np.random.default_rng(0).integers(len(d), size=40).tolist())
    with pytest.raises(IndexError):
        d.batch([0, len(d)])


def test_a_batch_follows_episodes_added_or_replaced(demos):
    """Batches gather from columns built once; adding or replacing episodes rebuilds them."""
    d = DemoDataset(demos.ds, chunk=5, cameras=[])
    d.batch([0])
    doubled = [replace(ep, action=ep.action * 2) for ep in d.low_dim]
    d.replace_episodes(doubled)
    assert_batch_is_items(d, [0, 3, len(d) - 1])
    assert torch.equal(d[0][L.ACTION], torch.from_numpy(doubled[0].action[:5]))
    before = len(d)
    d.add_episodes([replace(doubled[0], index=99)])
    assert len(d) == before + len(doubled[0])
    assert_batch_is_items(d, [before, len(d) - 1])
    with pytest.raises(ValueError, match="same length"):
        d.replace_episodes(doubled[:1])


def test_resize_in_chunks_gives_the_bytes_of_one_pass():
    import torch.nn.functional as F

    from rmbench.data.torch_dataset import RESIZE_CHUNK, resize

    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (2 * RESIZE_CHUNK + 5, 24, 32, 3), dtype=np.uint8)
    x = torch.from_numpy(frames).permute(0, 3, 1, 2).float()
    whole = F.interpolate(x, size=(9, 13), mode="bilinear", antialias=True, align_corners=False)
    expected = whole.round().clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()
    got = resize(frames, (9, 13))
    assert got.shape == (len(frames), 9, 13, 3) and got.dtype == np.uint8
    np.testing.assert_array_equal(got, expected)
