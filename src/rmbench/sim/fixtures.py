"""Fixed scene pieces shared by the tasks: mats, trays, the battery holder, lamps, spring
buttons, seven-segment tiles and walls (shelves, screens).

A fixed piece is a body without joints; its table position changes per episode by editing
``model.body_pos`` at reset, so one compiled model serves every seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from rmbench.sim.objects import BOX, CYLINDER, explicit_inertia
from rmbench.sim.station import TABLE_TOP

MAT_RGBA = (0.15, 0.35, 0.75, 1.0)


@dataclass
class StaticPiece:
    """A fixed body whose table position changes per episode (mats, tiles, button bases)."""

    name: str
    body_id: int = -1

    def bind(self, model: mujoco.MjModel) -> None:
        self.body_id = model.body(self.name).id

    def move(self, model: mujoco.MjModel, xy) -> None:
        model.body_pos[self.body_id][:2] = xy

    def xy(self, model: mujoco.MjModel) -> np.ndarray:
        return model.body_pos[self.body_id][:2].copy()


@dataclass
class Mat(StaticPiece):
    """A thin square mat lying on the table; identical mats are what make layouts alias."""

    size: float = 0.08
    thickness: float = 0.002
    rgba: tuple = MAT_RGBA

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP])
        # Visual only: a 2 mm collision slab would make cubes rock at its edge.
        body.add_geom(name=f"{self.name}/geom", type=BOX,
                      size=[self.size / 2, self.size / 2, self.thickness / 2],
                      pos=[0, 0, self.thickness / 2], rgba=list(self.rgba),
                      contype=0, conaffinity=0)

    def contains(self, model: mujoco.MjModel, xy, tol: float) -> bool:
        return bool(np.linalg.norm(np.asarray(xy)[:2] - self.xy(model)) <= tol)


@dataclass
class Tray(StaticPiece):
    """A square tray: a visual floor and four low walls that collide. Identical trays alias
    the same way identical mats do; the walls keep a dropped cube from sliding out."""

    inner: float = 0.11
    wall: float = 0.006
    wall_height: float = 0.012
    rgba: tuple = (0.55, 0.55, 0.6, 1.0)

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP])
        half = self.inner / 2
        body.add_geom(name=f"{self.name}/floor", type=BOX, size=[half, half, 0.001],
                      pos=[0, 0, 0.001], rgba=list(self.rgba), contype=0, conaffinity=0)
        long, t, h = half + self.wall, self.wall / 2, self.wall_height / 2
        for k, (x, y, sx, sy) in enumerate(((half + t, 0, t, long), (-half - t, 0, t, long),
                                            (0, half + t, long, t), (0, -half - t, long, t))):
            body.add_geom(name=f"{self.name}/wall{k}", type=BOX, size=[sx, sy, h],
                          pos=[x, y, h], rgba=list(self.rgba))

    def contains(self, model: mujoco.MjModel, xy) -> bool:
        return bool(np.all(np.abs(np.asarray(xy)[:2] - self.xy(model)) <= self.inner / 2))


@dataclass
class BatteryHolder(StaticPiece):
    """Two battery slots side by side (along x, ``spacing`` apart), each a pair of contact
    plates at the ends of a cell lying along y. The plates stand 12 mm above a resting cell,
    so the head camera cannot see which way an inserted cell points: at 30 mm the near end's
    gold face showed over the near plate, in the 8 mm of play a slot leaves."""

    spacing: float = 0.07
    slot_length: float = 0.074
    plate: tuple = (0.03, 0.004, 0.036)  # x, y, z extent of a contact plate
    rgba: tuple = (0.3, 0.3, 0.34, 1.0)

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP])
        px, py, pz = (v / 2 for v in self.plate)
        body.add_geom(name=f"{self.name}/base", type=BOX,
                      size=[self.spacing / 2 + px + 0.01, self.slot_length / 2 + py * 2, 0.001],
                      pos=[0, 0, 0.001], rgba=[0.45, 0.45, 0.5, 1], contype=0, conaffinity=0)
        for k in (0, 1):
            x = (k - 0.5) * self.spacing
            for end in (-1, 1):
                body.add_geom(name=f"{self.name}/plate{k}{'ab'[end > 0]}", type=BOX,
                              size=[px, py, pz],
                              pos=[x, end * (self.slot_length / 2 + py), pz], rgba=list(self.rgba))

    def slot(self, model: mujoco.MjModel, k: int) -> np.ndarray:
        """Table xy of slot ``k`` (0 left, 1 right)."""
        return self.xy(model) + np.array([(k - 0.5) * self.spacing, 0.0])


LAMP_COLOURS = {"off": (0.3, 0.3, 0.3, 1.0), "red": (1.0, 0.1, 0.1, 1.0),
                "green": (0.1, 1.0, 0.2, 1.0)}


@dataclass
class Lamp(StaticPiece):
    """An indicator light on a small post: off, red or green. Tasks use it to reveal a verdict
    (the battery holder's light, the ranking button's answer) that the policy must remember."""

    radius: float = 0.014
    height: float = 0.03
    state: str = "off"
    geom_id: int = -1

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP])
        body.add_geom(name=f"{self.name}/post", type=CYLINDER, size=[0.006, self.height / 2],
                      pos=[0, 0, self.height / 2], rgba=[0.2, 0.2, 0.22, 1],
                      contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/bulb", type=mujoco.mjtGeom.mjGEOM_SPHERE,
                      size=[self.radius, 0, 0], pos=[0, 0, self.height + self.radius * 0.6],
                      rgba=list(LAMP_COLOURS["off"]), contype=0, conaffinity=0)

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self.geom_id = model.geom(f"{self.name}/bulb").id

    def set(self, model: mujoco.MjModel, state: str) -> None:
        self.state = state
        model.geom_rgba[self.geom_id] = LAMP_COLOURS[state]


@dataclass
class Button(StaticPiece):
    """A spring-loaded push button with press counting.

    The cap slides down along z against a preloaded spring (joint stiffness with springref
    above the upper limit). A press counts once per push, the way a person counts them: the
    cap must travel past ``press_depth`` (the click), then come back above ``release_depth``
    and stay there for ``rearm_time`` seconds before a push can count again. A finger that
    shakes on the cap, or lifts off and lands again within that time, makes one press.
    """

    cap_rgba: tuple = (0.9, 0.15, 0.15, 1.0)
    radius: float = 0.025
    travel: float = 0.01
    press_depth: float = 0.006
    release_depth: float = 0.003
    rearm_time: float = 0.15  # s; a deliberate second push takes longer than this to come
    base_height: float = 0.02
    cap_height: float = 0.015
    count: int = 0
    armed: bool = True
    released_at: float | None = None  # when the cap last came back above release_depth
    qpos_adr: int = -1

    def build(self, spec: mujoco.MjSpec) -> None:
        base = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP])
        base.add_geom(name=f"{self.name}/base", type=CYLINDER,
                      size=[self.radius + 0.012, self.base_height / 2],
                      pos=[0, 0, self.base_height / 2], rgba=[0.25, 0.25, 0.28, 1])
        cap = base.add_body(name=f"{self.name}/cap", pos=[0, 0, self.base_height])
        # 1 cm travel, 300 N/m spring preloaded to 1.2 N, damped, stiff end stops.
        cap.add_joint(name=f"{self.name}/slide", type=mujoco.mjtJoint.mjJNT_SLIDE,
                      axis=[0, 0, 1], range=[-self.travel, 0.0], stiffness=300.0,
                      springref=0.004, damping=3.0, solref_limit=[0.004, 1.0])
        cap.add_geom(name=f"{self.name}/cap", type=CYLINDER,
                     size=[self.radius, self.cap_height / 2], pos=[0, 0, self.cap_height / 2],
                     rgba=list(self.cap_rgba), friction=[1.0, 0.005, 0.0001])
        explicit_inertia(cap, 0.02, [self.radius, self.radius, self.cap_height / 2])
        # The base is static, so MuJoCo treats it as part of the world and would let the sinking
        # cap collide with it; the pair is excluded explicitly.
        spec.add_exclude(bodyname1=self.name, bodyname2=f"{self.name}/cap")

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self.qpos_adr = int(model.joint(f"{self.name}/slide").qposadr[0])

    def reset(self) -> None:
        self.count = 0
        self.armed = True
        self.released_at = None

    def depth(self, data: mujoco.MjData) -> float:
        return float(-data.qpos[self.qpos_adr])

    def top(self, model: mujoco.MjModel) -> np.ndarray:
        """World position of the centre of the cap's top face at rest."""
        x, y, z = model.body_pos[self.body_id]
        return np.array([x, y, z + self.base_height + self.cap_height])

    def update(self, data: mujoco.MjData) -> bool:
        """Call after every physics step: counts a press on the way down, and says whether
        this step counted one (a task judges a press by the scene at that moment)."""
        d = self.depth(data)
        if self.armed and d >= self.press_depth:
            self.count += 1
            self.armed = False
            return True
        if not self.armed:
            if d > self.release_depth:
                self.released_at = None
            elif self.released_at is None:
                self.released_at = data.time
            elif data.time - self.released_at >= self.rearm_time:
                self.armed = True
                self.released_at = None
        return False


