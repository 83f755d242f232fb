"""More layouts from the same demonstrations: each one replayed with its whole scene moved.

A demonstration on the state observation is one layout. Moved by (dx, dy) on the table, every
position in the environment state moves by it, and the arms would have done the same thing
there: each grasp site's path moves by it too. The shifted copy's joints (measured and
commanded) are those poses solved by inverse kinematics, each frame warm-started from the
previous one's solution, the grippers as recorded. Each pose also turns about the vertical
by the change in its direction from the arm's base (a few degrees), as the experts' grasps
do (``natural_yaw``): kept at the recorded world orientation instead, the wrist would have
to roll the forearm by a quarter radian, where every demonstration holds it within 0.03.

An arm at its tucked rest pose does not go anywhere with the scene, so the shift is scaled by
how far a grasp site is from its rest position: none within ``REST_RADIUS`` of it, all of it
from twice that on. The rest pose's joints stay exact, which is where every evaluation starts.

A copy whose solved poses miss by more than ``MAX_MISS`` anywhere (a shift out of an arm's
reach) is left out. This is kinematics only: the copy is what the recorded arm motion would
be over the moved scene, not a new simulation of it.

Solving the copies takes about two minutes for 16 copies of 50 demonstrations, and every
policy trained on a dataset asks for the same ones (drawn with ``COPIES_SEED`` whatever the
training seed: the copies are part of the data, and two training seeds differ in the model's
initialisation, batch order and noise over the same copies), so
``add_layout_copies`` keeps them in ``DATASET/.cache/layout-shift-*.npz``: named by the
copies, reach, seed, the constants above, MuJoCo's version and the bytes of each
demonstration's data file (so that a dataset copied to another machine, where its files'
times change, keeps its copies), written atomically, and checked on reading by solving
the first copy again (a changed robot model or solver fails it). A file that fails any of
this is solved again and replaced. Each copy is a function of its demonstration and shift
alone, so ``solve_layout_copies`` solves them across worker processes into the same file: a
table's collection job does, before the trainings that read it start (two of them starting
at once would otherwise both solve it, each on one core).
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import zipfile
from dataclasses import replace
from pathlib import Path

import mujoco
import numpy as np

from rmbench.data import layout as L
from rmbench.data.reader import Dataset, Episode
from rmbench.files import write_atomic
from rmbench.parallel import in_order, make_executor
from rmbench.sim import robot
from rmbench.sim.kinematics import GraspKinematics, natural_yaw
from rmbench.sim.station import HOME_ARM

REST_RADIUS = 0.05  # m: within this of its rest position a grasp site is not shifted
MAX_MISS = 0.003  # m: a solved pose farther than this from its shifted target drops the copy
CACHE_FORMAT = 2  # bumped when what a cache file holds changes
FIELDS = ("state", "action", "environment_state")  # what a copy changes of its source

log = logging.getLogger(__name__)

COPIES_SEED = 0  # the draws of every training's layout copies (see above)


def xy_columns(state_names) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the environment state's x and y position entries."""
    xs = [i for i, n in enumerate(state_names) if n.endswith("_x")]
    ys = [i for i, n in enumerate(state_names) if n.endswith("_y")]
    return np.array(xs, np.int64), np.array(ys, np.int64)


def visibility_columns(state_names, columns: np.ndarray) -> np.ndarray:
    """For each position entry in ``columns``, the index of its object's ``*_visible`` flag,
    or -1 for an object always in view. A hidden object's pose is zeroed
    (``tasks/state.py``), and a zero does not move with the scene."""
    names = list(state_names)
    return np.array([names.index(f"{names[i][:-2]}_visible")
                     if f"{names[i][:-2]}_visible" in names else -1 for i in columns], np.int64)


