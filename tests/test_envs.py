import json

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rmbench
from rmbench.experts import make_expert
from rmbench.sim.station import home_action
from rmbench.tasks import UnknownTaskError, get_task
from rmbench.tasks.registry import register
from tests.conftest import roll_out


def test_check_env_on_every_registered_id(task_name):
    env = gym.make(get_task(task_name).gym_id, width=96, height=72)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_observation_layout(task_name):
    env = rmbench.make(task_name)
    obs, info = env.reset(seed=3)
    assert set(obs["pixels"]) == {"head", "left_wrist", "right_wrist"}
    assert all(img.shape == (240, 320, 3) and img.dtype == np.uint8
               for img in obs["pixels"].values())
    assert obs["agent_pos"].shape == (14,)
    assert info["instruction"] in get_task(task_name).instructions_seen
    assert info["subtask"] == get_task(task_name).subtasks[info["plan"][0]]
    env.close()


def test_unseen_instructions_are_held_out(task_name):
    env = rmbench.make(task_name, render=False, instructions="unseen")
    _, info = env.reset(seed=1)
    cls = get_task(task_name)
    assert info["instruction"] in cls.instructions_unseen
    assert not set(cls.instructions_seen) & set(cls.instructions_unseen)


def test_same_seed_same_episode_bit_for_bit(task_name):
    runs = []
    for _ in range(2):
        env = rmbench.make(task_name, width=128, height=96)
        runs.append(roll_out(env, make_expert(env), seed=100007, steps=80))
        env.close()
    (obs_a, act_a), (obs_b, act_b) = runs
    assert len(obs_a) == len(obs_b)
    for a, b in zip(act_a, act_b, strict=True):
        assert np.array_equal(a, b)
    for a, b in zip(obs_a, obs_b, strict=True):
        assert np.array_equal(a["agent_pos"], b["agent_pos"])
        for cam in a["pixels"]:
            assert np.array_equal(a["pixels"][cam], b["pixels"][cam])


def test_different_seeds_differ(task_name):
    env = rmbench.make(task_name, render=False)
    _, a = env.reset(seed=100000)
    _, b = env.reset(seed=100001)
    assert a["hidden"] != b["hidden"] or a["instruction"] != b["instruction"]


@pytest.mark.parametrize("bad, message", [
    (np.zeros(13), "shape"),
    (np.zeros((2, 14)), "shape"),
    (np.full(14, np.nan), "NaN"),
    (np.r_[np.zeros(13), np.inf], "NaN/inf at indices \\[13\\]"),
    (np.zeros(14) + 1j, "real numbers, got complex128"),
    (["0"] * 14, "real numbers"),
    ([None] * 14, "real numbers, got object"),
    ({"a": 1}, "real numbers"),
])
def test_bad_actions_raise_value_error(bad, message):
    env = rmbench.make("put_back_block", render=False)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=message):
        env.step(bad)


@pytest.mark.parametrize("limit", [0, -1, 2.5, True, "100"])
def test_a_step_limit_is_a_whole_number_of_steps(limit):
    with pytest.raises(ValueError, match="step_limit must be a whole number >= 1"):
        rmbench.make("put_back_block", render=False, step_limit=limit)


def test_targets_beyond_limits_are_clipped_and_counted():
    env = rmbench.make("put_back_block", render=False)
    env.reset(seed=0)
    action = home_action()
    action[0] = 10.0  # waist far past its limit
    action[6] = 1.5  # gripper above fully open
    _, _, _, _, info = env.step(action)
    assert info["clipped_targets"] == 2


def test_truncation_at_step_limit():
    env = rmbench.make("put_back_block", render=False, step_limit=5)
    obs, _ = env.reset(seed=0)
    for i in range(5):
        _, _, terminated, truncated, _ = env.step(obs["agent_pos"])
        assert not terminated
        assert truncated == (i == 4)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(obs["agent_pos"])


