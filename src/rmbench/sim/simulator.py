"""A compiled station: stepping with interpolated setpoints, proprioception, rendering."""

from __future__ import annotations

import atexit
import functools
import weakref

import mujoco
import numpy as np

from rmbench.sim import robot
from rmbench.sim.geometry import mat_to_quat
from rmbench.sim.gl import require_rendering
from rmbench.sim.station import MAX_QVEL, MAX_SPIN, SimulationError, StationConfig, home_action

ACTION_DIM = 14  # an action, and the joint state: per arm 6 joints then the gripper
ARM_ENTRIES = np.r_[0:6, 7:13]  # action entries of the 12 arm joints (not the grippers)
EE_POSE_DIM = 14
# Renderers freed by the garbage collector after MuJoCo's own exit hook has terminated the
# EGL display make EGL raise. Our hook is registered after the first context exists, i.e.
# after MuJoCo's, so it runs first (atexit is last-in, first-out) and closes them in time.
_LIVE: weakref.WeakSet = weakref.WeakSet()


@functools.cache
def _register_exit_hook() -> None:
    atexit.register(lambda: [sim.close() for sim in list(_LIVE)])


def servo_setpoint(setpoint: np.ndarray, start: np.ndarray, goal: np.ndarray, fraction: float,
                   gain: float) -> np.ndarray:
    """The servos' setpoint after one physics step: it moves ``gain`` of the way to the
    reference, which runs linearly from ``start`` to ``goal`` over the control period
    (``fraction`` of it has passed). Controllers that predict the arm use the same rule."""
    return setpoint + gain * (start + (goal - start) * fraction - setpoint)


def gripper_opening(finger):
    """A finger's slide position (metres from the gripper's centre line) as the gripper
    opening agent_pos reports: 0 at the closed end of its range, 1 at the open end."""
    return (finger - robot.FINGER_CLOSED) / (robot.FINGER_OPEN - robot.FINGER_CLOSED)


def data_renderer(model: mujoco.MjModel, width: int, height: int) -> mujoco.Renderer:
    """A renderer set up for data cameras: no shadows, reflections or skybox (the model's
    offscreen buffer already has anti-aliasing off)."""
    r = mujoco.Renderer(model, height=height, width=width)
    for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION,
                 mujoco.mjtRndFlag.mjRND_SKYBOX):
        r.scene.flags[flag] = False
    return r


