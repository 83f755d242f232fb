"""PyTorch access for training: frames with action chunks, in-order sampling for memory
policies, and a disk cache of decoded, resized frames so that epochs after the first do not
decode video again."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import Sampler

from rmbench.data import layout as L
from rmbench.data.reader import Dataset
from rmbench.files import atomic_path


class FrameCache:
    """Decoded frames of each (episode, camera), resized to ``size`` = (height, width), stored as
    .npy files and memory-mapped. Dataset episodes never change once written; the video file's
    size and modification time are part of the cache name all the same, so a dataset collected
    anew into the same folder cannot be served stale frames."""

    def __init__(self, dataset: Dataset, size: tuple[int, int] | None = None,
                 cache_dir: str | Path | None = None):
        self.ds = dataset
        self.size = tuple(size) if size is not None else None
        tag = "native" if self.size is None else f"{self.size[1]}x{self.size[0]}"
        self.dir = Path(cache_dir) if cache_dir is not None else dataset.root / ".cache" / f"frames-{tag}"
        self._open: dict[tuple[int, str], np.ndarray] = {}

    def _path(self, episode: int, camera: str) -> Path:
        return cache_file(self.dir, self.ds, episode, camera)

    def frames(self, episode: int, camera: str) -> np.ndarray:
        """(T, H, W, 3) uint8, memory-mapped (decoded and stored on first use)."""
        key = (episode, camera)
        if key not in self._open:
            path = self._path(episode, camera)
            stored = self._stored(path, episode, camera)
            if stored is None:
                save_atomic(path, self._decode(episode, camera))
                stored = np.load(path, mmap_mode="r")
            self._open[key] = stored
        return self._open[key]

    def read_once(self, episode: int, camera: str) -> np.ndarray:
        """The same frames for a reader that needs them once (the feature cache): from the
        stored file if there is one, else decoded now and not stored. Stored, the frames of
        450 episodes of three cameras at 96x128 take 18 GB."""
        stored = self._stored(self._path(episode, camera), episode, camera)
        return self._decode(episode, camera) if stored is None else stored

    def _stored(self, path: Path, episode: int, camera: str) -> np.ndarray | None:
        """The stored frames at ``path`` if they are this episode's at this size (the
        dataset's own, where none is asked): a file of another size (two sizes given one
        ``cache_dir``), length or type is decoded again."""
        if not path.exists():
            return None
        try:
            frames = np.load(path, mmap_mode="r")
        except (OSError, ValueError):
            return None
        size = self.size or tuple(self.ds.features[L.image_key(camera)]["shape"][:2])
        shape = (int(self.ds.lengths[episode]), *size, 3)
        return frames if frames.dtype == np.uint8 and frames.shape == shape else None

    def _decode(self, episode: int, camera: str) -> np.ndarray:
        frames = self.ds.episode(episode, cameras=[camera]).frames[camera]
        if self.size is not None and frames.shape[1:3] != self.size:
            frames = resize(frames, self.size)
        return frames


def cache_file(directory: Path, dataset: Dataset, episode: int, camera: str) -> Path:
    """Where a cache of per-(episode, camera) arrays keeps one: the video file's size and
    modification time are in the name, so a dataset collected anew into the same folder is
    never served stale arrays."""
    st = dataset.video_path(camera, episode).stat()
    return directory / camera / f"episode-{episode:06d}-{st.st_size}-{st.st_mtime_ns}.npy"


def save_atomic(path: Path, array: np.ndarray) -> None:
    """np.save under a temporary name, then renamed into place: readers never see half a file."""
    with atomic_path(path, suffix=".npy") as tmp:
        np.save(tmp, array)


RESIZE_CHUNK = 32  # frames a pass: an episode's frames as float32 at once are ~1 GB


def resize(frames: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(T, H, W, 3) uint8 -> (T, h, w, 3) uint8, antialiased bilinear.

    Each frame is resized on its own, so resizing ``RESIZE_CHUNK`` frames a pass gives the
    bytes a single pass over the episode gives, in less time: the float copy of a chunk stays
    in cache where an episode's (800 frames at 320x240) does not."""
    out = np.empty((len(frames), *size, 3), dtype=np.uint8)
    for i in range(0, len(frames), RESIZE_CHUNK):
        x = torch.from_numpy(np.ascontiguousarray(frames[i:i + RESIZE_CHUNK]))
        y = F.interpolate(x.permute(0, 3, 1, 2).float(), size=size, mode="bilinear",
                          antialias=True, align_corners=False)
        out[i:i + RESIZE_CHUNK] = y.round().clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1)
    return out


