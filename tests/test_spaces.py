"""Every observation lies in the env's declared observation space, on every task and
observation type, and Gymnasium's env checker passes with its warnings as errors."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rmbench
from rmbench.envs.env import OBS_TYPES
from rmbench.tasks import get_task

TASKS = sorted(rmbench.TASKS)
STEPS = 30
SMALL = {"cameras": ("head",), "width": 32, "height": 24}  # pixels at a glance


def outside(space: gym.spaces.Dict, obs: dict) -> list[str]:
    """The entries of ``obs`` its space does not hold, with the offending values."""
    bad = []
    for key, sub in space.spaces.items():
        if isinstance(sub, gym.spaces.Dict):
            bad += [f"{key}/{b}" for b in outside(sub, obs[key])]
        elif not sub.contains(obs[key]):
            x = np.asarray(obs[key])
            if x.shape != sub.shape or x.dtype != sub.dtype:
                bad.append(f"{key}: {x.dtype}{x.shape}, space {sub.dtype}{sub.shape}")
            else:
                idx = np.flatnonzero((x < sub.low) | (x > sub.high))
                bad.append(f"{key}[{idx.tolist()}] = {x.ravel()[idx].tolist()}, bounds "
                           f"{sub.low.ravel()[idx].tolist()} .. {sub.high.ravel()[idx].tolist()}")
    return bad


@pytest.mark.parametrize("obs_type", OBS_TYPES)
@pytest.mark.parametrize("task", TASKS)
def test_observations_of_random_steps_lie_in_the_space(task, obs_type):
    """The README's snippet, with the passive env checker gym.make adds: reset, then random
    targets, which swing the arms far harder than any policy and push joints past their
    limits (the observation reads them at the limit)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(get_task(task).gym_id, obs_type=obs_type, **SMALL)
        space, sim = env.observation_space, env.unwrapped.sim
        low, high = space["agent_pos"].low, space["agent_pos"].high
        env.action_space.seed(7)
        obs, _ = env.reset(seed=100000)
        for t in range(STEPS + 1):
            assert not outside(space, obs), (t, outside(space, obs))
            assert np.array_equal(obs["agent_pos"], np.clip(sim.agent_pos(), low, high))
            if t == STEPS:
                break
            obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:  # a piece knocked off the table, say
                obs, _ = env.reset(seed=100001 + t)
        env.close()


def test_bounds_come_from_the_models_joint_limits():
    env = rmbench.make("put_back_block", render=False)
    m, sim = env.sim.model, env.sim
    space = env.observation_space["agent_pos"]
    for k, side in enumerate(("left", "right")):
        for i, joint in enumerate(("waist", "shoulder", "elbow", "forearm_roll", "wrist_angle",
                                   "wrist_rotate")):
            lo, hi = m.joint(f"{side}/{joint}").range
            assert (space.low[7 * k + i], space.high[7 * k + i]) == (lo, hi)
        assert (space.low[7 * k + 6], space.high[7 * k + 6]) == (0.0, 1.0)
    # the gripper reads its finger (a slide joint) mapped onto [0, 1]: its limits map to 0, 1
    finger = m.joint("left/left_finger")
    d = sim.data
    saved = d.qpos.copy()
    for q, want in zip(finger.range, (0.0, 1.0), strict=True):
        d.qpos[finger.qposadr[0]] = q
        assert sim.agent_pos()[6] == want
    d.qpos[:] = saved
    # every action the action space holds lies within the joint limits: none is clipped
    a = env.action_space
    assert np.all(a.low.astype(np.float64) >= sim.action_low)
    assert np.all(a.high.astype(np.float64) <= sim.action_high)
    for edge in (a.low, a.high):
        assert sim.clip_action(edge.astype(np.float64))[1] == 0


def test_a_joint_past_its_limit_reads_at_the_limit_and_the_physics_keeps_it():
    """Random targets push a gripper's finger centimetres past its stop (a soft limit): the
    observation reads the limit, the simulation's own state is left as it is."""
    env = rmbench.make("press_button", obs_type="environment_state_agent_pos")
    env.action_space.seed(0)
    env.reset(seed=0)
    for _ in range(STEPS):
        obs, *_ = env.step(env.action_space.sample())
        raw = env.sim.agent_pos()
        if raw[6] < -0.1 or raw[6] > 1.1:
            break
    else:
        pytest.fail("no gripper past its limits in 30 random steps: pick another case")
    assert obs["agent_pos"][6] == np.clip(raw[6], 0.0, 1.0)
    qpos = env.sim.data.qpos.copy()
    env._observation()
    assert np.array_equal(env.sim.data.qpos, qpos)


def test_a_piece_thrown_beyond_5_m_reads_at_5_m():
    """Nothing walls the room: random targets throw a T out of it (seed 3, step 18)."""
    env = rmbench.make("swap_T", obs_type="environment_state_agent_pos")
    low, high = env.observation_space["environment_state"].low, \
        env.observation_space["environment_state"].high
    env.action_space.seed(3)
    env.reset(seed=3)
    for _ in range(STEPS):
        obs, *_ = env.step(env.action_space.sample())
        raw = env.task.environment_state()
        if np.any(np.abs(raw) > 5.0):
            break
    else:
        pytest.fail("no piece beyond 5 m in 30 random steps: pick another case")
    assert np.array_equal(obs["environment_state"], np.clip(raw, low, high))
    assert np.abs(obs["environment_state"]).max() == 5.0


def test_the_observation_after_a_physics_blow_up_lies_in_the_space():
    env = rmbench.make("put_back_block", obs_type="pixels_environment_state_agent_pos",
                       **SMALL)
    obs, _ = env.reset(seed=0)
    env.sim.data.qvel[:] = np.nan
    obs, _, _, truncated, info = env.step(obs["agent_pos"])
    assert truncated and "sim_error" in info
    assert not outside(env.observation_space, obs)


@pytest.mark.parametrize("task", TASKS)
def test_check_env_with_warnings_as_errors(task):
    env = gym.make(get_task(task).gym_id, obs_type="pixels_environment_state_agent_pos",
                   **SMALL)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # The one check that does not apply: Gymnasium advises a [-1, 1] (or [0, 1]) action
        # space for RL algorithms. rmbench's action is 14 absolute joint targets in radians
        # (the layout of gym-aloha, LeRobot and the datasets), bounded by the joint limits
        # (test_bounds_come_from_the_models_joint_limits).
        warnings.filterwarnings("ignore", message=r".*For Box action spaces, we recommend",
                                category=UserWarning)
        # unwrapped, as check_env asks; the render check makes a second env from the spec
        check_env(env.unwrapped)
    env.close()
