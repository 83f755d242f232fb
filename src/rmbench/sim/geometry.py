"""Small rigid-body helpers (quaternions are MuJoCo's w, x, y, z)."""

from __future__ import annotations

import mujoco
import numpy as np


def quat_z(yaw: float) -> np.ndarray:
    """A turn of ``yaw`` about the vertical axis."""
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])


def top_down_mat(yaw: float) -> np.ndarray:
    """A grasp site's rotation pointing straight down, fingers closing along world direction
    ``yaw``."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[0.0, c, s], [0.0, s, -c], [-1.0, 0.0, 0.0]])


def mat_to_quat(mat: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(mat, dtype=float).reshape(9))
    return quat


def quat_to_mat(quat: np.ndarray) -> np.ndarray:
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, np.asarray(quat, dtype=float))
    return mat.reshape(3, 3)


def look_at_quat(pos, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Orientation of a MuJoCo camera at ``pos`` looking at ``target`` (camera looks along -z)."""
    forward = np.asarray(target, float) - np.asarray(pos, float)
    forward /= np.linalg.norm(forward)
    x = np.cross(forward, up)
    x /= np.linalg.norm(x)
    y = np.cross(-forward, x)
    return mat_to_quat(np.stack([x, y, -forward], axis=1))


def wrap_angle(a: float) -> float:
    return float((a + np.pi) % (2 * np.pi) - np.pi)