def test_physics_blow_up_cuts_the_episode_off_with_sim_error():
    env = rmbench.make("put_back_block", render=False)
    obs, _ = env.reset(seed=0)
    env.unwrapped.sim.data.qvel[:] = np.nan
    _, reward, terminated, truncated, info = env.step(obs["agent_pos"])
    assert truncated and not terminated and not info["is_success"]
    assert "diverged" in info["sim_error"] or "non-finite" in info["sim_error"]


@pytest.mark.parametrize("spin, blow_up", [(400.0, False), (3000.0, True)])
def test_a_struck_piece_may_spin_fast_without_a_sim_error(spin, blow_up):
    """A cube knocked by an arm spins past the joints' 200 rad/s limit in sound physics;
    only a spin no strike gives is a blow-up."""
    env = rmbench.make("put_back_block", render=False)
    obs, _ = env.reset(seed=0)
    sim = env.unwrapped.sim
    free = sim.model.joint("cube/free")
    sim.data.qvel[free.dofadr[0] + 5] = spin  # about the vertical axis: it stays on the table
    _, _, _, truncated, info = env.step(obs["agent_pos"])
    assert ("sim_error" in info) == blow_up and truncated == blow_up


def test_unknown_task_lists_known_ones():
    with pytest.raises(UnknownTaskError, match="known tasks: .*put_back_block"):
        rmbench.make("no_such_task")
    with pytest.raises(UnknownTaskError, match="known tasks"):
        get_task("rmbench/NoSuchTask-v0")
    assert get_task("rmbench/PutBackBlock-v1").name == "put_back_block"


def test_registry_refuses_duplicates():
    cls = get_task("put_back_block")
    with pytest.raises(ValueError, match="already registered"):
        register(type("Copy", (cls,), {}))
    rmbench.register_envs()  # re-registering our own ids is a no-op
    spec = gym.registry[cls.gym_id]
    old = spec.kwargs
    spec.kwargs = {"task": "someone_else"}
    try:
        with pytest.raises(ValueError, match="already registered"):
            rmbench.register_envs()
    finally:
        spec.kwargs = old


def test_bad_camera_config_is_a_clear_error():
    with pytest.raises(ValueError, match="unknown camera"):
        rmbench.make("put_back_block", cameras=("head", "ceiling"))


@pytest.mark.parametrize("obs_type", ["environment_state_agent_pos",
                                      "pixels_environment_state_agent_pos"])
def test_check_env_with_the_state_observation(task_name, obs_type):
    env = gym.make(get_task(task_name).gym_id, width=96, height=72, obs_type=obs_type)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_obs_types():
    n = len(get_task("put_back_block").state_names)
    state = rmbench.make("put_back_block", obs_type="environment_state_agent_pos")
    obs, _ = state.reset(seed=3)
    assert set(obs) == {"agent_pos", "environment_state"}
    assert obs["environment_state"].shape == (n,) and obs["environment_state"].dtype == np.float64
    assert not state.unwrapped.config.render  # no pixels asked for: the cameras stay off
    both = rmbench.make("put_back_block", obs_type="pixels_environment_state_agent_pos",
                        width=64, height=48)
    obs_both, _ = both.reset(seed=3)
    assert set(obs_both) == {"agent_pos", "environment_state", "pixels"}
    assert np.array_equal(obs_both["environment_state"], obs["environment_state"])
    default = rmbench.make("put_back_block", width=64, height=48)  # today's observation
    obs_default, _ = default.reset(seed=3)
    assert set(obs_default) == {"agent_pos", "pixels"}
    assert set(default.observation_space.spaces) == {"agent_pos", "pixels"}
    for a, b in zip(obs_both["pixels"].values(), obs_default["pixels"].values(), strict=True):
        assert np.array_equal(a, b)
    action = obs["agent_pos"]
    for env in (state, both, default):
        env.step(action)
        env.close()
    with pytest.raises(ValueError, match="obs_type must be one of .*environment_state_agent_pos"):
        rmbench.make("put_back_block", obs_type="state")


