"""Grasp-site kinematics and the "ee" action space: poses read off joints come back to those
joints, on random postures and on an expert's recorded targets."""

import numpy as np
import pytest

from rmbench.data.reader import Dataset
from rmbench.policies.action_space import EE_DIM, EEActions, action_dim, rotation_from_6d
from rmbench.sim import robot
from rmbench.sim.kinematics import GraspKinematics


def test_inverse_reaches_the_pose_forward_gave():
    kin, rng = GraspKinematics(), np.random.default_rng(0)
    for side in robot.SIDES:
        for _ in range(50):
            # reaching postures (elbow bent, gripper below the wrist), away from the limits
            q = np.array([0.0, -0.3, 0.5, 0.0, 1.0, 0.0]) + rng.normal(0, 0.3, 6)
            pos, mat = kin.forward(side, q)
            solved = kin.inverse(side, pos, mat, q + rng.normal(0, 0.05, 6))
            pos2, mat2 = kin.forward(side, solved)
            np.testing.assert_allclose(pos2, pos, atol=5e-4)
            np.testing.assert_allclose(mat2, mat, atol=5e-3)


def test_a_slightly_wrong_rotation_does_not_swing_a_straight_wrist():
    """At the tucked home pose forearm roll and wrist rotate turn about nearly one axis: a
    pose 0.02 rad off there must not ask them to swing apart."""
    kin = GraspKinematics()
    home = np.array([0.9, -1.2, 1.5, 0.0, 0.3, 0.0])
    pos, mat = kin.forward("left", home)
    c, s = np.cos(0.02), np.sin(0.02)
    tilted = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ mat
    solved = kin.inverse("left", pos, tilted, home)
    assert np.abs(solved - home).max() < 0.05, solved - home


def test_inverse_stays_within_the_joint_limits():
    kin = GraspKinematics()
    far = np.array([5.0, 0.0, 3.0])  # out of reach: the nearest the iterations find
    q = kin.inverse("left", far, np.eye(3), np.zeros(6))
    assert np.all(q >= kin.low["left"]) and np.all(q <= kin.high["left"])


def test_both_arms_in_one_pass_give_each_arms_own_numbers():
    """``forward_arms`` (what a training's pose statistics read over every frame) gives
    ``forward``'s bytes, arm by arm, whatever the other arm does; so does ``from_joints``."""
    kin, rng = GraspKinematics(), np.random.default_rng(2)
    q = rng.uniform(-1.0, 1.0, (40, len(robot.SIDES), 6))
    pos, mat = kin.forward_arms(q)
    assert pos.shape == (40, 2, 3) and mat.shape == (40, 2, 3, 3)
    for t in range(len(q)):
        for k, side in enumerate(robot.SIDES):
            p1, m1 = kin.forward(side, q[t, k])
            np.testing.assert_array_equal(pos[t, k], p1)
            np.testing.assert_array_equal(mat[t, k], m1)
    joints = np.concatenate([q[:, 0], rng.uniform(0, 1, (40, 1)), q[:, 1],
                             rng.uniform(0, 1, (40, 1))], 1)
    poses = EEActions().from_joints(joints)
    for k, side in enumerate(robot.SIDES):
        p1, m1 = kin.forward(side, joints[7, 7 * k: 7 * k + 6])
        np.testing.assert_array_equal(poses[7, 10 * k: 10 * k + 3], p1.astype(np.float32))
        np.testing.assert_array_equal(poses[7, 10 * k + 3: 10 * k + 9],
                                      m1[:, :2].T.reshape(6).astype(np.float32))
    with pytest.raises(ValueError, match=r"forward_arms reads joints \(T, 2, 6\)"):
        kin.forward_arms(np.zeros((3, 12)))


def test_rotation_from_6d_is_a_rotation_and_keeps_a_rotation():
    rng = np.random.default_rng(1)
    r = rotation_from_6d(rng.normal(size=6))
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(rotation_from_6d(r[:, :2].T.reshape(6)), r, atol=1e-12)


def test_pose_actions_round_trip_an_experts_targets(dataset):
    ep = Dataset(dataset).episode(0, cameras=[])
    convert = EEActions()
    poses = convert.from_joints(ep.action)
    assert poses.shape == (len(ep), EE_DIM) and poses.dtype == np.float32
    np.testing.assert_array_equal(poses[:, 9], ep.action[:, 6])  # grippers pass through
    np.testing.assert_array_equal(poses[:, 19], ep.action[:, 13])
    # chunk by chunk as the policy runs them, warm-started from the measured joints: the
    # same poses (the joints may differ along a straight wrist's roll-rotate direction)
    for t in range(0, len(ep), 20):
        joints = convert.to_joints(poses[t:t + 20], ep.state[t])
        again = convert.from_joints(joints)
        np.testing.assert_allclose(again[:, [0, 1, 2, 10, 11, 12]],
                                   poses[t:t + 20][:, [0, 1, 2, 10, 11, 12]], atol=1e-3)
        np.testing.assert_allclose(again, poses[t:t + 20], atol=2e-2)


def test_unknown_action_space_is_a_one_line_error():
    with pytest.raises(ValueError, match="unknown action space 'cartesian'"):
        action_dim("cartesian")


def test_reach_grid_puts_the_grasp_site_top_down_over_the_point():
    """Where an arm reaches (put_back_block's mats and centre, from either arm), the grid's
    interpolated joints put the grasp site within 2 mm of the point at the reach height,
    pointing down, fingers across the reach direction."""
    from rmbench.sim.geometry import top_down_mat
    from rmbench.sim.kinematics import REACH_HEIGHT, natural_yaw, reach_grid
    from rmbench.sim.station import TABLE_TOP

    grid, kin, rng = reach_grid(), GraspKinematics(), np.random.default_rng(1)
    for side, sign in (("left", -1), ("right", 1)):
        for _ in range(40):
            xy = np.array([sign * rng.uniform(-0.05, 0.25), rng.uniform(-0.25, 0.04)])
            pos, mat = kin.forward(side, grid.joints(side, xy))
            np.testing.assert_allclose(pos, [*xy, TABLE_TOP + REACH_HEIGHT], atol=2e-3)
            np.testing.assert_allclose(mat, top_down_mat(natural_yaw(side, pos)), atol=2e-2)
    # many points at once, and outside the area the edge's value
    many = grid.joints("left", np.zeros((3, 4, 2)))
    assert many.shape == (3, 4, 6)
    np.testing.assert_allclose(grid.joints("left", np.array([9.0, 0.0])),
                               grid.joints("left", np.array([grid.xs[-1], 0.0])))
