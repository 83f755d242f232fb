"""Forward and inverse kinematics of the two grasp sites, on a robot-only copy of the station.

A pose is a grasp site's position and rotation matrix in the world frame. ``inverse`` is
Gauss-Newton on MuJoCo's site Jacobian, warm-started from given joints, that leaves out the
near-singular direction of a straight wrist: a pose read off joints by ``forward`` comes back
as that pose. The experts' IK (experts/ik.py, mink with a posture task) plans far moves; this
one follows nearby targets fast, one arm at a time (about a millisecond for both arms).

``ReachGrid`` holds, for points of the table, the joints that put a grasp site straight down
over them: a policy reading object positions can see them in its joint targets' terms.
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from rmbench.sim import robot
from rmbench.sim.geometry import top_down_mat
from rmbench.sim.station import ARM_MOUNTS, HOME_ARM, TABLE_TOP, StationConfig, base_spec

# ReachGrid's table area (world x, y; metres) and spacing: every task's pieces lie inside it.
REACH_X = (-0.40, 0.40)
REACH_Y = (-0.36, 0.16)
REACH_SPACING = 0.02
REACH_HEIGHT = 0.04  # the grasp site's height above the table: a 4 cm cube's top-down grasp


@functools.cache
def robot_model() -> mujoco.MjModel:
    """The empty station: the two arms on the table, no objects."""
    return base_spec(StationConfig(render=False)).compile()


class GraspKinematics:
    def __init__(self):
        self.model = robot_model()
        self.data = mujoco.MjData(self.model)
        m = self.model
        joints = {side: [m.joint(f"{side}/{j}") for j in robot.ARM_JOINTS] for side in robot.SIDES}
        self.qadr = {s: np.array([j.qposadr[0] for j in js]) for s, js in joints.items()}
        self.dofadr = {s: np.array([j.dofadr[0] for j in js]) for s, js in joints.items()}
        self.low = {s: np.array([m.jnt_range[j.id][0] for j in js]) for s, js in joints.items()}
        self.high = {s: np.array([m.jnt_range[j.id][1] for j in js]) for s, js in joints.items()}
        self.site = {s: m.site(f"{s}/grasp").id for s in robot.SIDES}
        # each arm's six joints lie consecutive in qpos: forward_arms writes them as slices
        self._arm_start = [int(self.qadr[s][0]) for s in robot.SIDES]
        if not all(np.array_equal(self.qadr[s], np.arange(a, a + 6))
                   for s, a in zip(robot.SIDES, self._arm_start, strict=True)):
            raise ValueError("the robot model's arm joints are not consecutive in qpos")
        self._jacp = np.zeros((3, m.nv))
        self._jacr = np.zeros((3, m.nv))

    def forward(self, side: str, q6: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grasp-site position (3,) and rotation matrix (3, 3) for ``side``'s joints ``q6``."""
        self.data.qpos[self.qadr[side]] = q6
        mujoco.mj_kinematics(self.model, self.data)
        sid = self.site[side]
        return self.data.site_xpos[sid].copy(), self.data.site_xmat[sid].reshape(3, 3).copy()

    def forward_arms(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Both grasp sites' positions (T, 2, 3) and rotation matrices (T, 2, 3, 3), sides in
        ``robot.SIDES`` order, for arm joints ``q`` (T, 2, 6): the numbers ``forward`` gives
        side by side, from one kinematics pass per row (a site moves with its own arm's joints
        only). Python's per-call work, not MuJoCo's, is most of ``forward``'s time: this is
        several times faster (benchmarks/pose_stats_speed.py); a state training starts by
        reading the poses of its every frame, layout copies included."""
        q = np.asarray(q, np.float64)
        if q.ndim != 3 or q.shape[1:] != (len(robot.SIDES), 6):
            raise ValueError(f"forward_arms reads joints (T, {len(robot.SIDES)}, 6), got {q.shape}")
        # slices, not fancy indexing, and MuJoCo's arrays read through views taken once, are
        # most of the saving
        starts, qpos = self._arm_start, self.data.qpos
        # one view per site, taken once: a row of a MuJoCo array, read without indexing again
        site_pos = [self.data.site_xpos[self.site[s]] for s in robot.SIDES]
        site_mat = [self.data.site_xmat[self.site[s]] for s in robot.SIDES]
        pos, mat = np.empty((len(q), len(starts), 3)), np.empty((len(q), len(starts), 9))
        model, data = self.model, self.data
        for t in range(len(q)):
            for k, a in enumerate(starts):
                qpos[a: a + 6] = q[t, k]
            mujoco.mj_kinematics(model, data)
            for k in range(len(starts)):
                pos[t, k] = site_pos[k]
                mat[t, k] = site_mat[k]
        return pos, mat.reshape(len(q), len(starts), 3, 3)

    def inverse(self, side: str, pos: np.ndarray, mat: np.ndarray, seed: np.ndarray,
                iters: int = 30, tol: float = 1e-7, rot_weight: float = 0.1,
                cutoff: float = 0.015) -> np.ndarray:
        """Joints (6,) within their limits that place ``side``'s grasp site at (``pos``, ``mat``),
        Gauss-Newton from ``seed`` on the position error and ``rot_weight`` (metres per radian)
        times the rotation error.

        Steps leave out the directions whose singular value (in those units) is well below
        ``cutoff``. Near a straight wrist, forearm roll and wrist rotate turn about nearly one
        axis (over put_back_block's demonstrations the smallest singular value is about 0.003,
        the next above 0.05): there a rotation error of a hundredth of a radian asks the two
        joints to swing a quarter radian apart, which a predicted pose's small errors would
        do at every step. The joints stay at the seed in that direction instead; the others
        converge."""
        q = np.clip(np.asarray(seed, np.float64), self.low[side], self.high[side])
        sid, dof = self.site[side], self.dofadr[side]
        err, quat = np.empty(6), np.empty(4)
        weight = np.array([1.0, 1.0, 1.0, rot_weight, rot_weight, rot_weight])
        for _ in range(iters):
            self.data.qpos[self.qadr[side]] = q
            mujoco.mj_kinematics(self.model, self.data)
            mujoco.mj_comPos(self.model, self.data)
            err[:3] = pos - self.data.site_xpos[sid]
            # the rotation taking the current orientation to the target, as a world-frame vector
            mujoco.mju_mat2Quat(quat, (mat @ self.data.site_xmat[sid].reshape(3, 3).T).reshape(9))
            mujoco.mju_quat2Vel(err[3:], quat, 1.0)
            mujoco.mj_jacSite(self.model, self.data, self._jacp, self._jacr, sid)
            jac = weight[:, None] * np.vstack([self._jacp[:, dof], self._jacr[:, dof]])
            u, sv, vt = np.linalg.svd(jac)
            # 1/s where s >> cutoff, tapering to 0 (as s^3 / cutoff^4) below it
            gain = sv**3 / (sv**4 + cutoff**4)
            step = vt.T @ (gain * (u.T @ (weight * err)))
            q = np.clip(q + step, self.low[side], self.high[side])
            if np.abs(step).max() < tol:
                break
        return q


def natural_yaw(side: str, xy) -> float:
    """Finger axis for a top-down grasp with the wrist unrotated: across the reach direction."""
    bx, by, _ = ARM_MOUNTS[side].pos
    return float(np.arctan2(xy[1] - by, xy[0] - bx) + np.pi / 2)


class ReachGrid:
    """Each arm's joints for a top-down grasp at ``REACH_HEIGHT`` above the table, the wrist
    unrotated (``natural_yaw``), on a ``REACH_SPACING`` grid over the table, read off by
    bilinear interpolation (points outside the area take its edge's value).

    A learned policy that outputs joint targets and reads object positions has to learn the
    arm's inverse kinematics from its demonstrations, where they happen to have been; over a
    layout it was not shown, a 12-demonstration fit of that map misses by centimetres. Given
    the same positions already in joint terms (``reach_input`` in Mem-0's config), what is
    left to learn is close to a selection and an offset. Solved once per process (about two
    seconds), warm-starting each point from its neighbour so that the grid is one smooth
    branch of the solutions."""

    def __init__(self, height: float = REACH_HEIGHT):
        kin = GraspKinematics()
        self.xs = np.arange(REACH_X[0], REACH_X[1] + 1e-9, REACH_SPACING)
        self.ys = np.arange(REACH_Y[0], REACH_Y[1] + 1e-9, REACH_SPACING)
        z = TABLE_TOP + height
        self.table = {}
        for side in robot.SIDES:
            grid = np.empty((len(self.xs), len(self.ys), 6))
            # Outward from the point nearest the arm's base, each point from its solved
            # neighbour: the grid is then one smooth branch (a far corner solved first lands
            # on another, or on no solution).
            bx, by, _ = ARM_MOUNTS[side].pos
            start = (int(np.argmin(np.abs(self.xs - bx))), int(np.argmin(np.abs(self.ys - by))))
            order = sorted(np.ndindex(len(self.xs), len(self.ys)),
                           key=lambda ij: (abs(ij[0] - start[0]) + abs(ij[1] - start[1]), ij))
            solved = np.zeros(grid.shape[:2], bool)
            for i, j in order:
                near = [(i + a, j + b) for a, b in ((-1, 0), (1, 0), (0, -1), (0, 1))
                        if 0 <= i + a < len(self.xs) and 0 <= j + b < len(self.ys)
                        and solved[i + a, j + b]]
                seed = grid[near[0]] if near else np.asarray(HOME_ARM[side], np.float64)
                pos = np.array([self.xs[i], self.ys[j], z])
                grid[i, j] = kin.inverse(side, pos, top_down_mat(natural_yaw(side, pos)), seed,
                                         iters=60)
                solved[i, j] = True
            self.table[side] = grid

    def joints(self, side: str, xy: np.ndarray) -> np.ndarray:
        """Points (..., 2) -> joints (..., 6) of ``side``'s arm."""
        xy = np.asarray(xy, np.float64)
        fx = np.clip((xy[..., 0] - self.xs[0]) / REACH_SPACING, 0, len(self.xs) - 1 - 1e-9)
        fy = np.clip((xy[..., 1] - self.ys[0]) / REACH_SPACING, 0, len(self.ys) - 1 - 1e-9)
        i, j = fx.astype(int), fy.astype(int)
        u, v = (fx - i)[..., None], (fy - j)[..., None]
        g = self.table[side]
        return ((1 - u) * (1 - v) * g[i, j] + u * (1 - v) * g[i + 1, j]
                + (1 - u) * v * g[i, j + 1] + u * v * g[i + 1, j + 1])


@functools.cache
def reach_grid() -> ReachGrid:
    return ReachGrid()
