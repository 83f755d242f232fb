"""What a policy's action head predicts, and how it becomes the env's 14 joint targets.

"joints": the env's action itself (6 joint targets + gripper, per arm).
"ee": per arm the grasp site's target pose (position, then the rotation matrix's first two
columns, the continuous 6D rotation of Zhou et al. 2019) and the gripper, 20 numbers; read
off the recorded joint targets by forward kinematics, turned back into joints by inverse
kinematics warm-started from the measured joints. Where a grasp goes is the object's pose plus
a fixed offset: in joint space a non-linear function a policy learns only where its
demonstrations have been, in this space a near-linear one it can carry to new layouts.
"""

from __future__ import annotations

import numpy as np

from rmbench.sim import robot
from rmbench.sim.kinematics import GraspKinematics
from rmbench.sim.simulator import ACTION_DIM as JOINT_DIM

ACTION_SPACES = ("joints", "ee")
EE_ARM = 10  # position (3), rotation's first two columns (6), gripper (1)
EE_DIM = 2 * EE_ARM


def action_dim(space: str) -> int:
    if space not in ACTION_SPACES:
        raise ValueError(f"unknown action space {space!r}; one of {', '.join(ACTION_SPACES)}")
    return JOINT_DIM if space == "joints" else EE_DIM


def rotation_from_6d(r6: np.ndarray) -> np.ndarray:
    """The rotation matrix nearest two predicted columns (Gram-Schmidt)."""
    a, b = r6[:3], r6[3:]
    x = a / max(np.linalg.norm(a), 1e-9)
    y = b - x * (x @ b)
    y = y / max(np.linalg.norm(y), 1e-9)
    return np.stack([x, y, np.cross(x, y)], 1)


class EEActions:
    """Converts between joint targets and grasp-pose targets (one instance per process: it
    holds a MuJoCo data buffer)."""

    def __init__(self):
        self.kin = GraspKinematics()

    def from_joints(self, actions: np.ndarray) -> np.ndarray:
        """Joint targets (T, 14) -> pose targets (T, 20), float32."""
        actions = np.asarray(actions, np.float64).reshape(len(actions), len(robot.SIDES), 7)
        pos, mat = self.kin.forward_arms(actions[:, :, :6])
        out = np.empty((len(actions), EE_DIM), np.float32)
        for k in range(len(robot.SIDES)):
            o = EE_ARM * k
            out[:, o: o + 3] = pos[:, k]
            out[:, o + 3: o + 9] = mat[:, k, :, :2].transpose(0, 2, 1).reshape(-1, 6)
            out[:, o + 9] = actions[:, k, 6]
        return out

    def to_joints(self, targets: np.ndarray, seed: np.ndarray) -> np.ndarray:
        """Pose targets (T, 20) -> joint targets (T, 14), each step's IK warm-started from the
        previous step's solution and the first from ``seed`` (the measured joints, (14,))."""
        targets = np.asarray(targets, np.float64)
        out = np.empty((len(targets), JOINT_DIM))
        q = {side: np.asarray(seed, np.float64)[7 * k: 7 * k + 6] for k, side in enumerate(robot.SIDES)}
        for t, x in enumerate(targets):
            for k, side in enumerate(robot.SIDES):
                o = EE_ARM * k
                q[side] = self.kin.inverse(side, x[o: o + 3], rotation_from_6d(x[o + 3: o + 9]),
                                           q[side])
                out[t, 7 * k: 7 * k + 6] = q[side]
                out[t, 7 * k + 6] = x[o + 9]
        return out
