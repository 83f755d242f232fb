"""MP4 I/O with PyAV: H.264 (libx264, yuv420p) encoding in memory, atomic files, decoding.

Dataset videos and episode videos share one encoder. Encoding goes to memory first so that a
file appears on disk only complete (``rmbench.files.write_atomic``), and so
that worker processes can hand finished videos to the process that owns the dataset.
"""

from __future__ import annotations

import io
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from rmbench.files import write_atomic


@dataclass(frozen=True)
class VideoCodec:
    """Encoder settings. ``veryfast`` at CRF 23 measured 0.9 MB for 3 x 300 frames at 320x240
    (``ultrafast`` CRF 18: 2.2 MB) with a mean error of 1.8/255, at about 0.9 ms per frame. A GOP
    of one second (20 frames) bounds the decode work of a random seek for frame-level readers
    such as LeRobot's.

    ``mbtree`` stays off because x264's AVX-512 code for it is not deterministic: the same
    frames, encoded single-threaded, sometimes gave another bitstream depending on what the
    process had done before (about one video in a hundred; one such 93-frame video had 58
    frames off by up to 21/255 after decoding). Measured over 2,400 encodes each:
    mbtree with AVX-512 gave 2 variants for 3 of 6 videos; without AVX-512, or with mbtree off
    (9,600 encodes), one each. Off, files are about 28% larger (0.70 -> 0.90 MB above)."""

    crf: int = 23
    preset: str = "veryfast"
    gop: int = 20
    codec: str = "libx264"
    pix_fmt: str = "yuv420p"
    mbtree: bool = False

    def options(self) -> dict[str, str]:
        """The encoder's private options (libx264's)."""
        return {"crf": str(self.crf), "preset": self.preset, "x264-params": f"mbtree={int(self.mbtree)}"}

    def info(self) -> dict:
        return {"video.codec": "h264", "video.pix_fmt": self.pix_fmt, "video.crf": self.crf,
                "video.g": self.gop, "video.preset": self.preset, "video.mbtree": self.mbtree}


DATASET_CODEC = VideoCodec()
# Videos for people to watch: smaller files, no random access needed.
PREVIEW_CODEC = VideoCodec(crf=23, preset="veryfast", gop=250)


def check_frame(frame: np.ndarray) -> None:
    """A video frame is (H, W, 3) uint8; ValueError otherwise."""
    if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
        raise ValueError(f"video frames must be (H, W, 3) uint8, got {frame.shape} {frame.dtype}")


def even_size(frame: np.ndarray) -> tuple[int, int]:
    """(width, height) a frame is encoded at: yuv420p needs even sizes, so odd ones lose their
    last row/column."""
    h, w = frame.shape[:2]
    return w - w % 2, h - h % 2


class Mp4Encoder:
    """Streams RGB uint8 frames (H, W, 3) into an MP4 held in memory."""

    def __init__(self, fps: int = 20, codec: VideoCodec = DATASET_CODEC):
        self.fps, self.codec = fps, codec
        self.frames = 0
        self._buf = io.BytesIO()
        self._container = None
        self._stream = None

    def options(self) -> dict[str, str]:
        """The encoder's private options (its codec's)."""
        return self.codec.options()

    def add(self, frame: np.ndarray) -> None:
        check_frame(frame)
        if self._container is None:
            self._container = av.open(self._buf, mode="w", format="mp4")
            s = self._container.add_stream(self.codec.codec, rate=self.fps)
            s.width, s.height = even_size(frame)
            s.pix_fmt = self.codec.pix_fmt
            s.codec_context.gop_size = self.codec.gop
            # One thread: x264's slices and PyAV's colour conversion then do not depend on how
            # many cores the process may use (a pinned or cgroup-limited worker), and a
            # collection already runs one worker per core.
            s.codec_context.thread_count = 1
            s.options = self.options()
            self._stream = s
        frame = np.ascontiguousarray(frame[: self._stream.height, : self._stream.width])
        for packet in self._stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
            self._container.mux(packet)
        self.frames += 1

    def finish(self) -> bytes:
        """Flush the encoder and return the MP4 file's bytes."""
        if self._container is None:
            raise ValueError("no frames were added to the video")
        for packet in self._stream.encode():
            self._container.mux(packet)
        self._container.close()
        self._container = None
        return self._buf.getvalue()