class LayoutShift:
    """Shifted copies of episodes (one instance per process: it holds a MuJoCo buffer)."""

    def __init__(self, state_names):
        self.kin = GraspKinematics()
        self.xs, self.ys = xy_columns(state_names)
        self.xs_seen, self.ys_seen = (visibility_columns(state_names, c) for c in (self.xs, self.ys))
        self.rest = {side: self.kin.forward(side, np.asarray(HOME_ARM[side], float))[0]
                     for side in robot.SIDES}

    def _joints(self, q: np.ndarray, delta: np.ndarray) -> np.ndarray | None:
        """Joint rows (T, 14) of one episode with each grasp site moved by ``delta`` (scaled
        by its distance from rest); None if a pose cannot be reached."""
        out = np.array(q, np.float64)
        for k, side in enumerate(robot.SIDES):
            cols = slice(7 * k, 7 * k + 6)
            seed = out[0, cols].copy()
            for t in range(len(out)):
                pos, mat = self.kin.forward(side, out[t, cols])
                w = np.clip(np.linalg.norm(pos - self.rest[side]) / REST_RADIUS - 1.0, 0.0, 1.0)
                if w == 0.0:
                    seed = out[t, cols].copy()
                    continue
                target = pos + w * np.array([delta[0], delta[1], 0.0])
                turn = natural_yaw(side, target) - natural_yaw(side, pos)
                c, s = np.cos(turn), np.sin(turn)
                rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
                seed = self.kin.inverse(side, target, rz @ mat, seed)
                if np.linalg.norm(self.kin.forward(side, seed)[0] - target) > MAX_MISS:
                    return None
                out[t, cols] = seed
        return out.astype(np.float32)

    def shift(self, ep: Episode, delta) -> Episode | None:
        """``ep`` with its scene moved by ``delta`` (dx, dy metres); None if out of reach.
        Its ``ee_pose`` stays the source's: an in-memory copy is trained on and never
        written, and no policy reads the column (grasp poses come from the joints'
        kinematics); the rendered copies written to disk record their own."""
        delta = np.asarray(delta, np.float64)
        state = self._joints(ep.state, delta)
        action = None if state is None else self._joints(ep.action, delta)
        if action is None:
            return None
        env = np.array(ep.environment_state, np.float32)
        for cols, seen, d in ((self.xs, self.xs_seen, delta[0]), (self.ys, self.ys_seen, delta[1])):
            shown = np.where(seen >= 0, env[:, np.maximum(seen, 0)] != 0, True)
            env[:, cols] += np.float32(d) * shown
        return replace(ep, state=state, action=action, environment_state=env)


def _draws(episodes: list[Episode], copies: int, reach: float, seed: int):
    """(position in ``episodes``, shift) of every copy, in the order they are drawn."""
    rng = np.random.default_rng(seed)
    return [(k, rng.uniform(-reach, reach, 2)) for k in range(len(episodes)) for _ in range(copies)]


# One LayoutShift per process (a worker's, or this one's), for the last dataset's state names.
_SHIFTER: tuple[tuple[str, ...], LayoutShift] | None = None


def _shift(state_names: tuple[str, ...], ep: Episode, delta: np.ndarray) -> Episode | None:
    global _SHIFTER
    if _SHIFTER is None or _SHIFTER[0] != state_names:
        _SHIFTER = (state_names, LayoutShift(state_names))
    return _SHIFTER[1].shift(ep, delta)


def shifted_copies(episodes: list[Episode], state_names, copies: int, reach: float,
                   seed: int, cache: str | Path | None = None, workers: int = 1
                   ) -> list[Episode]:
    """``copies`` shifted copies of each episode, each by (dx, dy) ~ U[-reach, reach]^2 drawn
    from ``seed``; copies out of reach are left out (so fewer may come back). With ``cache``
    (a file the caller names for these arguments), read from it when it holds them, else
    stored there. ``workers`` processes solve them (each copy is a function of its episode and
    shift alone, taken back in order: the copies do not depend on their number)."""
    if copies < 0 or reach < 0:
        raise ValueError(f"layout copies and shift must be >= 0, got {copies} and {reach}")
    if copies == 0 or reach == 0:
        return []
    names = tuple(state_names)
    if cache is not None and (hit := _load(Path(cache), episodes, names)) is not None:
        return hit
    out, kept = [], []
    executor = make_executor(workers)
    calls = (((k, delta), _shift, (names, episodes[k], delta))
             for k, delta in _draws(episodes, copies, reach, seed))
    try:
        for draw, moved in in_order(executor, calls):
            if moved is not None:
                out.append(moved)
                kept.append(draw)
    finally:
        executor.shutdown()
    if cache is not None:
        try:
            _save(Path(cache), out, kept)
        except OSError as e:  # a dataset folder that cannot be written to still trains
            log.warning("%s: layout copies not cached (%s)", cache, e)
    return out