class DemoDataset(torch.utils.data.Dataset):
    """Frame ``i`` of the dataset (episodes concatenated) with the next ``chunk`` actions.

    An item holds ``observation.state`` (14,) float32, ``observation.images.<camera>`` (3, H, W)
    uint8, ``action`` (chunk, 14) float32 with ``action_is_pad`` (chunk,) where the chunk runs
    past the episode's end (padded with its last action), and ``subtask_index``,
    ``subtask_end``, ``subtask_step``, ``task_index``, ``episode_index``, ``frame_index``, ``episode_start``.

    With ``history`` n > 1 the state and images are the last n frames, oldest first: state
    (n, 14) and images (n, 3, H, W), the episode's first frame repeated before its start (an
    observation window, as Diffusion Policy reads).

    With ``environment_state`` an item also holds ``observation.environment_state`` (D,) float32
    (the task's state observation; (n, D) with a history), for policies that read it; a dataset
    collected before the column existed raises ValueError.
    """

    def __init__(self, root: str | Path | Dataset, *, chunk: int = 30,
                 cameras: list[str] | None = None, image_size: tuple[int, int] | None = None,
                 episodes: list[int] | None = None, cache_dir: str | Path | None = None,
                 stride: int = 1, history: int = 1, environment_state: bool = False):
        if stride < 1 or history < 1:
            raise ValueError(f"stride and history must be at least 1, got {stride} and {history}")
        self.stride, self.history = stride, history
        self.ds = root if isinstance(root, Dataset) else Dataset(root)
        if chunk < 1:
            raise ValueError(f"chunk must be at least 1, got {chunk}")
        self.chunk = chunk
        self.cameras = list(self.ds.cameras if cameras is None else cameras)
        self.episode_ids = list(range(self.ds.num_episodes) if episodes is None else episodes)
        self.cache = FrameCache(self.ds, image_size, cache_dir)
        self.low_dim = [self.ds.episode(e, cameras=[]) for e in self.episode_ids]
        self.environment_state = environment_state
        if environment_state and self.ds.state_names is None:
            raise ValueError(f"{self.ds.root} has no {L.ENV_STATE} (collected before it existed)")
        self.task_index = [self.ds.instructions.index(ep.instruction) for ep in self.low_dim]
        self._index()

    def _index(self) -> None:
        """Where each episode starts among the concatenated frames; the concatenated columns
        that batches gather from are built anew on the next batch."""
        self.lengths = np.array([len(ep) for ep in self.low_dim], dtype=np.int64)
        self.starts = np.concatenate([[0], np.cumsum(self.lengths)])
        self._columns: dict[str, np.ndarray] | None = None

    def add_episodes(self, episodes: list) -> None:
        """Append episodes held in memory (``reader.Episode``, e.g. augmented copies of this
        dataset's own). They have no frames, so only a dataset read without cameras takes
        them."""
        if self.cameras:
            raise ValueError("episodes added in memory have no frames: read the dataset "
                             "without cameras to add them")
        self.low_dim += episodes
        # a copy keeps its source's dataset index (so ``episode_index`` in a batch names the
        # recorded episode it came from, not a unique one): nothing may read frames or cached
        # features by it, which copies do not have (frames are refused above; a policy
        # config that reads pixels refuses layout_copies)
        self.episode_ids += [ep.index for ep in episodes]
        self.task_index += [self.ds.instructions.index(ep.instruction) for ep in episodes]
        self._index()

    def replace_episodes(self, episodes: list) -> None:
        """Put ``episodes`` in place of the held ones, one for one and of the same lengths
        (their actions converted to another action space, say)."""
        if [len(ep) for ep in episodes] != self.lengths.tolist():
            raise ValueError("replace_episodes takes one episode of the same length per held one")
        self.low_dim = list(episodes)
        self._index()

    def columns(self) -> dict[str, np.ndarray]:
        """The per-frame columns of every episode, concatenated in flat-index order (what a
        batch gathers from), built once after the episodes last changed."""
        if self._columns is None:
            eps = self.low_dim
            cols = {L.STATE: np.concatenate([ep.state for ep in eps]),
                    L.ACTION: np.concatenate([ep.action for ep in eps]),
                    L.SUBTASK_INDEX: np.concatenate([ep.subtask_index for ep in eps]),
                    L.SUBTASK_END: np.concatenate([ep.subtask_end for ep in eps]),
                    L.SUBTASK_STEP: np.concatenate([ep.subtask_step for ep in eps])}
            if self.environment_state:
                cols[L.ENV_STATE] = np.concatenate([ep.environment_state for ep in eps])
            self._columns = cols
        return self._columns

    def __len__(self) -> int:
        return int(self.starts[-1])

    def locate(self, i: int) -> tuple[int, int]:
        """Flat index -> (position in ``episode_ids``, frame)."""
        k, t = self.locate_many([i])
        return int(k[0]), int(t[0])

    def observed(self, t):
        """The frames an item at frame ``t`` (or each of an array of frames) observes: ``t``,
        or with a history the last n, oldest first (a trailing axis), the episode's first
        repeated before its start."""
        if self.history == 1:
            return t
        return np.maximum(np.asarray(t)[..., None] + np.arange(1 - self.history, 1), 0)

    def locate_many(self, indices) -> tuple[np.ndarray, np.ndarray]:
        """Flat indices -> (positions in ``episode_ids``, frames), as arrays."""
        i = np.asarray(indices, dtype=np.int64).reshape(-1)
        if i.size and not (0 <= i.min() and i.max() < len(self)):
            bad = int(i[(i < 0) | (i >= len(self))][0])
            raise IndexError(f"index {bad} out of range for {len(self)} frames")
        k = np.searchsorted(self.starts, i, side="right") - 1
        return k, i - self.starts[k]

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {key: value[0] for key, value in self.batch([i]).items()}

    def batch(self, indices: list[int]) -> dict[str, torch.Tensor]:
        """The items at ``indices``, collated: each key's values stacked along a new first
        dimension, as ``default_collate`` stacks the items one by one, gathered from the
        concatenated columns at once (``training.batches.batch_stream`` reads batches so)."""
        k, t = self.locate_many(indices)
        start, n = self.starts[k], self.lengths[k]
        ahead = t[:, None] + np.arange(self.chunk)  # (B, chunk) frames of the action chunk
        rows = start[:, None] + np.minimum(ahead, n[:, None] - 1)
        seen = self.observed(t)  # (B, history) frames observed, or (B,)
        seen_rows = (start[:, None] if self.history > 1 else start) + seen
        col = self.columns()
        at = start + t
        batch = {
            L.STATE: torch.from_numpy(col[L.STATE][seen_rows]),
            L.ACTION: torch.from_numpy(col[L.ACTION][rows]),
            "action_is_pad": torch.from_numpy(ahead >= n[:, None]),
            L.SUBTASK_INDEX: torch.from_numpy(col[L.SUBTASK_INDEX][at].astype(np.int64)),
            L.SUBTASK_END: torch.from_numpy(col[L.SUBTASK_END][at].astype(bool)),
            L.SUBTASK_STEP: torch.from_numpy(col[L.SUBTASK_STEP][at].astype(np.int64)),
            "task_index": torch.from_numpy(np.asarray(self.task_index, np.int64)[k]),
            "episode_index": torch.from_numpy(np.asarray([self.low_dim[j].index for j in k],
                                                         np.int64)),
            "frame_index": torch.from_numpy(t.astype(np.int64)),
            # the first frame a walk with this stride visits (EpisodeOrderSampler's phase)
            "episode_start": torch.from_numpy(t < self.stride),
        }
        if self.environment_state:
            batch[L.ENV_STATE] = torch.from_numpy(col[L.ENV_STATE][seen_rows])
        for cam in self.cameras:
            frames = np.stack([self.cache.frames(self.episode_ids[j], cam)[s]
                               for j, s in zip(k, seen, strict=True)])
            batch[L.image_key(cam)] = torch.from_numpy(frames).movedim(-1, -3).contiguous()
        return batch