class VideoWriter:
    """An MP4 file written frame by frame; it appears at ``path`` on close, complete."""

    def __init__(self, path: str | Path, fps: int = 20, codec: VideoCodec = PREVIEW_CODEC):
        self.path = Path(path)
        self._encoder = Mp4Encoder(fps, codec)

    def add(self, frame: np.ndarray) -> None:
        self._encoder.add(frame)

    def close(self) -> None:
        if self._encoder.frames:
            write_atomic(self.path, self._encoder.finish())

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.close()


class FrameCodec:
    """Frames through a codec one at a time, each decoded back as it goes in: a frame near the
    one a dataset stores (RGB to 4:2:0, the codec's loss; not equal, as the stored stream's
    B-frames and lookahead code each frame otherwise) for a policy trained on stored frames,
    in closed loop. One stream per camera and episode, as a recorded episode's video. x264
    runs without lookahead or B-frames (``tune=zerolatency``), so frame t comes back at step
    t; the codec's other settings (CRF, preset, GOP) are kept."""

    def __init__(self, fps: int = 20, codec: VideoCodec = DATASET_CODEC):
        self.fps, self.codec = fps, codec
        self._encoder: av.CodecContext | None = None
        self._decoder: av.CodecContext | None = None
        self._pts = 0

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        check_frame(frame)
        if self._encoder is None:
            enc = av.CodecContext.create(self.codec.codec, "w")
            enc.width, enc.height = even_size(frame)
            enc.pix_fmt, enc.gop_size, enc.thread_count = self.codec.pix_fmt, self.codec.gop, 1
            enc.time_base, enc.framerate = Fraction(1, self.fps), Fraction(self.fps, 1)
            enc.options = {**self.codec.options(), "tune": "zerolatency"}
            self._encoder = enc
            self._decoder = av.CodecContext.create("h264", "r")
            self._decoder.thread_count = 1
        enc = self._encoder
        image = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame[:enc.height, :enc.width]),
                                           format="rgb24")
        image.pts = self._pts
        self._pts += 1
        out = [f for packet in enc.encode(image) for f in self._decoder.decode(packet)]
        if len(out) != 1:
            raise RuntimeError(f"the codec gave {len(out)} frames for one (zerolatency expected)")
        return out[0].to_ndarray(format="rgb24")


def decode_video(source: str | Path | bytes) -> np.ndarray:
    """All frames of an MP4 (a path or its bytes) as one (T, H, W, 3) uint8 array."""
    src = io.BytesIO(source) if isinstance(source, bytes) else str(source)
    with av.open(src) as container:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        # into one array as they decode (the header's count; a list and np.stack copy each
        # frame twice), grown if a file holds more frames than its header says
        frames: np.ndarray | None = None
        n = 0
        for f in container.decode(stream):
            frame = f.to_ndarray(format="rgb24")
            if frames is None:
                frames = np.empty((max(stream.frames, 1), *frame.shape), dtype=frame.dtype)
            elif n == len(frames):
                frames = np.concatenate([frames, np.empty_like(frames)])
            frames[n] = frame
            n += 1
    if frames is None:
        raise ValueError(f"{source if not isinstance(source, bytes) else 'video'} has no frames")
    return frames[:n] if n < len(frames) else frames


def probe_video(path: str | Path) -> dict:
    """Frame count, size and codec of an MP4 from its header, without decoding."""
    with av.open(str(path)) as container:
        if not container.streams.video:
            raise ValueError("no video stream")
        s = container.streams.video[0]
        return {"frames": int(s.frames), "width": s.codec_context.width,
                "height": s.codec_context.height, "codec": s.codec_context.name}
