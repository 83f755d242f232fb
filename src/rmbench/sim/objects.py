"""Movable scene pieces shared by the tasks: cubes, covers, T blocks, batteries and
procedural shapes (fixed pieces are in :mod:`rmbench.sim.fixtures`).

Each piece adds itself to an MjSpec at build time (``build``), looks its ids up once after
compilation (``bind``), and is then placed per episode through its free joint. Per-episode
looks (colours, shapes) are edits of the compiled model, so one model serves every seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from rmbench.sim.geometry import quat_z
from rmbench.sim.station import TABLE_TOP

BOX = mujoco.mjtGeom.mjGEOM_BOX
CYLINDER = mujoco.mjtGeom.mjGEOM_CYLINDER
RED = (0.85, 0.1, 0.1, 1.0)


def explicit_inertia(body, mass: float, half_sizes) -> None:
    """Solid-box inertia set explicitly (the arm assets restrict inertia-from-geom groups);
    ipos/iquat must be set too, or MuJoCo keeps a stale centre of mass."""
    x, y, z = (2 * np.asarray(half_sizes, float)) ** 2
    body.explicitinertial = True
    body.mass = mass
    body.inertia = [mass * (y + z) / 12, mass * (x + z) / 12, mass * (x + y) / 12]
    body.ipos = [0, 0, 0]
    body.iquat = [1, 0, 0, 0]


@dataclass
class FreePiece:
    """A free-floating object. Subclasses add geoms in ``_geoms`` and say how high the body
    origin sits above the table when the object rests (``rest_height``)."""

    name: str
    rgba: tuple = RED
    mass: float = 0.05
    body_id: int = -1
    geom_id: int = -1  # the main (painted) geom
    qpos_adr: int = -1
    qvel_adr: int = -1

    @property
    def rest_height(self) -> float:
        raise NotImplementedError

    def _geoms(self, body) -> None:
        raise NotImplementedError

    def build(self, spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP + self.rest_height])
        body.add_freejoint(name=f"{self.name}/free")
        self._geoms(body)

    def bind(self, model: mujoco.MjModel) -> None:
        joint = model.joint(f"{self.name}/free")
        self.body_id = model.body(self.name).id
        self.geom_id = model.geom(f"{self.name}/geom").id
        self.qpos_adr = int(joint.qposadr[0])
        self.qvel_adr = int(joint.dofadr[0])

    def place(self, data: mujoco.MjData, xy, yaw: float = 0.0, z: float | None = None) -> None:
        z = TABLE_TOP + self.rest_height if z is None else z
        data.qpos[self.qpos_adr: self.qpos_adr + 3] = (xy[0], xy[1], z)
        data.qpos[self.qpos_adr + 3: self.qpos_adr + 7] = quat_z(yaw)
        data.qvel[self.qvel_adr: self.qvel_adr + 6] = 0.0

    def pos(self, data: mujoco.MjData) -> np.ndarray:
        return data.xpos[self.body_id].copy()

    def paint(self, model: mujoco.MjModel, rgba) -> None:
        """Recolour per episode (one compiled model serves every colour draw)."""
        model.geom_rgba[self.geom_id] = rgba

    def yaw(self, data: mujoco.MjData) -> float:
        mat = data.xmat[self.body_id].reshape(3, 3)
        return float(np.arctan2(mat[1, 0], mat[0, 0]))

    def upright(self, data: mujoco.MjData, tol: float = 0.1) -> bool:
        return bool(data.xmat[self.body_id][8] > np.cos(tol))

    def speed(self, data: mujoco.MjData) -> float:
        return float(np.linalg.norm(data.qvel[self.qvel_adr: self.qvel_adr + 3]))

    def resting(self, data: mujoco.MjData, tol: float = 0.005) -> bool:
        """On the table (or a mat), not moving."""
        return (abs(self.pos(data)[2] - (TABLE_TOP + self.rest_height)) < tol
                and self.speed(data) < 0.02)


@dataclass
class Cube(FreePiece):
    """A free cube of edge ``size`` (metres)."""

    size: float = 0.04

    @property
    def rest_height(self) -> float:
        return self.size / 2

    def on_a_face(self, data: mujoco.MjData, tol: float = 0.1) -> bool:
        """Resting square on one of its six faces, within ``tol`` rad: for a cube of one colour
        what ``upright`` is for other pieces (a cube turned onto another face looks the same)."""
        return bool(np.abs(data.xmat[self.body_id][6:9]).max() > np.cos(tol))

    def _geoms(self, body) -> None:
        h = self.size / 2
        body.add_geom(name=f"{self.name}/geom", type=BOX, size=[h, h, h], rgba=list(self.rgba),
                      friction=[1.0, 0.005, 0.0001], condim=4)
        explicit_inertia(body, self.mass, [h, h, h])


@dataclass
class Cover(FreePiece):
    """An upside-down square cup with a knob on top, to hide a cube from the cameras.

    The body origin is the centre of the open bottom; the gripper takes the knob.
    """

    inner: float = 0.076  # 18 mm each side of a 40 mm cube: room for a hand a little off
    wall: float = 0.004
    height: float = 0.062
    knob: float = 0.022  # knob edge (square) and height
    rgba: tuple = (0.8, 0.8, 0.78, 1.0)
    mass: float = 0.06

    @property
    def rest_height(self) -> float:
        return 0.0

    def around(self, data: mujoco.MjData, point: np.ndarray, margin: float = 0.0) -> bool:
        """Whether ``point`` (xy) lies within the cup's inner square less ``margin`` a side,
        in the cup's own frame (1 mm of play): with a cube's half edge as the margin, whether
        the cube fits inside, which it always does under a cover that stands down on the
        table (the walls could not stand across it)."""
        rot = data.xmat[self.body_id].reshape(3, 3)
        local = rot[:2, :2].T @ (np.asarray(point[:2]) - self.pos(data)[:2])
        return bool(np.all(np.abs(local) <= self.inner / 2 - margin + 1e-3))

    def knob_centre(self, data: mujoco.MjData) -> np.ndarray:
        return self.pos(data) + (0, 0, self.height + self.knob / 2)

    @property
    def knob_base(self) -> float:
        """Height of the knob's bottom above the cover's bottom (for placing by the knob)."""
        return self.height

    def _geoms(self, body) -> None:
        half, t, h = self.inner / 2, self.wall / 2, self.height / 2
        rgba = list(self.rgba)
        body.add_geom(name=f"{self.name}/geom", type=BOX, size=[half + self.wall, half + self.wall, t],
                      pos=[0, 0, self.height - t], rgba=rgba)
        for k, (x, y, sx, sy) in enumerate(((half + t, 0, t, half), (-half - t, 0, t, half),
                                            (0, half + t, half + self.wall, t),
                                            (0, -half - t, half + self.wall, t))):
            body.add_geom(name=f"{self.name}/wall{k}", type=BOX, size=[sx, sy, h - t],
                          pos=[x, y, h - t], rgba=rgba)
        body.add_geom(name=f"{self.name}/knob", type=BOX, size=[self.knob / 2] * 3,
                      pos=[0, 0, self.height + self.knob / 2], rgba=[0.35, 0.35, 0.38, 1],
                      friction=[1.0, 0.005, 0.0001], condim=4)
        # Mass spread like a shell: centre of mass at mid-height.
        body.explicitinertial = True
        body.mass = self.mass
        r = half + self.wall
        body.inertia = [self.mass * (r**2 + h**2) / 3, self.mass * (r**2 + h**2) / 3,
                        self.mass * 2 * r**2 / 3]
        body.ipos = [0, 0, h]
        body.iquat = [1, 0, 0, 0]


@dataclass
class TBlock(FreePiece):
    """A flat T: a stem along body y with a crossbar across its +y end. The body origin is the
    middle of the stem, where the gripper takes it (fingers closing along body x)."""

    width: float = 0.03  # of both bars
    stem: float = 0.07
    bar: float = 0.10
    thickness: float = 0.03
    mass: float = 0.06

    @property
    def rest_height(self) -> float:
        return self.thickness / 2

    def _geoms(self, body) -> None:
        w, t = self.width / 2, self.thickness / 2
        kw = {"rgba": list(self.rgba), "friction": [1.0, 0.005, 0.0001], "condim": 4}
        body.add_geom(name=f"{self.name}/geom", type=BOX, size=[w, self.stem / 2, t], **kw)
        body.add_geom(name=f"{self.name}/bar", type=BOX, size=[self.bar / 2, w, t],
                      pos=[0, self.stem / 2 + w, 0], **kw)
        explicit_inertia(body, self.mass, [self.bar / 2, (self.stem + self.width) / 2, t])

    def paint(self, model: mujoco.MjModel, rgba) -> None:
        model.geom_rgba[self.geom_id] = rgba
        model.geom_rgba[model.geom(f"{self.name}/bar").id] = rgba


@dataclass
class Battery(FreePiece):
    """A cylinder cell lying on its side along body x, with its positive terminal (a bright
    nub and end face) at +x. ``yaw`` is the direction the positive end points."""

    radius: float = 0.012
    length: float = 0.058
    rgba: tuple = (0.12, 0.12, 0.14, 1.0)
    terminal_rgba: tuple = (0.95, 0.75, 0.1, 1.0)
    mass: float = 0.04

    @property
    def rest_height(self) -> float:
        return self.radius

    def _geoms(self, body) -> None:
        along_x = [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0]  # cylinder axis z -> x
        half = self.length / 2
        # A lying cylinder rolls away from the fingers and squeezes out of a top-down grip;
        # the cell collides as a square prism (hidden, group 3) and shows as a cylinder.
        body.add_geom(name=f"{self.name}/geom", type=CYLINDER, size=[self.radius, half],
                      quat=along_x, rgba=list(self.rgba), contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/collision", type=BOX,
                      size=[half, self.radius * 0.92, self.radius], group=3,
                      rgba=[0, 0, 0, 0], friction=[1.0, 0.005, 0.0001], condim=4)
        # The gold face sits flush with the end (0.1 mm proud): a disc standing out further
        # showed its rim from above, in the gap beyond a slotted cell's end, and told the
        # head camera which way an inserted cell points.
        body.add_geom(name=f"{self.name}/plus_face", type=CYLINDER,
                      size=[self.radius * 0.95, 0.001], pos=[half - 0.0009, 0, 0], quat=along_x,
                      rgba=list(self.terminal_rgba), contype=0, conaffinity=0)
        body.add_geom(name=f"{self.name}/nub", type=CYLINDER, size=[0.004, 0.0015],
                      pos=[half + 0.0015, 0, 0], quat=along_x, rgba=list(self.terminal_rgba),
                      contype=0, conaffinity=0)
        explicit_inertia(body, self.mass, [half, self.radius, self.radius])

    def axis(self, data: mujoco.MjData) -> np.ndarray:
        """World direction of the positive end."""
        return data.xmat[self.body_id].reshape(3, 3)[:, 0].copy()


# Procedural shapes: geom -> (half sizes, local position) for up to two boxes "a", "b" and a
# cylinder "c" (radius, half height). Every shape is gripped at the body origin with the
# fingers closing along body x. The fingers are 7 cm wide and lean a little, so compound
# shapes keep everything within the grip's footprint (a T or L made of bars would put its
# crossbar under a finger); "slab" carries a handle block on top.
SHAPES = {
    "cube": {"a": ((0.02, 0.02, 0.02), (0, 0, 0))},
    "bar": {"a": ((0.014, 0.04, 0.018), (0, 0, 0))},
    "tall": {"a": ((0.014, 0.014, 0.032), (0, 0, 0))},
    "cylinder": {"c": ((0.018, 0.024), (0, 0, 0))},
    "disc": {"c": ((0.026, 0.012), (0, 0, 0))},
    "slab": {"a": ((0.015, 0.035, 0.012), (0, 0, 0)), "b": ((0.015, 0.012, 0.01), (0, 0, 0.022))},
}


def footprint(shape: str) -> float:
    """Radius of the circle around the grip point that holds the shape in the table plane."""
    return max(np.hypot(abs(p[0]) + (s[0]), abs(p[1]) + (s[1] if k != "c" else s[0]))
               for k, (s, p) in SHAPES[shape].items())

SHAPE_COLOURS = {"red": (0.85, 0.1, 0.1, 1.0), "green": (0.1, 0.65, 0.2, 1.0),
                 "blue": (0.1, 0.25, 0.85, 1.0), "yellow": (0.95, 0.8, 0.1, 1.0)}
_MAX_SIZE = {"a": (0.02, 0.04, 0.032), "b": (0.015, 0.012, 0.01), "c": (0.026, 0.024, 0)}
HIDDEN_GROUP = 3  # not drawn by the default renderer options


@dataclass
class Shape(FreePiece):
    """An object whose shape and colour are set per episode from ``SHAPES`` and
    ``SHAPE_COLOURS``: one compiled model serves every draw. Unused geoms stop colliding and
    move to a group the renderer does not draw. With ``free=False`` it is a fixed display copy
    (the reference on the shelf) that never collides."""

    free: bool = True
    shape: str = "cube"
    colour: str = "red"
    geom_ids: dict = field(default_factory=dict)
    _rest: float = 0.02

    @property
    def rest_height(self) -> float:
        return self._rest

    @property
    def height(self) -> float:
        return 2 * self._rest

    def build(self, spec: mujoco.MjSpec) -> None:
        if self.free:
            super().build(spec)
            return
        self._geoms(spec.worldbody.add_body(name=self.name, pos=[0, 0, TABLE_TOP]))

    def _geoms(self, body) -> None:
        collide = {} if self.free else {"contype": 0, "conaffinity": 0}
        for key, size in _MAX_SIZE.items():
            body.add_geom(name=f"{self.name}/geom" if key == "a" else f"{self.name}/{key}",
                          type=CYLINDER if key == "c" else BOX, size=list(size),
                          rgba=list(self.rgba), friction=[1.0, 0.005, 0.0001], condim=4,
                          **collide)
        if self.free:
            explicit_inertia(body, self.mass, [0.02, 0.02, 0.02])

    def bind(self, model: mujoco.MjModel) -> None:
        if self.free:
            super().bind(model)
        else:
            self.body_id = model.body(self.name).id
        self.geom_ids = {k: model.geom(f"{self.name}/geom" if k == "a" else f"{self.name}/{k}").id
                         for k in _MAX_SIZE}

    def configure(self, model: mujoco.MjModel, shape: str, colour: str) -> None:
        """Become ``shape`` in ``colour`` (call before placing)."""
        self.shape, self.colour = shape, colour
        parts = SHAPES[shape]
        self._rest = max(size[-1] if k != "c" else size[1] for k, (size, _) in parts.items())
        for key, gid in self.geom_ids.items():
            used = key in parts
            model.geom_group[gid] = 0 if used else HIDDEN_GROUP
            model.geom_contype[gid] = model.geom_conaffinity[gid] = int(used and self.free)
            model.geom_rgba[gid] = SHAPE_COLOURS[colour]
            if used:
                size, pos = parts[key]
                model.geom_size[gid][: len(size)] = size
                model.geom_pos[gid] = pos
        if not self.free:
            model.body_pos[self.body_id][2] = TABLE_TOP + self._rest

    def show_at(self, model: mujoco.MjModel, xyz, yaw: float) -> None:
        """Place the fixed display copy with its bottom at height ``xyz[2]``."""
        model.body_pos[self.body_id] = (xyz[0], xyz[1], xyz[2] + self._rest)
        model.body_quat[self.body_id] = quat_z(yaw)