class EpisodeOrderSampler(Sampler[list[int]]):
    """Batches for memory policies: slot ``b`` of every batch continues one episode frame by
    frame, so a per-slot memory carried across batches is what the policy would hold at run
    time. When a slot's episode ends the slot starts the next episode of a shuffled queue (its
    first item has ``episode_start`` set: clear the slot's memory there). Batches mix episodes at
    different time steps.

    The batches form one endless stream (``stream(start)``), deterministic for a ``seed``: slots
    run on across epoch boundaries, so every frame of every episode is visited whatever the
    batch size. An epoch (``__iter__`` after ``set_epoch``) is the stream's ``len(self)``
    batches from ``epoch * len(self)``, about one pass over the frames.

    With a dataset of ``stride`` s a slot visits every s-th frame of its episode from a random
    phase in [0, s) (the phase's frame is the one the dataset marks ``episode_start``), for
    memories written every s control steps."""

    def __init__(self, dataset: DemoDataset, batch_size: int, shuffle: bool = True, seed: int = 0):
        if batch_size < 1:
            raise ValueError(f"batch_size must be at least 1, got {batch_size}")
        self.starts, self.lengths = dataset.starts[:-1], dataset.lengths
        self.batch_size, self.shuffle, self.seed, self.epoch = batch_size, shuffle, seed, 0
        self.stride = dataset.stride

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return max(1, int(self.lengths.sum()) // (self.batch_size * self.stride))

    def __iter__(self) -> Iterator[list[int]]:
        yield from itertools.islice(self.stream(self.epoch * len(self)), len(self))

    def stream(self, start: int = 0) -> Iterator[list[int]]:
        """Batch ``start`` of the stream and all after it (skipping costs index arithmetic only)."""
        rng = np.random.default_rng(self.seed)
        n = len(self.lengths)

        def queue():
            while True:
                yield from (rng.permutation(n) if self.shuffle else range(n))

        episodes = queue()

        def begin() -> list[int]:
            e = int(next(episodes))
            phase = int(rng.integers(self.stride)) if self.stride > 1 else 0
            return [e, min(phase, int(self.lengths[e]) - 1)]

        slots = [begin() for _ in range(self.batch_size)]
        step = 0
        while True:
            batch = []
            for slot in slots:
                e, t = slot
                batch.append(int(self.starts[e] + t))
                slot[1] += self.stride
                if slot[1] >= self.lengths[e]:
                    slot[:] = begin()
            if step >= start:
                yield batch
            step += 1


class RandomFrameSampler:
    """Batches of uniformly drawn frames for memoryless policies. Batch k comes from a
    generator seeded by (seed, k), so ``stream(start)`` resumes in O(1) and a resumed run sees
    the batches an uninterrupted one would."""

    def __init__(self, dataset: DemoDataset, batch_size: int, seed: int = 0):
        if batch_size < 1:
            raise ValueError(f"batch_size must be at least 1, got {batch_size}")
        self.frames, self.batch_size, self.seed = len(dataset), batch_size, seed

    def stream(self, start: int = 0) -> Iterator[list[int]]:
        for step in itertools.count(start):
            rng = np.random.default_rng([self.seed, step])
            yield rng.integers(self.frames, size=self.batch_size).tolist()
