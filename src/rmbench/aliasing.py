"""Aliasing points, measured: why each task needs memory.

Every task names the pairs of moments its expert's plan revisits (``Task.aliasing_pairs``,
the first its headline): each moment is a set of fixed hidden variables, a stage of the plan,
and which expert segment start after reaching that stage.
Run from the same seed, the two moments should look alike to the head camera while the
expert's next subtask (or, where the text is the same, its actions from there on) differ. The pixel
distance is compared with the same moment in an unrelated seed. The distance between the two
moments' state observations (``Task.environment_state``) is compared with the distance between
the first frames of the two seeds: a state policy meets the same aliasing as a pixel policy,
or the state vector leaks what memory should carry. Every policy also reads the arms' joints,
so the two moments' joints are compared too: an arm left where the last step put it tells the
steps apart as surely as the table would.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import mujoco
import numpy as np

from rmbench.envs.registration import make
from rmbench.experts import make_expert
from rmbench.sim.robot import JOINT_NAMES, SIDES
from rmbench.tasks import get_task
from rmbench.tasks.state import is_continuous, symmetric_heading

_GRIPPER = np.array([n.endswith("gripper") for n in JOINT_NAMES])  # in the arms' joint vector
_ARM_JOINTS = [n for n, g in zip(JOINT_NAMES, _GRIPPER, strict=True) if not g]


@dataclass
class Moment:
    frame: np.ndarray | None  # head camera, HxWx3 uint8 (None when not rendered)
    step: int
    next_subtask: str
    actions: np.ndarray  # the expert's actions from the moment to the end of the episode
    state: np.ndarray | None = None  # the task's environment_state() at the moment
    first_state: np.ndarray | None = None  # ... and at the episode's first frame
    joints: np.ndarray | None = None  # the arms' joint positions at the moment (agent_pos)
    robot: np.ndarray | None = None  # HxW bool: the frame's pixels that show the robot
    first_frame: np.ndarray | None = None  # the episode's first frame and its robot pixels
    # (with ``first``: what the scene's distance between layouts is taken on)
    first_robot: np.ndarray | None = None


@dataclass
class AliasingResult:
    task: str
    seed: int
    unrelated_seed: int
    pixel_distance: float  # mean |difference| (0-255) between the two moments
    unrelated_distance: float  # the first moment vs the same moment in the unrelated seed
    ratio: float
    # The scene alone (the robot's pixels in either frame left out): the pair's distance
    # against that between the first frames of ``seed`` and ``unrelated_seed`` (how far two
    # layouts look apart, as for the state below; at some moments the same moment of another
    # layout shows next to nothing of it, e.g. swap_T's Ts held up). The arms are compared by
    # their joints below: at a fraction of a degree apart their edges still move by a pixel,
    # which the whole frame counts on tables that differ little between layouts (battery_try).
    scene_distance: float
    unrelated_scene_distance: float
    scene_ratio: float
    next_subtasks: tuple[str, str]
    action_divergence: float  # max |difference| of the expert's actions from there on (rad)
    steps: tuple[int, int]
    # The state observation (Euclidean distances between environment_state vectors): the
    # pair's, and the mean between the first frames of ``seed`` and of UNRELATED_FIRST_FRAMES
    # seeds after ``unrelated_seed`` (how far apart two layouts are; the same moment in
    # another layout of an M(n) task can look as alike as the pair does).
    state_distance: float = float("nan")
    unrelated_state_distance: float = float("nan")
    state_ratio: float = float("nan")
    # The same ratio without the headings of symmetric pieces (cubes, covers, cells' axes): a
    # carried cube keeps its yaw from reset, so where the pair's moments have cubes in each
    # other's places (swap_blocks, blocks_ranking_try) their headings are traded too, in the
    # frames as in the vectors, and no frame tells a traded yaw from a drawn one.
    state_ratio_core: float = float("nan")
    state_entry: str = ""  # the entry that differs most between the two moments
    state_discrete_differ: tuple[str, ...] = ()  # flags, one-hots, colours, digits that differ
    state_position_jitter: float = float("nan")  # max |difference| of x, y, z entries (m)
    # The arms' joints (what every policy reads beside the scene): the largest difference
    # between the two moments, over the twelve arm joints and over the two grippers (rad).
    arm_gap: float = float("nan")
    arm_entry: str = ""  # the arm joint that differs most
    gripper_gap: float = float("nan")
    pair: int = 0  # which of ``Task.aliasing_pairs``

    def to_dict(self) -> dict:
        return asdict(self)


def capture(task: str, seed: int, hidden: dict, stage: int, segment: int,
            width: int = 320, height: int = 240, render: bool = True,
            first: bool = False) -> Moment:
    """Roll the expert from ``seed`` with ``hidden`` fixed until its ``segment``-th segment
    start after the env reached ``stage`` (``segment`` 0: the first frame at that stage, the
    one a planner chooses the next step at); return the head frame and its robot pixels
    (``render``; ``first``: the episode's first frame too) and the state observation there,
    and what follows."""
    env = make(task, render=False)
    try:
        expert = make_expert(env)
        obs, info = env.reset(seed=seed, options={"hidden": hidden})
        expert.reset(info["instruction"], info)
        first_state = env.unwrapped.task.environment_state()
        plan = info["plan"]
        reached, seen, frame, step = info["subtask_step"] >= stage, 0, None, 0
        state, joints, found, robot = None, None, False, None
        first_frame = first_robot = None
        if render and first:
            first_frame = env.unwrapped.sim.render(["head"], width, height)["head"]
            first_robot = robot_pixels(env.unwrapped.sim, "head", width, height)
        actions: list[np.ndarray] = []
        for t in range(env.unwrapped.step_limit):
            action = expert.act(obs)
            if not found and reached and (segment == 0 or expert.segment_start):
                seen += 1
                if seen == max(segment, 1):
                    found, step = True, t
                    state = env.unwrapped.task.environment_state()
                    joints = np.asarray(obs["agent_pos"], dtype=float)
                    if render:
                        frame = env.unwrapped.sim.render(["head"], width, height)["head"]
                        robot = robot_pixels(env.unwrapped.sim, "head", width, height)
            if found:
                actions.append(action)
            obs, _, terminated, truncated, info = env.step(action)
            reached = reached or info["subtask_step"] >= stage
            if terminated or truncated:
                break
        if not found:
            raise RuntimeError(f"{task} seed {seed}: the expert never reached stage {stage} "
                               f"segment {segment} with {hidden}")
        subtasks = get_task(task).subtasks
        return Moment(frame, step, subtasks[plan[stage]] if stage < len(plan) else "done",
                      np.array(actions), state, first_state, joints, robot, first_frame,
                      first_robot)
    finally:
        env.close()


def robot_pixels(sim, camera: str, width: int, height: int) -> np.ndarray:
    """(H, W) bool: the pixels of ``camera`` that show a geom of either arm (segmentation
    rendering; the colour renderer is left as it was)."""
    r = sim.renderer(width, height)
    r.enable_segmentation_rendering()
    try:
        r.update_scene(sim.data, camera=camera)
        seg = r.render()
    finally:
        r.disable_segmentation_rendering()
    m = sim.model
    arm = np.array([m.body(int(b)).name.startswith(tuple(f"{s}/" for s in SIDES))
                    for b in m.geom_bodyid])
    is_geom = seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM)
    return is_geom & arm[np.clip(seg[..., 0], 0, len(arm) - 1)]


def pixel_distance(a: np.ndarray, b: np.ndarray, keep: np.ndarray | None = None) -> float:
    """Mean |difference| (0-255) over all pixels, or over those ``keep`` marks."""
    d = np.abs(a.astype(np.int16) - b.astype(np.int16))
    return float(d.mean() if keep is None else d[keep].mean())


def state_distance(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b))


UNRELATED_FIRST_FRAMES = 8


def first_states(task: str, seeds) -> np.ndarray:
    """The state observation at reset for each seed (physics only; hidden variables drawn)."""
    env = make(task, obs_type="environment_state_agent_pos")
    try:
        return np.stack([env.reset(seed=int(s))[0]["environment_state"] for s in seeds])
    finally:
        env.close()


def measure(task: str, seed: int = 100000, unrelated_seed: int | None = None,
            pixels: bool = True, pair: int = 0) -> AliasingResult:
    """The ``pair``-th aliasing pair of ``task`` (``Task.aliasing_pairs``; 0, the headline)
    from ``seed`` against its first moment in ``unrelated_seed``; ``pixels=False`` skips
    rendering (the pixel fields are then NaN)."""
    cls = get_task(task)
    if not 0 <= pair < len(cls.aliasing_pairs):
        raise ValueError(f"{cls.name} has aliasing pairs 0-{len(cls.aliasing_pairs) - 1}, "
                         f"not {pair}")
    moments = cls.aliasing_pairs[pair]
    unrelated_seed = seed + 1 if unrelated_seed is None else unrelated_seed
    a = capture(cls.name, seed, *moments[0], render=pixels, first=True)
    b = capture(cls.name, seed, *moments[1], render=pixels)
    other = capture(cls.name, unrelated_seed, *moments[0], render=pixels, first=True)
    if pixels:
        d, d_other = pixel_distance(a.frame, b.frame), pixel_distance(a.frame, other.frame)
        s = pixel_distance(a.frame, b.frame, ~(a.robot | b.robot))
        s_other = pixel_distance(a.first_frame, other.first_frame,
                                 ~(a.first_robot | other.first_robot))
    else:
        d = d_other = s = s_other = float("nan")
    names = cls.state_names
    firsts = first_states(cls.name, [seed, *range(unrelated_seed,
                                                  unrelated_seed + UNRELATED_FIRST_FRAMES)])
    core = np.array([not symmetric_heading(n) for n in names])
    ratios = []
    for keep in (np.ones(len(names), bool), core):
        between = state_distance(a.state[keep], b.state[keep])
        apart = float(np.mean([state_distance(firsts[0][keep], f[keep]) for f in firsts[1:]]))
        ratios.append((between, apart, between / max(apart, 1e-9)))
    gap = np.abs(a.state - b.state)
    worst = names[int(np.argmax(gap))]
    discrete = tuple(n for n, g in zip(names, gap, strict=True) if g > 0 and not is_continuous(n))
    jitter = max((g for n, g in zip(names, gap, strict=True) if n.endswith(("_x", "_y", "_z"))),
                 default=0.0)
    arm_gap = np.abs(a.joints - b.joints)[~_GRIPPER]
    gripper_gap = np.abs(a.joints - b.joints)[_GRIPPER]
    n = max(len(a.actions), len(b.actions))  # a finished episode holds its last action
    pad = [np.concatenate([m.actions, np.repeat(m.actions[-1:], n - len(m.actions), 0)])
           for m in (a, b)]
    return AliasingResult(cls.name, seed, unrelated_seed, round(d, 3), round(d_other, 3),
                          round(d / max(d_other, 1e-9), 3), round(s, 3), round(s_other, 3),
                          round(s / max(s_other, 1e-9), 3), (a.next_subtask, b.next_subtask),
                          round(float(np.abs(pad[0] - pad[1]).max()), 3), (a.step, b.step),
                          *(round(v, 4) for v in ratios[0]), round(ratios[1][2], 4), worst,
                          discrete, round(float(jitter), 4),
                          round(float(arm_gap.max()), 4), _ARM_JOINTS[int(np.argmax(arm_gap))],
                          round(float(gripper_gap.max()), 4), pair)
