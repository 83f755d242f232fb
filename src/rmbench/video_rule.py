"""Which episodes of an evaluation keep a video (``--video``): read by evaluations and checked
by a table before it runs, so it imports nothing heavy."""

from __future__ import annotations

import re


def keeps_video(video: str, index: int, success: bool | None) -> bool:
    """Under the ``--video`` rule ``video`` (first:K, failures or none), keep a video of the
    ``index``-th episode? (``success`` None: before it runs.) A ValueError for another rule."""
    if video == "none":
        return False
    if video == "failures":
        return success is None or not success
    m = re.fullmatch(r"first:(\d+)", video)
    if not m:
        raise ValueError(f"video must be first:K, failures or none, got {video!r}")
    return index < int(m.group(1))