def _save(path: Path, copies: list[Episode], kept: list) -> None:
    """The copies as one .npz, written atomically (their lengths are their sources')."""
    arrays = {"source": np.array([k for k, _ in kept], np.int64).reshape(-1),
              "delta": np.array([d for _, d in kept], np.float64).reshape(-1, 2)}
    for name in FIELDS:
        arrays[name] = np.concatenate([getattr(ep, name) for ep in copies]) if copies else np.zeros(0)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    write_atomic(path, buf.getvalue())


def _load(path: Path, episodes: list[Episode], state_names: tuple[str, ...]
          ) -> list[Episode] | None:
    """The copies stored at ``path``, or None (logged) if it is missing, damaged, does not
    fit ``episodes`` or its first copy solves differently now."""
    if not path.exists():
        return None
    try:
        with np.load(path, allow_pickle=False) as f:
            a = {k: f[k] for k in ("source", "delta", *FIELDS)}
        src = a["source"]
        if len(src) != len(a["delta"]) or (
                len(src) and (src.min() < 0 or src.max() >= len(episodes))):
            raise ValueError("its copies do not match the demonstrations")
        ends = np.cumsum([len(episodes[k]) for k in src], dtype=np.int64)
        if any(len(a[n]) != (ends[-1] if len(src) else 0) for n in FIELDS):
            raise ValueError("its copies' lengths are not their demonstrations'")
        rows = {n: np.split(a[n], ends[:-1]) if len(src) else [] for n in FIELDS}
        copies = [replace(episodes[k], state=rows["state"][i], action=rows["action"][i],
                          environment_state=rows["environment_state"][i])
                  for i, k in enumerate(src)]
        if copies:
            again = _shift(state_names, episodes[src[0]], a["delta"][0])
            if again is None or not all(np.array_equal(getattr(again, n), getattr(copies[0], n))
                                        for n in FIELDS):
                raise ValueError("its first copy solves differently now")
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as e:
        log.warning("%s: solving the layout copies again (%s)", path, e)
        return None
    return copies


def cache_path(ds: Dataset, indices: list[int], copies: int, reach: float, seed: int) -> Path:
    """Where the copies of ``ds``'s episodes ``indices`` are kept (named by their data files'
    bytes, 1-23 MB on the table's datasets: finding the cache decodes no episode)."""
    files = {e: L.data_file(e) for e in indices}
    digests = {f: hashlib.sha256((ds.root / f).read_bytes()).hexdigest() for f in set(files.values())}
    sources = [(e, files[e], digests[files[e]]) for e in indices]
    key = json.dumps([CACHE_FORMAT, copies, reach, seed, REST_RADIUS, MAX_MISS,
                      mujoco.__version__, sources])
    digest = hashlib.sha256(key.encode()).hexdigest()[:16]
    return ds.root / ".cache" / f"layout-shift-{copies}x{reach:g}-seed{seed}-{digest}.npz"


def add_layout_copies(examples, copies: int, reach: float, seed: int) -> int:
    """Append ``copies`` shifted copies (up to ``reach`` metres) of each demonstration to
    ``examples`` (a ``DemoDataset`` read without cameras); how many were kept."""
    before, ds = len(examples.low_dim), examples.ds
    examples.add_episodes(shifted_copies(
        examples.low_dim, ds.state_names, copies, reach, seed,
        cache_path(ds, [ep.index for ep in examples.low_dim], copies, reach, seed)))
    return len(examples.low_dim) - before


def _whole_cache(ds: Dataset, copies: int, reach: float, seed: int) -> Path:
    """The cache of the copies of every demonstration in ``ds`` (what a training reads)."""
    return cache_path(ds, list(range(ds.num_episodes)), copies, reach, seed)


def solve_layout_copies(root: str | Path, copies: int, reach: float, seed: int,
                        workers: int = 1) -> int:
    """Solve and cache the copies that training with these arguments reads from the dataset
    at ``root`` (every one of its demonstrations), across ``workers`` processes; how many were
    kept. A table's collection does this once per dataset, before its trainings start."""
    ds = Dataset(root)
    episodes = [ds.episode(e, cameras=[]) for e in range(ds.num_episodes)]
    return len(shifted_copies(episodes, ds.state_names, copies, reach, seed,
                              _whole_cache(ds, copies, reach, seed), workers))


def layout_copies_cached(root: str | Path, copies: int, reach: float, seed: int) -> bool:
    """Whether the dataset at ``root`` holds a cache for these copies (checked on reading)."""
    return _whole_cache(Dataset(root), copies, reach, seed).exists()
