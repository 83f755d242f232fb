"""Motion primitives shared by every scripted expert.

A :class:`Motion` keeps the commanded 14-d target (what the servos are tracking) and turns
high-level moves into per-control-step actions. Every primitive is a generator of actions,
so experts compose them with ``yield from`` and read the live scene between primitives.
Cartesian moves are straight lines of the grasp site with minimum-jerk timing, solved by IK
step by step from the previous solution; moves from far away (home) go in joint space.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from rmbench.experts.ik import ArmIK, top_down_quat
from rmbench.sim.kinematics import natural_yaw
from rmbench.sim.simulator import ARM_ENTRIES, servo_setpoint
from rmbench.sim.station import ARM_MOUNTS, HOME_ARM, StationConfig, home_action

FINGER_TIP_BELOW_SITE = 0.017  # fingertips reach this far below the grasp site
HOVER = 0.10  # approach height of the grasp site above its target
CARRY_SPEED = 0.30  # m/s
FINE_SPEED = 0.15  # m/s, last centimetres of descents
JOINT_SPEED = 1.6  # rad/s, joint-space moves
CLOSED, OPEN = 0.0, 1.0
OPEN_SETTLE = 15  # steps for fingers reopened at home to come to rest
# Joint feedback: every step the measured joints are compared with where the servos should
# be (the commands sent, through the servos' known lag) and the difference, low-passed with
# this gain per step, is taken off the next command. A slow error (a drift, an offset, sag
# under load) is removed within a few steps. The price is a little step-to-step jitter: an
# EMA of white noise adds GAIN / (2 - GAIN) of its variance (0.43 here, a 20% larger std),
# against a drift followed within about two steps.
# Comparing with the lagged setpoint, not the command itself, matters: the lag read as an
# offset would make every move overshoot by the distance the servos trail.
FEEDBACK_GAIN = 0.6
FEEDBACK_LIMIT = 0.15  # rad: never correct more than this per joint

ALIGN_TOL = 0.003  # m: line up until the held piece is this close to its target (xy)
ALIGN_STEPS = 3  # corrections at most
# Share of the held piece's offset from its target corrected per step on the way down. The
# piece trails the command by a step or two (the servos' lag), so a larger share overshoots.
DESCENT_GAIN = 0.3
# Steering by the piece's offset in the hand (``Handle.in_hand``): that offset (an off-centre
# grasp, a cell slipped along the fingers) changes slowly, so it is low-passed with this gain
# per step; the piece is let go this far above its resting height.
IN_HAND_GAIN = 0.3
IN_HAND_CLEARANCE = 0.002
PLACE_TOL = 0.02  # m: a piece set down farther than this from its target is set down again
ATTEMPTS = 3  # grasps (and set-downs) of one piece before the expert gives up

Actions = Iterator[np.ndarray]


class GaveUp(Exception):
    """The expert cannot finish the episode (a piece out of reach, a grasp that keeps failing):
    the episode ends as a task failure with this reason. Never a crash."""


@dataclass(frozen=True)
class Handle:
    """How an expert takes hold of a movable piece, read live from the scene each attempt.

    locate: () -> (grasp centre in world coordinates, the piece's yaw), now.
    height: the held part's height (the fingers close 1 cm above its bottom).
    symmetry: the piece looks the same turned by this angle (grasp yaws repeat with it).
    opening: finger opening to approach with (less inside trays and beside plates).
    hover: approach and lift height above the grasp point.
    in_hand: set down by the piece's offset in the hand (see ``Motion.place``).
    """

    locate: Callable[[], tuple[np.ndarray, float]]
    height: float
    symmetry: float = np.pi / 2
    opening: float = OPEN
    hover: float = HOVER
    in_hand: bool = False


def min_jerk(n: int) -> np.ndarray:
    """n samples in (0, 1] of the minimum-jerk profile."""
    s = np.arange(1, n + 1) / n
    return 10 * s**3 - 15 * s**4 + 6 * s**5


def grasp_yaw(side: str, xy, object_yaw: float, symmetry: float = np.pi / 2,
              prefer: float | None = None) -> float:
    """Of the object's symmetric grasp yaws, the one closest to ``prefer`` (default: the arm's
    natural yaw at ``xy``)."""
    nat = natural_yaw(side, xy) if prefer is None else prefer
    k = np.round((nat - object_yaw) / symmetry)
    return float(object_yaw + k * symmetry)


def nearer_side(xy) -> str:
    """The arm whose base is closer to ``xy`` in the table plane."""
    d = {side: np.hypot(xy[0] - m.pos[0], xy[1] - m.pos[1]) for side, m in ARM_MOUNTS.items()}
    return min(d, key=d.get)


class Motion:
    """The commanded target of both arms and the primitives that move it, one control step
    per yielded action. ``observe`` (measured joints) and ``compensate`` (the action sent)
    close the loop on the joints; the primitives that touch pieces check the live scene."""

    def __init__(self, ik: ArmIK, substeps: int = 25, servo_gain: float = 1.0,
                 period: float = 1.0 / StationConfig.control_hz):
        self.ik = ik
        # s per control step (the station's): a move takes length / (speed * period) steps, and half again
        self.period = period
        self.cmd = home_action()
        self.away: set[str] = set()  # arms out of their home pose
        self.offset = np.zeros(len(ARM_ENTRIES))  # estimated executed-minus-commanded joints
        self.sent: np.ndarray | None = None  # the last action handed out
        self.substeps, self.servo_gain = substeps, servo_gain  # the station's servos
        self.setpoint = self.cmd.copy()  # where the servos should be, had no noise been added
        self.measured: np.ndarray | None = None  # the last measured joints (agent_pos)

    def observe(self, agent_pos: np.ndarray) -> None:
        """Update the joint-offset estimate from the measured joints (see FEEDBACK_GAIN)."""
        self.measured = agent_pos.copy()
        if self.sent is None:
            return
        error = agent_pos[ARM_ENTRIES] - self.setpoint[ARM_ENTRIES]
        self.offset += FEEDBACK_GAIN * (error - self.offset)
        np.clip(self.offset, -FEEDBACK_LIMIT, FEEDBACK_LIMIT, out=self.offset)

    def compensate(self, action: np.ndarray) -> np.ndarray:
        """``action`` corrected by the estimated joint offset (a new array)."""
        out = np.array(action, float)
        out[ARM_ENTRIES] -= self.offset
        start = self.setpoint if self.sent is None else self.sent  # at rest at first
        for i in range(1, self.substeps + 1):
            self.setpoint = servo_setpoint(self.setpoint, start, out, i / self.substeps,
                                           self.servo_gain)
        self.sent = out.copy()
        return out

    def clear_for(self, side: str) -> Actions:
        """Send the other arm home first if it is out: the arms never work side by side."""
        other = "right" if side == "left" else "left"
        if other in self.away:
            yield from self.go_home(other)

    @staticmethod
    def _slice(side: str) -> slice:
        return slice(0, 6) if side == "left" else slice(7, 13)

    @staticmethod
    def _grip(side: str) -> int:
        return 6 if side == "left" else 13

    def joints(self, side: str) -> np.ndarray:
        return self.cmd[self._slice(side)].copy()

    def site_pos(self, side: str) -> np.ndarray:
        return self.ik.forward(side, self.joints(side))[0]

    def measured_site_pos(self, side: str) -> np.ndarray:
        """Where the grasp site is, from the measured joints (the commanded ones if none)."""
        q = self.joints(side) if self.measured is None else self.measured[self._slice(side)]
        return self.ik.forward(side, q)[0]

    def gripper_yaw(self, side: str) -> float:
        """World direction in which the commanded fingers close (see top_down_quat)."""
        mat = self.ik.forward(side, self.joints(side))[1]
        return float(np.arctan2(mat[1, 1], mat[0, 1]))

    # -------------------------------------------------------------- primitives
    def hold(self, steps: int) -> Actions:
        for _ in range(steps):
            yield self.cmd.copy()

    def gripper(self, side: str, value: float, steps: int = 6) -> Actions:
        start = self.cmd[self._grip(side)]
        if start == value:
            return
        for s in min_jerk(steps):
            self.cmd[self._grip(side)] = start + (value - start) * s
            yield self.cmd.copy()

    def move_joints(self, side: str, target: np.ndarray, speed: float = JOINT_SPEED) -> Actions:
        self.away.add(side)
        start = self.joints(side)
        n = max(int(np.ceil(np.abs(target - start).max() / (speed * self.period) * 1.5)), 2)
        for s in min_jerk(n):
            self.cmd[self._slice(side)] = start + (target - start) * s
            yield self.cmd.copy()

    def move_to(self, side: str, pos, yaw: float, speed: float = CARRY_SPEED) -> Actions:
        """Straight line of the grasp site to ``pos`` with the gripper pointing down."""
        self.away.add(side)
        start = self.site_pos(side)
        pos = np.asarray(pos, float)
        n = max(int(np.ceil(np.linalg.norm(pos - start) / (speed * self.period) * 1.5)), 2)
        quat = top_down_quat(yaw)
        q = self.joints(side)
        for s in min_jerk(n):
            q, _ = self.ik.solve(side, start + (pos - start) * s, quat, seed=q)
            self.cmd[self._slice(side)] = q
            yield self.cmd.copy()

    def approach(self, side: str, pos, yaw: float, park: bool = False) -> Actions:
        """From anywhere (e.g. home) to a top-down pose at ``pos`` through joint space. An arm
        already out is solved from where it is, so the wrist does not unwind a turn; unless it
        parks: then it takes the one solution found from the reaching posture, so where it
        waits does not show where it has been (a memory task's arm must not be its memory)."""
        seed = self.joints(side) if side in self.away and not park else None
        q, err = self.ik.solve(side, pos, top_down_quat(yaw), seed=seed)
        if err > 0.005:
            raise GaveUp(f"{side} arm cannot reach {np.round(pos, 3)} (IK error {err:.3f} m)")
        yield from self.move_joints(side, q)

    def go_home(self, side: str) -> Actions:
        yield from self.move_joints(side, np.array(HOME_ARM[side]))
        self.away.discard(side)

    def retreat(self) -> Actions:
        """Every arm that is out goes home."""
        for side in sorted(self.away):
            yield from self.go_home(side)

    def retreat_open(self) -> Actions:
        """Every arm that is out goes home, then opens its fingers as at reset and holds while
        they come to rest: a hand left closed or half open at home would tell every later
        moment from an earlier one without memory."""
        moved = sorted(self.away)
        yield from self.retreat()
        for side in moved:
            yield from self.gripper(side, OPEN)
        if moved:
            yield from self.hold(OPEN_SETTLE)

    def move_by(self, side: str, delta, yaw: float, speed: float = CARRY_SPEED) -> Actions:
        yield from self.move_to(side, self.site_pos(side) + np.asarray(delta), yaw, speed)

    def grasp(self, side: str, centre, yaw: float, height: float, opening: float = OPEN,
              hover: float = HOVER) -> Actions:
        """Open (to ``opening``, less inside trays), come down over ``centre`` (the object's
        centre, ``height`` tall), close, lift."""
        centre = np.asarray(centre, float)
        grip_z = centre[2] - height / 2 + FINGER_TIP_BELOW_SITE + 0.010
        grip = np.array([centre[0], centre[1], max(grip_z, centre[2] - 0.01)])
        yield from self.gripper(side, opening, 4)
        yield from self.approach(side, grip + (0, 0, hover), yaw)
        yield from self.move_to(side, grip, yaw, FINE_SPEED)
        yield from self.gripper(side, CLOSED, 8)
        yield from self.hold(3)
        yield from self.move_to(side, grip + (0, 0, hover), yaw, FINE_SPEED)

    def place(self, side: str, target, yaw: float, height: float, opening: float = OPEN,
              hover: float = HOVER,
              locate: Callable[[], tuple[np.ndarray, float]] | None = None,
              in_hand: bool = False) -> Actions:
        """Carry the held object over ``target`` (table xy, z of the surface), set it down, open
        (to ``opening``), and rise. With ``locate`` (the held piece's grasp centre, live), the
        hand is steered on the way down so that the piece itself, not the hand, arrives over
        the target: that absorbs an off-centre grasp and a drifting arm.

        ``in_hand`` steers by the piece's offset from the measured hand instead of its offset
        from the target, in height as well, and lets go at once. Chasing the piece's offset
        from the target also chases the arm's step-to-step jitter, which the joint feedback
        already takes out a step later: under smooth action noise the two corrections added
        up and battery_try's cells reached the bottom a median 7 mm off, pressed into the
        table or held 1-2 cm above it; and opening over 6 steps let the jittering hand drag a
        cell further off its slot."""
        target = np.asarray(target, float)
        release = np.array([target[0], target[1],
                            target[2] + FINGER_TIP_BELOW_SITE + 0.010 + 0.004])
        yield from self.move_to(side, release + (0, 0, hover), yaw)
        if locate is not None and in_hand:
            low = np.array([*target[:2], target[2] + height / 2 + IN_HAND_CLEARANCE])
            yield from self.hold(2)  # let the piece stop swinging before looking
            grip = locate()[0] - self.measured_site_pos(side)
            aim = low - grip  # the hand's target for the piece to sit at ``low``
            yield from self.move_to(side, aim + (0, 0, hover), yaw, FINE_SPEED)
            quat, q = top_down_quat(yaw), self.joints(side)
            n = max(int(np.ceil(hover / (FINE_SPEED * self.period) * 1.5)), 2)
            for s in min_jerk(n):
                grip += IN_HAND_GAIN * (locate()[0] - self.measured_site_pos(side) - grip)
                aim = low - grip
                q, _ = self.ik.solve(side, aim + (0, 0, hover * (1 - s)), quat, seed=q)
                self.cmd[self._slice(side)] = q
                yield self.cmd.copy()
            release = aim
        elif locate is not None:
            # Lined up at the hover height, then kept over the target all the way down: each
            # step the piece's own offset nudges the hand (a drift changes within the descent).
            aim = release.copy()
            for _ in range(ALIGN_STEPS):
                yield from self.hold(2)  # let the piece stop swinging before looking
                error = target[:2] - locate()[0][:2]
                if np.linalg.norm(error) <= ALIGN_TOL:
                    break
                aim[:2] += error
                yield from self.move_to(side, aim + (0, 0, hover), yaw, FINE_SPEED)
            quat, q = top_down_quat(yaw), self.joints(side)
            n = max(int(np.ceil(hover / (FINE_SPEED * self.period) * 1.5)), 2)
            for s in min_jerk(n):
                aim[:2] += DESCENT_GAIN * (target[:2] - locate()[0][:2])
                q, _ = self.ik.solve(side, aim + (0, 0, hover * (1 - s)), quat, seed=q)
                self.cmd[self._slice(side)] = q
                yield self.cmd.copy()
            release = aim
        yield from self.move_to(side, release, yaw, FINE_SPEED)
        yield from self.gripper(side, opening, 2 if in_hand else 6)
        yield from self.move_to(side, release + (0, 0, hover), yaw, FINE_SPEED)

    def transfer(self, side: str, pos, object_yaw: float, height: float, dest,
                 symmetry: float = np.pi / 2, turn: float = 0.0, opening: float = OPEN,
                 hover: float = HOVER) -> Actions:
        """Pick the object at ``pos`` (centre) and set it down at ``dest`` (table xy and surface
        z), turned by ``turn`` about z."""
        yaw = grasp_yaw(side, pos[:2], object_yaw, symmetry,
                        self.gripper_yaw(side) if side in self.away else None)
        yield from self.grasp(side, pos, yaw, height, opening, hover)
        if abs(turn) > 1e-3:
            yield from self.twist(side, turn)
        yield from self.place(side, dest, yaw + turn, height, opening, hover)

    def carry(self, side: str, handle: Handle, dest, turn_to: Callable[[float], float] | None = None,
              placed: Callable[[], bool] | None = None) -> Actions:
        """Pick the piece up and set it down at ``dest`` (table xy and surface z), checking each
        step against the live scene: a grasp that did not lift the piece is tried again from
        where the piece now lies, and so is a set-down that missed (``placed``, by default the
        grasp centre within PLACE_TOL of ``dest`` in xy). ``turn_to`` maps the piece's yaw at
        the grasp to the turn it needs. Gives up after ATTEMPTS tries."""
        dest = np.asarray(dest, float)
        if placed is None:
            def placed() -> bool:
                return bool(np.linalg.norm(handle.locate()[0][:2] - dest[:2]) <= PLACE_TOL)
        for _ in range(ATTEMPTS):
            pos, piece_yaw = handle.locate()
            yaw = grasp_yaw(side, pos[:2], piece_yaw, handle.symmetry,
                            self.gripper_yaw(side) if side in self.away else None)
            yield from self.grasp(side, pos, yaw, handle.height, handle.opening, handle.hover)
            if handle.locate()[0][2] < pos[2] + handle.hover / 2:  # it stayed behind
                yield from self.gripper(side, handle.opening, 4)
                continue
            turn = turn_to(piece_yaw) if turn_to is not None else 0.0
            if abs(turn) > 1e-3:
                yield from self.twist(side, turn)
            yield from self.place(side, dest, yaw + turn, handle.height, handle.opening,
                                  handle.hover, handle.locate, handle.in_hand)
            if placed():
                return
        raise GaveUp(f"could not move a piece to {np.round(dest[:2], 3).tolist()} in "
                     f"{ATTEMPTS} attempts")

    def twist(self, side: str, angle: float, speed: float = 2 * JOINT_SPEED) -> Actions:
        """Turn the held object about the vertical with the wrist alone (the gripper points
        down, so the wrist-rotate axis is vertical); the other way round if the joint range
        requires it."""
        q = self.joints(side)
        target = q[5] - angle  # the wrist-rotate axis points down: +joint is -yaw
        if abs(target) > np.pi:
            target -= np.sign(target) * 2 * np.pi
        q[5] = target
        yield from self.move_joints(side, q, speed)

    def press(self, side: str, top, depth: float = 0.012, approach: bool = True,
              count: Callable[[], int] | None = None) -> Actions:
        """Push down on the point ``top`` with closed fingers, and come up. ``depth`` is the
        commanded travel: past the 1 cm end stop, so servo lag still bottoms the button out.
        With ``count`` (the button's press counter), a push that did not register is made
        again, as a person would who felt no click; the expert gives up after ATTEMPTS."""
        before = count() if count is not None else 0
        for attempt in range(ATTEMPTS):
            yield from self._push(side, top, depth, approach and attempt == 0)
            if count is None or count() > before:
                return
        raise GaveUp(f"{ATTEMPTS} pushes on the button at {np.round(top[:2], 3).tolist()} did "
                     f"not register")

    def _push(self, side: str, top, depth: float, approach: bool) -> Actions:
        top = np.asarray(top, float)
        yaw = natural_yaw(side, top)
        above = top + (0, 0, FINGER_TIP_BELOW_SITE + 0.04)
        down = top + (0, 0, FINGER_TIP_BELOW_SITE - depth)
        yield from self.gripper(side, CLOSED, 4)
        if approach:
            yield from self.approach(side, above, yaw)
        else:
            yield from self.move_to(side, above, yaw)
        yield from self.move_to(side, down, yaw, FINE_SPEED)
        yield from self.hold(2)
        yield from self.move_to(side, above, yaw, FINE_SPEED)
