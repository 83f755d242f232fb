"""observe_and_pickup — M(1).

Task: a shelf at the back shows a reference object; five objects lie on the table, one of
them a copy of the reference. Keep still while the reference is shown; a screen then rises in
front of the shelf. Pick up the object that matches the reference with the arm on its side.

Randomization: the reference's shape (cube, bar, tall, cylinder, disc, slab) and colour (red,
green, blue, yellow) uniformly; each of the four distractors is another shape with
probability 0.8 (any colour) and else the same shape in another colour, all five distinct;
positions x ~ U[-0.35, 0.35], y ~ U[-0.20, -0.05] (the benchmark's y in [-0.25, -0.10], 5 cm
further from the arm bases so every object is reachable from above), drawn again while
|x| < 0.07, two footprints are less than 1 cm apart or two grip points less than 8 cm apart;
yaws ~ U[-0.6, 0.6]. Which of the five is the copy is uniform.

Observation phase: the first second (20 policy steps at 20 Hz); moving a gripper more than
3 cm in it fails the episode. Then the screen (0.6 x 0.4 m) stands in front of the shelf for
the rest of the episode.

Success: the matching object's bottom is 6 cm or more above the table, held, and no other
object is lifted. Failure: moving in the observation phase; lifting another object (3 cm);
an object off the table.

Memory: TMC M(1). Aliasing point: after the screen rises, every episode with the same table
looks the same whatever the reference was.
"""

from __future__ import annotations

import mujoco
import numpy as np

from rmbench.sim.fixtures import Wall
from rmbench.sim.objects import SHAPE_COLOURS, SHAPES, Shape, footprint
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks import state as S
from rmbench.tasks.base import Evaluation, Task
from rmbench.tasks.randomization import Uniform
from rmbench.tasks.registry import register

# Randomization (m, rad), in the order drawn
OBJECT_X = Uniform(-0.35, 0.35)
OBJECT_Y = Uniform(-0.20, -0.05)
OBJECT_YAW = Uniform(-0.6, 0.6)
MIN_ABS_X = 0.07  # a position nearer x = 0 is drawn again
FOOTPRINT_GAP = 0.01  # ... as is one whose footprint comes this close to another's
GRIP_GAP = 0.08  # ... or whose grip point (the centre) this close to another's

N_OBJECTS = 5
OBSERVE_SECONDS = 1.0
STILL_TOL = 0.03
LIFT_SUCCESS = 0.06
LIFT_WRONG = 0.03
SHELF_XY = (0.0, 0.17)
SHELF_TOP = 0.14  # above the table
SCREEN_XY = (0.0, 0.09)
OTHER_SHAPE_P = 0.8


