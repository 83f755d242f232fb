"""Dataset videos are bit-exact: the encoder runs on one thread and without x264's MB-tree rate
control, whose AVX-512 code sometimes gave another bitstream for the same frames depending on
what the process had done before (benchmarks/encoder_determinism.py measures it)."""

import re

import numpy as np

from rmbench.video import DATASET_CODEC, PREVIEW_CODEC, Mp4Encoder


def x264_options(mp4: bytes) -> dict[str, str]:
    """The settings x264 wrote into the stream (its SEI), e.g. {"mbtree": "0", ...}."""
    text = re.search(rb"x264 - core .*? options: ([^\x00]*)", mp4).group(1).decode()
    return dict(item.split("=", 1) for item in text.split())


def frames(n: int = 8) -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, (n, 48, 64, 3), dtype=np.uint8)


def encode(codec, video: np.ndarray) -> bytes:
    enc = Mp4Encoder(codec=codec)
    for frame in video:
        enc.add(frame)
    return enc.finish()


def test_videos_are_encoded_on_one_thread_without_mbtree():
    for codec in (DATASET_CODEC, PREVIEW_CODEC):
        opts = x264_options(encode(codec, frames()))
        assert (opts["mbtree"], opts["threads"], opts["lookahead_threads"]) == ("0", "1", "1")
    assert DATASET_CODEC.info()["video.mbtree"] is False



def test_decode_gives_every_frame_encoded():
    from rmbench.video import decode_video

    video = frames(30)
    decoded = decode_video(encode(DATASET_CODEC, video))
    assert decoded.shape == video.shape and decoded.dtype == np.uint8
    # lossy, but each decoded frame is its own source frame's, in order
    errors = np.abs(decoded.astype(int)[:, None] - video.astype(int)[None]).mean(axis=(2, 3, 4))
    assert (errors.argmin(axis=1) == np.arange(len(video))).all()


def test_frame_codec_gives_each_frame_back_as_the_dataset_would_store_it():
    import pytest

    from rmbench.video import FrameCodec, decode_video

    y, x = np.mgrid[0:48, 0:64]
    video = np.stack([np.stack([(x * 4 + t) % 256, (y * 5) % 256, (x + y + 3 * t) % 256], -1)
                      for t in range(25)]).astype(np.uint8)  # smooth, moving
    codec = FrameCodec()
    coded = np.stack([codec(frame) for frame in video])  # one back per frame, at once
    assert coded.shape == video.shape and coded.dtype == np.uint8
    err = np.abs(coded.astype(int) - video.astype(int)).mean()
    stored = np.abs(decode_video(encode(DATASET_CODEC, video)).astype(int) - video.astype(int)).mean()
    assert 0 < err < 8 and 0 < stored < 8  # lossy, as much as the dataset's videos
    assert np.array_equal(coded, np.stack([c for c in map(FrameCodec(), video)]))  # deterministic
    with pytest.raises(ValueError, match="uint8"):
        codec(video[0].astype(np.float32))
