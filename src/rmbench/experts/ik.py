"""Inverse kinematics for both arms with mink, on a robot-only copy of the station."""

from __future__ import annotations

import mink
import numpy as np

from rmbench.sim import robot
from rmbench.sim.geometry import mat_to_quat, quat_to_mat, top_down_mat
from rmbench.sim.kinematics import robot_model
from rmbench.sim.station import home_action


def top_down_quat(yaw: float) -> np.ndarray:
    """Gripper pointing straight down with its fingers closing along world direction ``yaw``."""
    return mat_to_quat(top_down_mat(yaw))


MAX_STEP = 0.2  # rad per IK iteration


class ArmIK:
    """Differential IK (mink) that solves grasp-site poses for one arm at a time.

    The model is the empty station, so object joints never enter the problem; the solution
    is the 6 joint angles of the requested arm, warm-started from ``seed`` for continuity.
    """

    def __init__(self):
        self.model = robot_model()
        self.config = mink.Configuration(self.model)
        self.limits = [mink.ConfigurationLimit(self.model)]
        self.tasks = {}
        self.qadr = {}
        for side in robot.SIDES:
            self.tasks[side] = mink.FrameTask(f"{side}/grasp", "site", position_cost=1.0,
                                              orientation_cost=0.5, lm_damping=1e-3)
            self.qadr[side] = np.array(
                [self.model.joint(f"{side}/{j}").qposadr[0] for j in robot.ARM_JOINTS])
        self.posture = mink.PostureTask(self.model, cost=1e-3)
        q = np.zeros(self.model.nq)
        home = home_action()
        for k, side in enumerate(robot.SIDES):
            q[self.qadr[side]] = home[7 * k: 7 * k + 6]
        self.posture.set_target(q)

    def ready_seed(self, side: str, pos) -> np.ndarray:
        """A forward-reaching posture turned towards ``pos``: a good start far from home."""
        base = self.model.body(f"{side}/base")
        dx, dy = np.asarray(pos[:2]) - self.model.body_pos[base.id][:2]
        return np.array([np.arctan2(-dx, dy), -0.3, 0.3, 0.0, 1.2, 0.0])

    def solve(self, side: str, pos, quat, seed: np.ndarray | None = None, tol: float = 5e-4,
              max_iters: int = 100) -> tuple[np.ndarray, float]:
        """Joint angles placing ``side``'s grasp site at (pos, quat); returns (q6, error m)."""
        q = self.config.q.copy()
        q[self.qadr[side]] = self.ready_seed(side, pos) if seed is None else seed
        self.config.update(q)
        task = self.tasks[side]
        target = mink.SE3.from_rotation_and_translation(
            mink.SO3.from_matrix(quat_to_mat(quat)), np.asarray(pos, float))
        task.set_target(target)
        err = np.inf
        for _ in range(max_iters):
            vel = mink.solve_ik(self.config, [task, self.posture], 0.1, "daqp", damping=1e-4,
                                limits=self.limits)
            # Only this arm's joints may move.
            mask = np.zeros_like(vel)
            mask[self.qadr[side]] = 1.0
            step = vel * mask * 0.1
            # Bounded steps: a full Gauss-Newton step from far away swings the waist around.
            step *= min(1.0, MAX_STEP / max(np.abs(step).max(), 1e-12))
            self.config.integrate_inplace(step / 0.1, 0.1)
            e = task.compute_error(self.config)
            err = float(np.linalg.norm(e[:3]))
            if err < tol and np.linalg.norm(e[3:]) < 20 * tol:
                break
        return self.config.q[self.qadr[side]].copy(), err

    def forward(self, side: str, q6: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Grasp-site position and rotation matrix for joint angles ``q6``."""
        q = self.config.q.copy()
        q[self.qadr[side]] = q6
        self.config.update(q)
        sid = self.model.site(f"{side}/grasp").id
        return self.config.data.site_xpos[sid].copy(), self.config.data.site_xmat[sid].reshape(3, 3).copy()