def test_a_step_ended_by_a_physics_error_has_every_key_of_a_step():
    env = rmbench.make("put_back_block", render=False)
    obs, _ = env.reset(seed=0)
    keys = set(env.step(obs["agent_pos"])[4])
    env.unwrapped.sim.data.qvel[:] = np.nan
    info = env.step(obs["agent_pos"])[4]
    assert keys <= set(info) and info["subtask_end"] is False
    assert info["step"] == 2 and info["failure_reason"].startswith("sim error")


def test_a_reset_that_fails_leaves_no_episode_to_step():
    """A hidden value the task refuses fails the reset after the old episode was torn down:
    step() then refuses instead of going on with half of it. Unknown options are named."""
    env = rmbench.make("put_back_block", render=False)
    obs, _ = env.reset(seed=0)
    with pytest.raises(ValueError):
        env.reset(seed=1, options={"hidden": {"original_mat": "nowhere"}})
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(obs["agent_pos"])
    with pytest.raises(ValueError, match=r"unknown reset option\(s\) \['hiden'\]; options: "
                                         r"\['hidden'\]"):
        env.reset(seed=1, options={"hiden": {"original_mat": "left"}})
    env.reset(seed=1, options={"hidden": {"original_mat": "left"}})
    env.step(obs["agent_pos"])
    for bad, said in ((["hidden"], "options must be a map"), ({"hidden": ["left"]},
                                                             "hidden must be a map")):
        with pytest.raises(ValueError, match=said):
            env.reset(seed=1, options=bad)
    with pytest.raises(ValueError, match="cameras=\\('head',\\)"):
        rmbench.make("put_back_block", cameras="head")
    with pytest.raises(ValueError, match="render=False"):
        rmbench.make("put_back_block", cameras=())
    # a state observation with rendering on (for env.render's video) needs no camera
    rmbench.make("put_back_block", obs_type="environment_state_agent_pos", render=True,
                 cameras=()).close()
    assert "pixels" not in rmbench.make("put_back_block", cameras=(), render=False).reset(
        seed=0)[0]


@pytest.mark.parametrize("task", ["battery_try", "cover_blocks", "blocks_ranking_try"])
def test_an_episode_s_hidden_facts_fix_another_s_as_reported(task):
    """``info["hidden"]``'s settable facts (as JSON lists) given back as the hidden option
    set the same facts."""
    env = rmbench.make(task, render=False)
    _, info = env.reset(seed=3)
    fixed = {k: v for k, v in info["hidden"].items() if k in rmbench.TASKS[task].hidden_keys}
    assert fixed and any(isinstance(v, list) for v in fixed.values())
    _, again = env.reset(seed=11, options={"hidden": fixed})
    assert {k: again["hidden"][k] for k in fixed} == fixed
    env.close()


@pytest.mark.parametrize("task", sorted(rmbench.TASKS))
def test_an_episode_s_hidden_facts_given_back_whole_fix_that_episode(task):
    """``info["hidden"]`` as reported (through JSON) given back whole: the settable facts are
    fixed and the rest checked, so the same seed gives the same episode; a reported fact that
    is not the episode's is refused in one line."""
    env = rmbench.make(task, render=False)
    obs, info = env.reset(seed=3)
    hidden = json.loads(json.dumps(info["hidden"]))
    again, info_again = env.reset(seed=3, options={"hidden": hidden})
    assert info_again["hidden"] == info["hidden"]
    assert all(np.array_equal(obs[k], again[k]) for k in obs)
    reported = sorted(set(hidden) - set(rmbench.TASKS[task].hidden_keys))
    if reported:
        _, other = env.reset(seed=4)
        wrong = next((k for k in reported if other["hidden"][k] != info["hidden"][k]), None)
        if wrong is not None:
            with pytest.raises(ValueError, match=f"hidden {wrong}=.* is not this episode's"):
                env.reset(seed=4, options={"hidden": {wrong: hidden[wrong]}})
    with pytest.raises(ValueError, match="cannot fix hidden variable 'no_such'"):
        env.reset(seed=3, options={"hidden": {"no_such": 1}})
    env.close()
