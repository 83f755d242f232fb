"""The on-disk layout: LeRobot v3.0 paths and features, plus rmbench's own metadata files.

One episode per data file and per video file (``file_index`` = episode index within its chunk).
LeRobot v3.0 allows several episodes per file; one per file is what makes each episode an
atomic unit: written completely, then committed, never rewritten, so collection can be killed
and resumed at any moment and worker processes never share a file.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from rmbench.sim import robot
from rmbench.sim.simulator import ACTION_DIM, EE_POSE_DIM
from rmbench.video import VideoCodec

CODEBASE_VERSION = "v3.0"
# rmbench's own metadata (meta/rmbench.json). rmbench/2: one subtask per plan step
# (``subtask_step``), so a step repeated back to back (press_button's pushes) has its own end.
FORMAT = "rmbench/2"
ROBOT_TYPE = "aloha"  # two ViperX 300s arms, the gym-aloha layout
CHUNKS_SIZE = 1000

INFO = "meta/info.json"
STATS = "meta/stats.json"
TASKS = "meta/tasks.parquet"
SUBTASKS = "meta/subtasks.parquet"
RMBENCH = "meta/rmbench.json"
EPISODES_DIR = "meta/episodes"
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
VIDEO_PATH = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"

STATE = "observation.state"
# The task's state observation (rmbench.make(..., obs_type="environment_state_agent_pos")):
# absent from datasets collected before it existed.
ENV_STATE = "observation.environment_state"
EE_POSE = "observation.ee_pose"
ACTION = "action"
IMAGE_PREFIX = "observation.images."
SUBTASK_INDEX = "subtask_index"
SUBTASK_END = "subtask_end"
# Which step of the task's plan a frame works on (0 .. len(plan) - 1): the number of plan steps
# the simulator counts as done at that frame. A subtask ends where its step does.
SUBTASK_STEP = "subtask_step"
PROGRESS = "progress"
INDEX_COLUMNS = ("timestamp", "frame_index", "episode_index", "index", "task_index")

JOINT_NAMES = list(robot.JOINT_NAMES)  # a list, as the dataset's info.json stores it
EE_NAMES = [f"{side}_{c}" for side in robot.SIDES for c in ("x", "y", "z", "qw", "qx", "qy", "qz")]
assert len(JOINT_NAMES) == ACTION_DIM and len(EE_NAMES) == EE_POSE_DIM


def chunk_file(episode_index: int) -> tuple[int, int]:
    return divmod(episode_index, CHUNKS_SIZE)


def data_file(episode_index: int) -> str:
    c, f = chunk_file(episode_index)
    return DATA_PATH.format(chunk_index=c, file_index=f)


def video_file(key: str, episode_index: int) -> str:
    c, f = chunk_file(episode_index)
    return VIDEO_PATH.format(video_key=key, chunk_index=c, file_index=f)


def episodes_file(episode_index: int) -> str:
    c, f = chunk_file(episode_index)
    return EPISODES_PATH.format(chunk_index=c, file_index=f)


def image_key(camera: str) -> str:
    return IMAGE_PREFIX + camera


@dataclass(frozen=True)
class Spec:
    """What every frame of a dataset holds: the cameras, their resolution, the rate."""

    cameras: tuple[str, ...]
    width: int
    height: int
    fps: int = 20
    codec: VideoCodec = VideoCodec()

    def __post_init__(self):
        if not self.cameras:
            raise ValueError("a dataset needs at least one camera")
        if self.width % 2 or self.height % 2 or self.width < 16 or self.height < 16:
            raise ValueError(f"resolution must be even and at least 16x16 (H.264 yuv420p), "
                             f"got {self.width}x{self.height}")

    @property
    def video_keys(self) -> list[str]:
        return [image_key(c) for c in self.cameras]

    def features(self, state_names: Sequence[str] | None = None) -> dict[str, dict]:
        """The ``features`` of meta/info.json, in column order; ``state_names`` (the task's
        ``state_names``) adds ``observation.environment_state``."""
        feats: dict[str, dict] = {}
        for key in self.video_keys:
            feats[key] = {
                "dtype": "video", "shape": [self.height, self.width, 3],
                "names": ["height", "width", "channels"],
                "info": {"video.height": self.height, "video.width": self.width,
                         **self.codec.info(), "video.is_depth_map": False,
                         "video.fps": self.fps, "video.channels": 3, "has_audio": False}}
        feats[STATE] = {"dtype": "float32", "shape": [ACTION_DIM], "names": JOINT_NAMES}
        if state_names is not None:
            feats[ENV_STATE] = {"dtype": "float32", "shape": [len(state_names)],
                                "names": list(state_names)}
        feats[EE_POSE] = {"dtype": "float32", "shape": [EE_POSE_DIM], "names": EE_NAMES}
        feats[ACTION] = {"dtype": "float32", "shape": [ACTION_DIM], "names": JOINT_NAMES}
        feats[SUBTASK_INDEX] = {"dtype": "int64", "shape": [1], "names": None}
        feats[SUBTASK_END] = {"dtype": "bool", "shape": [1], "names": None}
        feats[SUBTASK_STEP] = {"dtype": "int64", "shape": [1], "names": None}
        feats[PROGRESS] = {"dtype": "float32", "shape": [1], "names": None}
        feats["timestamp"] = {"dtype": "float32", "shape": [1], "names": None}
        for col in INDEX_COLUMNS[1:]:
            feats[col] = {"dtype": "int64", "shape": [1], "names": None}
        return feats


def root_path(root: str | Path) -> Path:
    return Path(root).expanduser()
