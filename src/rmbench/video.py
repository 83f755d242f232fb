"""MP4 writing with PyAV (H.264, yuv420p), written to a temporary file and renamed into place."""

from __future__ import annotations

import os
from pathlib import Path

import av
import numpy as np


class VideoWriter:
    def __init__(self, path: str | Path, fps: int = 20, crf: int = 23):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp.mp4")
        self._fps, self._crf = fps, crf
        self._container = None
        self._stream = None

    def add(self, frame: np.ndarray) -> None:
        if self._container is None:
            h, w = frame.shape[:2]
            self._container = av.open(str(self._tmp), mode="w")
            self._stream = self._container.add_stream("libx264", rate=self._fps)
            self._stream.width, self._stream.height = w - w % 2, h - h % 2
            self._stream.pix_fmt = "yuv420p"
            self._stream.options = {"crf": str(self._crf), "preset": "veryfast"}
        frame = np.ascontiguousarray(frame[: self._stream.height, : self._stream.width])
        for packet in self._stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
            self._container.mux(packet)

    def close(self) -> None:
        if self._container is None:
            return
        for packet in self._stream.encode():
            self._container.mux(packet)
        self._container.close()
        os.replace(self._tmp, self.path)
        self._container = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if exc[0] is None:
            self.close()
        elif self._container is not None:
            self._container.close()
            self._tmp.unlink(missing_ok=True)