class Simulator:
    """Owns the MjModel/MjData of one compiled scene and the robot's index tables."""

    def __init__(self, model: mujoco.MjModel, config: StationConfig):
        self.model = model
        self.data = mujoco.MjData(model)
        self.config = config
        m = model
        # each dof's runaway limit: the spin of a free piece (a free joint's last 3 dofs) may
        # far exceed what a joint or a translation reaches in sound physics
        self.qvel_limit = np.full(m.nv, MAX_QVEL)
        for j in np.flatnonzero(m.jnt_type == mujoco.mjtJoint.mjJNT_FREE):
            self.qvel_limit[m.jnt_dofadr[j] + 3: m.jnt_dofadr[j] + 6] = MAX_SPIN
        # Per side: 6 arm joint qpos/qvel addresses, then the two finger joints.
        self.arm_qpos = {}
        self.arm_dof = {}
        self.finger_qpos = {}
        self.arm_act = {}
        self.finger_act = {}
        for side in robot.SIDES:
            joints = [m.joint(f"{side}/{j}") for j in robot.ARM_JOINTS]
            self.arm_qpos[side] = np.array([j.qposadr[0] for j in joints])
            self.arm_dof[side] = np.array([j.dofadr[0] for j in joints])
            self.finger_qpos[side] = np.array(
                [m.joint(f"{side}/{f}").qposadr[0] for f in ("left_finger", "right_finger")])
            self.arm_act[side] = np.array([m.actuator(f"{side}/{j}").id for j in robot.ARM_JOINTS])
            self.finger_act[side] = np.array(
                [m.actuator(f"{side}/{f}").id for f in ("left_finger", "right_finger")])
        self.ctrl_lo = m.actuator_ctrlrange[:, 0].copy()
        self.ctrl_hi = m.actuator_ctrlrange[:, 1].copy()
        self.arm_range = {
            side: m.jnt_range[[m.joint(f"{side}/{j}").id for j in robot.ARM_JOINTS]]
            for side in robot.SIDES}
        self.action_low = np.concatenate(
            [np.append(self.arm_range[s][:, 0], 0.0) for s in robot.SIDES])
        self.action_high = np.concatenate(
            [np.append(self.arm_range[s][:, 1], 1.0) for s in robot.SIDES])
        self.grasp_sites = np.array([m.site(f"{side}/grasp").id for side in robot.SIDES])
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._target = np.zeros(m.nu)
        # Per physics step, the setpoint moves this fraction of the way to the reference.
        self.servo_gain = (1.0 if config.servo_tau == 0
                            else float(-np.expm1(-config.timestep / config.servo_tau)))

    # ------------------------------------------------------------------ state
    def reset_robot(self, action: np.ndarray | None = None) -> None:
        """Put both arms exactly at ``action`` (default: home) at rest."""
        action = home_action() if action is None else np.asarray(action, float)
        ctrl = self.action_to_ctrl(action)
        for side in robot.SIDES:
            self.data.qpos[self.arm_qpos[side]] = ctrl[self.arm_act[side]]
            self.data.qpos[self.finger_qpos[side]] = ctrl[self.finger_act[side]]
        self.data.qvel[:] = 0.0
        self.data.ctrl[:] = ctrl
        self._target = ctrl.copy()
        mujoco.mj_forward(self.model, self.data)

    def action_to_ctrl(self, action: np.ndarray) -> np.ndarray:
        ctrl = np.zeros(self.model.nu)
        for k, side in enumerate(robot.SIDES):
            a = action[7 * k: 7 * k + 7]
            ctrl[self.arm_act[side]] = a[:6]
            finger = robot.FINGER_CLOSED + a[6] * (robot.FINGER_OPEN - robot.FINGER_CLOSED)
            ctrl[self.finger_act[side]] = (finger, -finger)
        return ctrl

    def agent_pos(self) -> np.ndarray:
        """Proprioception in the action layout: 6 joints + gripper opening, per arm, as the
        physics has them (a joint can stand past its limit: see RMBenchEnv._observation)."""
        out = np.empty(ACTION_DIM)
        for k, side in enumerate(robot.SIDES):
            out[7 * k: 7 * k + 6] = self.data.qpos[self.arm_qpos[side]]
            out[7 * k + 6] = gripper_opening(self.data.qpos[self.finger_qpos[side][0]])
        return out

    def agent_pos_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Per entry of agent_pos, the range the model's joint limits (``jnt_range``) give it:
        an arm joint's own range; the gripper's, its finger's range through the mapping
        agent_pos reads the finger with (which is exactly [0, 1])."""
        m = self.model
        low, high = np.empty(ACTION_DIM), np.empty(ACTION_DIM)
        for k, side in enumerate(robot.SIDES):
            low[7 * k: 7 * k + 6], high[7 * k: 7 * k + 6] = self.arm_range[side].T
            # the finger agent_pos reads (finger_qpos[side][0])
            finger = m.joint(f"{side}/left_finger").range
            low[7 * k + 6], high[7 * k + 6] = gripper_opening(finger)
        return low, high

    def ee_pose(self, data: mujoco.MjData | None = None) -> np.ndarray:
        """End-effector poses (14,): per arm the point between the fingertips (x, y, z, world
        frame) and the gripper orientation as a unit quaternion (w, x, y, z), w >= 0; of
        ``data`` (another state of this model) if given."""
        d = self.data if data is None else data
        out = np.empty(EE_POSE_DIM)
        for k, sid in enumerate(self.grasp_sites):
            quat = mat_to_quat(d.site_xmat[sid].reshape(3, 3))
            out[7 * k: 7 * k + 3] = d.site_xpos[sid]
            out[7 * k + 3: 7 * k + 7] = quat if quat[0] >= 0 else -quat
        return out

    # ---------------------------------------------------------------- control
    def clip_action(self, action: np.ndarray) -> tuple[np.ndarray, int]:
        """Clip to joint limits and gripper [0, 1]; return the clipped action and how many."""
        clipped = np.clip(action, self.action_low, self.action_high)
        return clipped, int(np.count_nonzero(clipped != action))

    def step(self, action: np.ndarray, on_substep=None) -> None:
        """Run one control period towards ``action`` (already validated and clipped): the
        reference moves linearly from the previous target to the new one, and the servo
        setpoints (``data.ctrl``) follow it with the first-order lag ``servo_tau``."""
        start = self._target
        goal = self.action_to_ctrl(action)
        n, ctrl = self.config.substeps, self.data.ctrl
        for i in range(1, n + 1):
            ctrl[:] = servo_setpoint(ctrl, start, goal, i / n, self.servo_gain)
            mujoco.mj_step(self.model, self.data)
            if on_substep is not None:
                on_substep()
        self._target = goal
        self.check_physics()

    def check_physics(self) -> None:
        d = self.data
        if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            raise SimulationError(f"non-finite state at t={d.time:.3f}s")
        over = np.abs(d.qvel) > self.qvel_limit
        if over.any():
            dof = int(np.flatnonzero(over)[0])
            raise SimulationError(f"runaway velocity {d.qvel[dof]:.1f} (dof {dof}) at "
                                  f"t={d.time:.3f}s")
        # MuJoCo resets the state itself when it meets a bad value, so its warnings are the
        # only trace of a blow-up inside the control period.
        for warning in ("BADQPOS", "BADQVEL", "BADQACC"):
            if d.warning[getattr(mujoco.mjtWarning, f"mjWARN_{warning}")].number > 0:
                raise SimulationError(f"physics diverged (MuJoCo reset the state after "
                                      f"mjWARN_{warning})")

    # -------------------------------------------------------------- rendering
    def renderer(self, width: int, height: int) -> mujoco.Renderer:
        key = (width, height)
        if key not in self._renderers:
            require_rendering()
            r = data_renderer(self.model, width, height)
            self._renderers[key] = r
            _LIVE.add(self)
            _register_exit_hook()
        return self._renderers[key]

    def render(self, cameras=None, width=None, height=None) -> dict[str, np.ndarray]:
        cameras = self.config.cameras if cameras is None else cameras
        r = self.renderer(width or self.config.width, height or self.config.height)
        frames = {}
        for cam in cameras:
            r.update_scene(self.data, camera=cam)
            frames[cam] = r.render()  # a fresh array per call
        return frames

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