# Seven-segment layout: segment -> (centre x, centre y, horizontal?) in units of the digit
# height, and which segments each digit lights.
_SEGMENTS = {"a": (0.0, 0.5, True), "b": (0.25, 0.25, False), "c": (0.25, -0.25, False),
             "d": (0.0, -0.5, True), "e": (-0.25, -0.25, False), "f": (-0.25, 0.25, False),
             "g": (0.0, 0.0, True)}
DIGIT_SEGMENTS = {0: "abcdef", 1: "bc", 2: "abdeg", 3: "abcdg", 4: "bcfg", 5: "acdfg",
                  6: "acdefg", 7: "abc", 8: "abcdefg", 9: "abcdfg"}


@dataclass
class NumberTile(StaticPiece):
    """A flat 6 x 9 cm tile showing one digit as seven 1 cm-wide segments.

    All seven segments exist in the model; a digit is shown by colouring the lit ones dark
    and the others like the tile, so one compiled model shows any digit.
    """

    width: float = 0.06
    height: float = 0.09
    seg_width: float = 0.01
    tile_rgba: tuple = (0.95, 0.95, 0.9, 1.0)
    ink_rgba: tuple = (0.05, 0.05, 0.05, 1.0)
    seg_ids: dict = field(default_factory=dict)
    digit: int = 0

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP])
        body.add_geom(name=f"{self.name}/tile", type=BOX,
                      size=[self.width / 2, self.height / 2, 0.002], pos=[0, 0, 0.002],
                      rgba=list(self.tile_rgba), contype=0, conaffinity=0)
        span = self.height - 2 * self.seg_width  # distance between the outer horizontal bars
        for seg, (cx, cy, horizontal) in _SEGMENTS.items():
            length = span / 2 + self.seg_width
            size = ([length / 2, self.seg_width / 2, 0.0005] if horizontal
                    else [self.seg_width / 2, length / 2, 0.0005])
            body.add_geom(name=f"{self.name}/seg_{seg}", type=BOX, size=size,
                          pos=[cx * span, cy * span, 0.0045], rgba=list(self.tile_rgba),
                          contype=0, conaffinity=0)

    def bind(self, model: mujoco.MjModel) -> None:
        super().bind(model)
        self.seg_ids = {s: model.geom(f"{self.name}/seg_{s}").id for s in _SEGMENTS}

    def show(self, model: mujoco.MjModel, digit: int) -> None:
        if digit not in DIGIT_SEGMENTS:
            raise ValueError(f"a tile shows one digit 0-9, got {digit}")
        self.digit = digit
        for seg, gid in self.seg_ids.items():
            lit = seg in DIGIT_SEGMENTS[digit]
            model.geom_rgba[gid] = self.ink_rgba if lit else self.tile_rgba


@dataclass
class Wall(StaticPiece):
    """A box that can appear and disappear between steps: shelves, the screen. Hidden, it
    waits under the floor."""

    size: tuple = (0.3, 0.01, 0.2)  # half extents
    rgba: tuple = (0.35, 0.38, 0.42, 1.0)
    solid: bool = True

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, -1.0])
        collide = {} if self.solid else {"contype": 0, "conaffinity": 0}
        body.add_geom(name=f"{self.name}/geom", type=BOX, size=list(self.size),
                      rgba=list(self.rgba), **collide)

    def show(self, model: mujoco.MjModel, xy, bottom: float = TABLE_TOP) -> None:
        model.body_pos[self.body_id] = (xy[0], xy[1], bottom + self.size[2])

    def hide(self, model: mujoco.MjModel) -> None:
        model.body_pos[self.body_id] = (0.0, 0.0, -1.0)
