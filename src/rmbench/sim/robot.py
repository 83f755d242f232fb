"""The two ViperX 300s arms, composed from gym-aloha's asset files.

The asset files ship inside the ``gym_aloha`` wheel and are found with
``importlib.resources``; nothing is downloaded. We read the single-arm include files,
rename ``vx300s_left/...`` to ``left/...`` (and right), mount each arm where the station
wants it, and emit one MJCF document that :mod:`rmbench.sim.station` extends with MjSpec.
"""

from __future__ import annotations

import contextlib
import importlib.resources
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SIDES = ("left", "right")
ARM_JOINTS = ("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle", "wrist_rotate")
# The 14 joints a policy reads (agent_pos) and commands (the action), in that order.
JOINT_NAMES = tuple(f"{side}_{name}" for side in SIDES for name in (*ARM_JOINTS, "gripper"))
# Finger slide range of the asset (metres from the gripper centre line, per finger).
FINGER_CLOSED, FINGER_OPEN = 0.021, 0.057

# Position-actuator gains. The asset's own wrist gains (kp 10-50 against 30 N m of joint
# friction) leave the wrist centimetres off target; these gains track a smooth 20 Hz
# trajectory to ~1 mm at the gripper while staying stable at the 2 ms physics step.
KP = {"waist": 800, "shoulder": 1600, "elbow": 800, "forearm_roll": 150, "wrist_angle": 150,
      "wrist_rotate": 60, "finger": 200}
FORCE = {"waist": 150, "shoulder": 300, "elbow": 100, "forearm_roll": 30, "wrist_angle": 30,
         "wrist_rotate": 15, "finger": 12}
DAMPING = {"waist": 5.0, "shoulder": 8.0, "elbow": 5.0, "forearm_roll": 1.0, "wrist_angle": 1.0,
           "wrist_rotate": 0.5}
# Finger pads: rubber on a plastic or wooden piece (sliding friction about 1.5-2). At the
# asset's 1.0, a 50 g cube slid out of a 4 N grip within a dozen steps of a jittery carry.
FINGER_FRICTION = (2.0, 0.03, 0.0001)
FRICTIONLOSS = {"waist": 5.0, "shoulder": 6.0, "elbow": 6.0, "forearm_roll": 1.0,
                "wrist_angle": 1.0, "wrist_rotate": 0.5}


@dataclass(frozen=True)
class ArmMount:
    """Where an arm's base sits in the world and which way (yaw, radians) it faces."""

    pos: tuple[float, float, float]
    yaw: float


@contextlib.contextmanager
def asset_dir():
    """The gym-aloha asset directory as a real path (``as_file`` copes with zipped installs)."""
    files = importlib.resources.files("gym_aloha") / "assets"
    with importlib.resources.as_file(files) as path:
        yield Path(path)


def _quat_z(yaw: float) -> str:
    return f"{np.cos(yaw / 2):.9f} 0 0 {np.sin(yaw / 2):.9f}"


def _arm_body(assets: Path, side: str, mount: ArmMount) -> ET.Element:
    root = ET.parse(assets / f"vx300s_{side}.xml").getroot()
    body = root.find("body")
    assert body is not None, f"vx300s_{side}.xml has no arm body"
    old = f"vx300s_{side}"
    for el in body.iter():
        for key in ("name", "target", "mesh"):
            value = el.get(key)
            if value is not None and key != "mesh" and value.startswith(old):
                el.set(key, side + value[len(old):])
        if el.tag == "camera":
            el.set("name", f"{side}_wrist")
        if el.tag == "joint":
            short = el.get("name", "").split("/")[-1]
            el.set("frictionloss", str(FRICTIONLOSS.get(short, 1.0)))
            if short in DAMPING:
                el.set("damping", str(DAMPING[short]))
            el.set("armature", "0.01")
        if el.tag == "geom" and el.get("name", "").endswith("_gripper_finger"):
            el.set("friction", " ".join(str(v) for v in FINGER_FRICTION))
        if el.tag == "site" and el.get("name", "").startswith("cali_"):
            el.set("group", "4")
    body.set("name", f"{side}/base")
    body.set("pos", " ".join(f"{v:.6f}" for v in mount.pos))
    body.attrib.pop("euler", None)
    body.set("quat", _quat_z(mount.yaw))
    gripper = next(el for el in body.iter("body") if el.get("name") == f"{side}/gripper_link")
    # The point between the fingertips: what IK steers and what "the gripper" means in tasks.
    ET.SubElement(gripper, "site", name=f"{side}/grasp", pos="0.137 0 0", size="0.004",
                  rgba="0 1 0 0", group="4")
    return body


def arms_mjcf(mounts: dict[str, ArmMount]) -> tuple[str, dict[str, bytes]]:
    """MJCF text for both arms with their actuators, and the mesh files it refers to."""
    with asset_dir() as assets:
        deps = ET.parse(assets / "vx300s_dependencies.xml").getroot()
        mesh_files = {m.get("file"): (assets / m.get("file")).read_bytes()
                      for m in deps.iter("mesh")}
        bodies = [_arm_body(assets, side, mounts[side]) for side in SIDES]
    root = ET.Element("mujoco", model="rmbench_station")
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="auto",
                  inertiagrouprange="4 5", autolimits="true")
    asset = ET.SubElement(root, "asset")
    for mesh in deps.iter("mesh"):
        asset.append(mesh)
    world = ET.SubElement(root, "worldbody")
    world.extend(bodies)
    act = ET.SubElement(root, "actuator")
    for side in SIDES:
        for j in ARM_JOINTS:
            lo, hi = joint_range(bodies, f"{side}/{j}")
            ET.SubElement(act, "position", name=f"{side}/{j}", joint=f"{side}/{j}",
                          kp=str(KP[j]), ctrlrange=f"{lo} {hi}",
                          forcerange=f"{-FORCE[j]} {FORCE[j]}")
        for finger, sign in (("left_finger", 1), ("right_finger", -1)):
            lo, hi = sorted((sign * FINGER_CLOSED, sign * FINGER_OPEN))
            ET.SubElement(act, "position", name=f"{side}/{finger}", joint=f"{side}/{finger}",
                          kp=str(KP["finger"]), ctrlrange=f"{lo} {hi}",
                          forcerange=f"{-FORCE['finger']} {FORCE['finger']}")
    return ET.tostring(root, encoding="unicode"), mesh_files


def joint_range(bodies: list[ET.Element], name: str) -> tuple[str, str]:
    for body in bodies:
        for joint in body.iter("joint"):
            if joint.get("name") == name:
                lo, hi = joint.get("range", "-3.14158 3.14158").split()
                return lo, hi
    raise KeyError(name)