@register
class ObserveAndPickup(Task):
    name = "observe_and_pickup"
    gym_id = "rmbench/ObserveAndPickup-v1"
    tmc = "M(1)"
    step_limit = 250
    subtasks = ("watch the reference object", "pick up the matching object")
    instructions_seen = (
        "Look at the object on the shelf, then pick up the same object from the table.",
        "Remember the object shown on the shelf and lift its twin from the table.",
        "Observe the reference object; once it is hidden, pick up the matching one.",
        "Watch the shelf without moving, then pick up the object identical to the one shown.",
    )
    instructions_unseen = (
        "Memorize the displayed item and grab its copy from the table.",
        "Stay still while the shelf object is shown, then lift the matching item.",
    )
    aliasing_point = "after the screen rises: the same table whatever the reference was"
    aliasing_stage = 1
    hidden_keys = ("target",)
    aliasing_pairs = ((({"target": 0}, 1, 1), ({"target": 3}, 1, 1)),)

    # The state observation: each table object's pose and look (shape, colour), and the
    # reference's look while it can be seen (zero once the screen stands in front of it).
    state_names = (
        *(n for k in range(N_OBJECTS) for n in (
            *S.pose_names(f"object{k}", "k"), *S.one_hot_names(f"object{k}_shape", SHAPES),
            *S.one_hot_names(f"object{k}_colour", SHAPE_COLOURS))),
        "reference_visible", *S.one_hot_names("reference_shape", SHAPES),
        *S.one_hot_names("reference_colour", SHAPE_COLOURS))

    def __init__(self):
        super().__init__()
        self.objects = tuple(Shape(f"object{k}") for k in range(N_OBJECTS))
        self.reference = Shape("reference", free=False)
        self.shelf = Wall("shelf", size=(0.1, 0.06, SHELF_TOP / 2), rgba=(0.5, 0.4, 0.3, 1.0))
        self.screen = Wall("screen", size=(0.3, 0.01, 0.2))
        self.target = 0
        self.t0: float | None = None
        self.start_sites = np.zeros((2, 3))
        self.moved_early = False
        self.screen_up = False

    @property
    def pieces(self):
        return (*self.objects, self.reference, self.shelf, self.screen)

    def bind(self, model, data) -> None:
        super().bind(model, data)
        self._sites = [model.site(f"{s}/grasp").id for s in ("left", "right")]

    def initialize(self, rng: np.random.Generator) -> None:
        shapes, colours = list(SHAPES), list(SHAPE_COLOURS)
        ref = (shapes[int(rng.integers(len(shapes)))], colours[int(rng.integers(len(colours)))])
        looks = [ref]
        while len(looks) < N_OBJECTS:
            if rng.uniform() < OTHER_SHAPE_P:
                look = (shapes[int(rng.integers(len(shapes)))],
                        colours[int(rng.integers(len(colours)))])
                if look[0] == ref[0]:
                    continue
            else:
                look = (ref[0], colours[int(rng.integers(len(colours)))])
            if look not in looks:
                looks.append(look)
        order = rng.permutation(N_OBJECTS)  # object k gets look order[k]; look 0 is the copy
        positions = self._positions(rng, [footprint(looks[i][0]) for i in order])
        yaws = OBJECT_YAW.draw(rng, N_OBJECTS)
        drawn_target = int(np.flatnonzero(order == 0)[0])
        self.target = self.choose("target", drawn_target, range(N_OBJECTS))
        for k, obj in enumerate(self.objects):
            obj.configure(self.model, *looks[order[k]])
            obj.place(self.data, positions[k], yaw=yaws[k])
        target = self.objects[self.target]
        self.reference.configure(self.model, target.shape, target.colour)
        self.reference.show_at(self.model, (*SHELF_XY, TABLE_TOP + SHELF_TOP), yaw=0.0)
        self.shelf.show(self.model, SHELF_XY)
        self.screen.hide(self.model)
        self.t0 = None
        self.moved_early = False
        self.screen_up = False

    def _positions(self, rng, radii) -> np.ndarray:
        """Rejection sampling; objects keep 1 cm between their footprints (and 8 cm between
        grip points), starting over if the table fills up badly."""
        while True:
            out: list[np.ndarray] = []
            for _ in range(200):
                p = np.array([OBJECT_X.draw(rng), OBJECT_Y.draw(rng)])
                k = len(out)
                if abs(p[0]) >= MIN_ABS_X and all(
                        np.linalg.norm(p - q) >= max(GRIP_GAP, radii[k] + radii[j] + FOOTPRINT_GAP)
                        for j, q in enumerate(out)):
                    out.append(p)
                    if len(out) == N_OBJECTS:
                        return np.array(out)

    def plan(self) -> list[int]:
        return [0, 1]

    def environment_state(self) -> np.ndarray:
        d, shapes, colours = self.data, list(SHAPES), list(SHAPE_COLOURS)
        # The screen as the cameras draw it: it stands once its body has come up from under
        # the floor (on_substep updates the drawn pose at once).
        visible = 0.0 if d.xpos[self.screen.body_id][2] > 0 else 1.0
        return S.assemble(self.state_names, [
            *((S.pose(o, d, S.SHAPE_SYMMETRY[o.shape]), S.one_hot(o.shape, shapes),
               S.one_hot(o.colour, colours)) for o in self.objects),
            [visible], visible * S.one_hot(self.reference.shape, shapes),
            visible * S.one_hot(self.reference.colour, colours)])

    def hidden_state(self) -> dict:
        t = self.objects[self.target]
        return {"target": self.target, "shape": t.shape, "colour": t.colour}

    def on_substep(self) -> None:
        if self.t0 is not None and not self.screen_up and \
                self.data.time - self.t0 >= OBSERVE_SECONDS:
            self.screen.show(self.model, SCREEN_XY)
            self.screen_up = True
            # Moving a body changes where it is drawn only at the next mj_step's kinematics: a
            # screen raised on a period's last substep would appear a frame after screen_up.
            # Kinematics alone leaves the dynamics as they were (the next step recomputes it).
            mujoco.mj_kinematics(self.model, self.data)

    def lift(self, obj: Shape) -> float:
        return float(obj.pos(self.data)[2] - obj.rest_height - TABLE_TOP)

    def evaluate(self) -> Evaluation:
        d = self.data
        sites = d.site_xpos[self._sites]
        if self.t0 is None:  # the first evaluation, right after the env settled the scene
            self.t0 = d.time
            self.start_sites = sites.copy()
        if not self.screen_up and np.linalg.norm(sites - self.start_sites, axis=1).max() > STILL_TOL:
            self.moved_early = True
        target = self.objects[self.target]
        wrong = [k for k, o in enumerate(self.objects) if k != self.target
                 and self.lift(o) > LIFT_WRONG]
        lifted = self.lift(target) >= LIFT_SUCCESS and self.touched_by_fingers(target.body_id)
        reason = ""
        if self.moved_early:
            reason = "the robot moved while the reference was shown"
        elif wrong:
            other = self.objects[wrong[0]]
            reason = f"picked up a wrong object ({other.colour} {other.shape})"
        elif self.fell_off(self.objects):
            reason = "an object fell off the table"
        stage = 2 if lifted else 1 if self.screen_up else 0
        stage, progress = self.advance(stage, 1.0 if stage == 2 else 0.0)
        preds = {"screen_up": self.screen_up, "moved_early": self.moved_early,
                 "target_lift": round(self.lift(target), 4), "wrong_lifted": len(wrong)}
        return Evaluation(success=stage == 2 and not reason, failure=bool(reason),
                          progress=progress, stage=stage, failure_reason=reason,
                          predicates=preds)
