"""Building blocks of the state observation (``obs_type="environment_state_agent_pos"``).

A task's ``environment_state()`` is a fixed-length float vector of what the head camera shows
of the scene, in the order of its ``state_names``. It is assembled from the entries below, so
the nine tasks share one encoding:

- a pose: x, y, z (metres, world frame: origin on the floor under the table centre, +x right,
  +y away from the robot, +z up) and the heading as cos(k * yaw), sin(k * yaw), where k is
  the object's visible rotational symmetry (a cube looks the same turned by 90 degrees: k = 4;
  a T: k = 1; a cylinder standing up: k = 0, no heading entries are non-zero). The encoding is
  continuous through every turn and carries no heading the camera could not tell apart;
- a fixed piece's table position: x, y;
- a button: x, y and the cap's depth (metres pushed in, 0 at rest, 0.01 at the stop);
- a lamp: one-hot over off, red, green;
- a one-hot over a fixed list of visible looks (shapes, colour names), or RGB in [0, 1].

Identical objects (two red cubes, three covers) carry no identity a camera could see, so
their entries are sorted left to right (by x) rather than kept in a fixed order that would
tell which one is which. Hidden things are zeroed behind a visibility flag.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence

import numpy as np

from rmbench.sim.fixtures import LAMP_COLOURS

# Visible rotational symmetry of each procedural shape (observe_and_pickup): a bar or a slab
# looks the same turned by half a turn, a cylinder or a disc standing up by any angle.
SHAPE_SYMMETRY = {"cube": 4, "bar": 2, "tall": 4, "cylinder": 0, "disc": 0, "slab": 2}
CUBE_SYMMETRY = 4
COVER_SYMMETRY = 4  # a square cup with a square knob
LAMP_STATES = tuple(LAMP_COLOURS)  # off, red, green


def _heading_names(prefix: str, k) -> tuple[str, str]:
    tag = "_yaw" if k == 1 else f"{k}yaw"
    return f"{prefix}_cos{tag}", f"{prefix}_sin{tag}"


def pose_names(prefix: str, k: int | str) -> tuple[str, ...]:
    """Names of a pose's five entries; ``k`` the symmetry (or "k" where it varies by episode)."""
    return (f"{prefix}_x", f"{prefix}_y", f"{prefix}_z", *_heading_names(prefix, k))


def xy_names(prefix: str) -> tuple[str, ...]:
    return f"{prefix}_x", f"{prefix}_y"


def button_names(prefix: str) -> tuple[str, ...]:
    return f"{prefix}_x", f"{prefix}_y", f"{prefix}_depth"


def lamp_names(prefix: str) -> tuple[str, ...]:
    return tuple(f"{prefix}_{s}" for s in LAMP_STATES)


def one_hot_names(prefix: str, values: Iterable[str]) -> tuple[str, ...]:
    return tuple(f"{prefix}_{v}" for v in values)


def rgb_names(prefix: str) -> tuple[str, ...]:
    return f"{prefix}_r", f"{prefix}_g", f"{prefix}_b"


def heading(yaw: float, k: int) -> np.ndarray:
    if k == 0:
        return np.zeros(2)
    return np.array([np.cos(k * yaw), np.sin(k * yaw)])


def pose(piece, data, k: int) -> np.ndarray:
    """x, y, z and the heading of a free piece (or a fixed body: its world pose)."""
    return np.r_[data.xpos[piece.body_id], heading(piece.yaw(data), k)]


def xy(piece, model) -> np.ndarray:
    return piece.xy(model)


def button(b, model, data) -> np.ndarray:
    return np.r_[b.xy(model), b.depth(data)]


def lamp(lamp_piece) -> np.ndarray:
    return one_hot(lamp_piece.state, LAMP_STATES)


def one_hot(value, values: Sequence) -> np.ndarray:
    out = np.zeros(len(values))
    out[list(values).index(value)] = 1.0
    return out


def left_to_right(pieces, data) -> list:
    """Identical pieces in the order a camera can give them: by x, then y."""
    return sorted(pieces, key=lambda p: (float(data.xpos[p.body_id][0]),
                                         float(data.xpos[p.body_id][1])))


def is_position(name: str) -> bool:
    """A coordinate of a piece's position, in metres (``*_x``, ``*_y``, ``*_z``)."""
    return name.rsplit("_", 1)[-1] in ("x", "y", "z")


def is_continuous(name: str) -> bool:
    """A position, heading or depth (jitters from episode to episode); the rest (flags,
    one-hots, RGB, digits) takes a few exact values."""
    return name.endswith(("_x", "_y", "_z", "yaw", "_depth"))


def symmetric_heading(name: str) -> bool:
    """A heading entry of a piece with a rotational symmetry (cos/sin of k * yaw, k >= 2 or
    varying by episode): cubes, covers, a cell's axis, the procedural shapes."""
    return re.search(r"_(cos|sin)(k|[2-9])yaw$", name) is not None


def bounds(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per-entry (low, high) for the observation space, from the naming conventions above:
    positions within 5 m of the origin, headings in [-1, 1], a cap's depth within 5 cm, a
    digit in [0, 9], flags, one-hots and RGB in [0, 1]."""
    low, high = np.zeros(len(names)), np.ones(len(names))
    for i, name in enumerate(names):
        last = name.rsplit("_", 1)[-1]
        if is_position(name):
            low[i], high[i] = -5.0, 5.0
        elif name.endswith("yaw"):  # ..._cos_yaw, ..._sin4yaw, ..._coskyaw
            low[i] = -1.0
        elif last == "depth":
            low[i], high[i] = -0.05, 0.05
        elif last == "digit":
            high[i] = 9.0
    return low, high


def _flatten(parts: Iterable):
    for p in parts:
        if isinstance(p, tuple):  # a group of entries, e.g. (pose, colour) of one object
            yield from _flatten(p)
        else:
            yield np.ravel(np.asarray(p, np.float64))


def assemble(names: Sequence[str], parts: Iterable) -> np.ndarray:
    """Concatenate ``parts`` (arrays, lists, or tuples of them) into the vector ``names``
    describes: float64, its length checked."""
    out = np.concatenate(list(_flatten(parts)))
    if out.shape != (len(names),):
        raise AssertionError(f"state vector has {out.size} entries, state_names {len(names)}")
    return out
