"""The station: table, two ViperX 300s arms, cameras, lights, and the control loop.

World frame: origin on the floor under the table centre, +x to the robot's right, +y away
from the robot, +z up. The table top is 1.0 x 0.6 m at z = 0.75; its near edge is at
y = -0.30. Both arm bases face +y from behind the near edge.

Control: an action is 14 absolute targets (6 joints + gripper in [0, 1], left then right),
applied at ``control_hz`` (20 Hz). Each control period runs ``substeps`` physics steps of
``timestep`` seconds (25 x 2 ms) while a reference moves linearly from the previous target to
the new one and the actuator setpoints follow it with a 50 ms first-order lag (``servo_tau``),
so the position servos see a smooth reference instead of a step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from rmbench.sim import robot
from rmbench.sim.geometry import look_at_quat

TABLE_TOP = 0.75
TABLE_HALF = (0.5, 0.3)
ARM_MOUNTS = {
    "left": robot.ArmMount((-0.275, -0.40, 0.80), np.pi / 2),
    "right": robot.ArmMount((0.275, -0.40, 0.80), np.pi / 2),
}
# A tucked rest pose that keeps both arms out of the head camera's view of the table.
HOME_ARM = {"left": (0.9, -1.2, 1.5, 0.0, 0.3, 0.0), "right": (-0.9, -1.2, 1.5, 0.0, 0.3, 0.0)}
HOME_GRIPPER = 1.0
DEFAULT_CAMERAS = ("head", "left_wrist", "right_wrist")
ALL_CAMERAS = ("head", "left_wrist", "right_wrist", "third_person")
# Runaway-velocity thresholds: far beyond anything the servos command (rad/s, m/s), and for a
# free piece's spin (rad/s) far beyond what a struck piece reaches (a 4 cm cube knocked at
# 4.7 m/s spins at about 200 rad/s; a 2 cm piece's edge at 2,000 rad/s would move at 20 m/s).
MAX_QVEL = 200.0
MAX_SPIN = 2000.0


class SimulationError(RuntimeError):
    """The physics diverged (NaN state or runaway velocity)."""


@dataclass(frozen=True)
class StationConfig:
    """How the station simulates and renders.

    cameras: cameras rendered into observations (subset of ALL_CAMERAS).
    width, height: observation image size in pixels.
    control_hz: policy/control rate; one env step is one control period.
    timestep: physics step in seconds.
    render: False runs physics only (observations carry no pixels).
    servo_tau: time constant (s) of the servos' response to a new target. Real joint servos
        (the ViperX's Dynamixels) move to a new goal through a velocity/acceleration profile,
        not at once; modelled as a first-order lag of the setpoint. Without it a jumpy target
        shook the arms hard enough to throw a held battery or cover out of the fingers.
    """

    cameras: tuple[str, ...] = DEFAULT_CAMERAS
    width: int = 320
    height: int = 240
    control_hz: float = 20.0
    timestep: float = 0.002
    render: bool = True
    servo_tau: float = 0.05
    video_size: tuple[int, int] = field(default=(480, 360))

    def __post_init__(self):
        object.__setattr__(self, "cameras", tuple(self.cameras))
        unknown = [c for c in self.cameras if c not in ALL_CAMERAS]
        if unknown:
            raise ValueError(f"unknown camera(s) {unknown}; known: {list(ALL_CAMERAS)}")
        if len(set(self.cameras)) != len(self.cameras):
            raise ValueError(f"duplicate cameras in {self.cameras}")
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise ValueError(f"resolution {self.width}x{self.height} outside 16..4096")
        if self.control_hz <= 0 or self.timestep <= 0:
            raise ValueError("control_hz and timestep must be positive")
        if not self.servo_tau >= 0:
            raise ValueError(f"servo_tau must be >= 0, got {self.servo_tau}")
        n = round(1.0 / (self.control_hz * self.timestep))
        if n < 1 or abs(n * self.timestep * self.control_hz - 1.0) > 1e-6:
            raise ValueError(
                f"control period 1/{self.control_hz} s is not a whole number of "
                f"{self.timestep} s physics steps")

    @property
    def substeps(self) -> int:
        return round(1.0 / (self.control_hz * self.timestep))


def home_action() -> np.ndarray:
    return np.array([*HOME_ARM["left"], HOME_GRIPPER, *HOME_ARM["right"], HOME_GRIPPER])


def base_spec(config: StationConfig) -> mujoco.MjSpec:
    """The empty station (robot, table, cameras, lights) as an editable MjSpec."""
    xml, meshes = robot.arms_mjcf(ARM_MOUNTS)
    spec = mujoco.MjSpec.from_string(xml, assets=meshes)
    spec.option.timestep = config.timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    # Data cameras: no anti-aliasing (shadows are switched off per light and in the renderer).
    spec.visual.quality.offsamples = 0
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.45, 0.45, 0.45]
    spec.visual.global_.offwidth = max(config.width, config.video_size[0], 640)
    spec.visual.global_.offheight = max(config.height, config.video_size[1], 480)

    world = spec.worldbody
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[3, 3, 0.1],
                   rgba=[0.55, 0.57, 0.6, 1])
    table = world.add_body(name="table", pos=[0, 0, TABLE_TOP / 2])
    table.add_geom(name="table_top", type=mujoco.mjtGeom.mjGEOM_BOX,
                   size=[*TABLE_HALF, TABLE_TOP / 2], rgba=[0.62, 0.5, 0.38, 1],
                   friction=[1.0, 0.005, 0.0001])
    for side, mount in ARM_MOUNTS.items():
        x, y, z = mount.pos
        world.add_geom(name=f"{side}/pedestal", type=mujoco.mjtGeom.mjGEOM_BOX,
                       pos=[x, y, z / 2], size=[0.06, 0.06, z / 2], rgba=[0.2, 0.2, 0.22, 1],
                       contype=0, conaffinity=0)
    for pos, direction in (((-1, -1, 2.5), (1, 1, -2.5)), ((1, -1, 2.5), (-1, 1, -2.5))):
        world.add_light(pos=list(pos), dir=list(direction), type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                        castshadow=0,
                        diffuse=[0.35, 0.35, 0.35], specular=[0.1, 0.1, 0.1])
    _add_camera(spec, "head", (0.0, -0.55, 1.50), (0.0, -0.05, TABLE_TOP), fovy=58)
    _add_camera(spec, "third_person", (0.62, 0.42, 1.30), (0.0, -0.15, TABLE_TOP), fovy=50)
    return spec


def _add_camera(spec: mujoco.MjSpec, name: str, pos, target, fovy: float) -> None:
    spec.worldbody.add_camera(name=name, pos=list(pos), quat=list(look_at_quat(pos, target)),
                              fovy=fovy)
