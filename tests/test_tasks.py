"""Success and failure predicates, with the scene set up directly."""

import mujoco
import numpy as np
import pytest

import rmbench


def settle(env, steps=150):
    sim = env.unwrapped.sim
    for _ in range(steps):
        mujoco.mj_step(sim.model, sim.data)
        env.unwrapped.task.on_substep()


def press(env, button):
    """Drive a button through a full push the way physics would: down past the click, back up,
    and left up long enough to re-arm (the button debounces)."""
    data = env.unwrapped.sim.data
    data.qpos[button.qpos_adr] = -button.travel
    env.unwrapped.task.on_substep()
    data.qpos[button.qpos_adr] = 0.0
    env.unwrapped.task.on_substep()
    data.time += button.rearm_time + 1e-3
    env.unwrapped.task.on_substep()


def task_env(name, seed):
    """A physics-only env of ``name`` reset to ``seed``, and its task."""
    env = rmbench.make(name, render=False)
    env.reset(seed=seed)
    return env, env.unwrapped.task


def put_back_env():
    return task_env("put_back_block", seed=5)


def test_put_back_block_success_path():
    env, task = put_back_env()
    data, model = task.data, task.model
    task.cube.place(data, task.centre)
    settle(env)
    assert task.evaluate().stage == 1
    press(env, task.button)
    ev = task.evaluate()
    assert ev.stage == 2 and not ev.failure
    task.cube.place(data, task.mats[task.original].xy(model))
    settle(env)
    ev = task.evaluate()
    assert ev.success and ev.progress == 1.0 and ev.stage == 3


def test_put_back_block_wrong_mat_is_failure_not_success():
    env, task = put_back_env()
    task.cube.place(task.data, task.centre)
    settle(env)
    press(env, task.button)
    wrong = next(n for n in task.mats if n != task.original)
    task.cube.place(task.data, task.mats[wrong].xy(task.model))
    settle(env)
    ev = task.evaluate()
    assert not ev.success and ev.failure and "wrong mat" in ev.failure_reason


def test_put_back_block_press_before_centre_fails():
    env, task = put_back_env()
    press(env, task.button)
    ev = task.evaluate()
    assert ev.failure and "before the block" in ev.failure_reason


def test_put_back_block_second_press_fails():
    env, task = put_back_env()
    task.cube.place(task.data, task.centre)
    settle(env)
    press(env, task.button)
    press(env, task.button)
    ev = task.evaluate()
    assert ev.failure and "more than once" in ev.failure_reason


def test_put_back_block_untouched_is_neither():
    env, task = put_back_env()
    ev = task.evaluate()
    assert not ev.success and not ev.failure and ev.progress == 0.0


def test_every_episode_starts_from_the_first_stage_with_only_its_own_overrides():
    """The base class starts each episode (progress only moves forward within one), and a
    hidden value fixed for one episode is not fixed for the next."""
    env, task = put_back_env()
    drawn = task.original
    fixed = next(n for n in task.mats if n != drawn)
    task.cube.place(task.data, task.centre)
    settle(env)
    press(env, task.button)
    assert task.evaluate().stage == 2
    _, info = env.reset(seed=5, options={"hidden": {"original_mat": fixed}})
    ev = task.evaluate()
    assert (ev.stage, ev.progress, info["progress"]) == (0, 0.0, 0.0)
    assert info["hidden"]["original_mat"] == fixed
    env.reset(seed=5)
    assert task.original == drawn and task.evaluate().stage == 0


def press_button_env():
    return task_env("press_button", seed=11)


def enter_digits(env, task):
    """Press the left button d1 times and the middle one d2 times."""
    for button, times in ((task.left, task.d1), (task.middle, task.d2)):
        for _ in range(times):
            press(env, button)


def test_press_button_exact_counts_then_confirm_succeeds():
    env, task = press_button_env()
    enter_digits(env, task)
    ev = task.evaluate()
    assert not ev.success and ev.stage == task.d1 + task.d2
    press(env, task.confirm)
    ev = task.evaluate()
    assert ev.success and ev.progress == 1.0


def test_press_button_confirm_with_wrong_count_fails():
    env, task = press_button_env()
    for _ in range(task.d1):
        press(env, task.left)
    press(env, task.confirm)
    ev = task.evaluate()
    assert ev.failure and not ev.success and "confirmed after" in ev.failure_reason


def test_press_button_overcount_fails():
    env, task = press_button_env()
    for _ in range(task.d1 + 1):
        press(env, task.left)
    ev = task.evaluate()
    assert ev.failure and "left button pressed" in ev.failure_reason


def test_press_button_press_after_confirm_fails():
    env, task = press_button_env()
    enter_digits(env, task)
    press(env, task.confirm)
    press(env, task.confirm)
    assert task.evaluate().failure


def test_press_button_tiles_show_the_digits():
    from rmbench.sim.fixtures import DIGIT_SEGMENTS

    env, task = press_button_env()
    for tile, digit in zip(task.tiles, (task.d1, task.d2), strict=True):
        lit = {s for s, gid in tile.seg_ids.items()
               if np.allclose(task.model.geom_rgba[gid], tile.ink_rgba)}
        assert lit == set(DIGIT_SEGMENTS[digit])


def test_an_evaluation_that_contradicts_itself_is_refused():
    """Every task's verdict goes through Evaluation, so its invariants hold for all nine: a
    success is full progress, and never a failure too."""
    from rmbench.tasks.base import Evaluation
    Evaluation(success=True, failure=False, progress=1.0, stage=3)
    with pytest.raises(ValueError, match="progress 1.0"):
        Evaluation(success=True, failure=False, progress=0.5, stage=1)
    with pytest.raises(ValueError, match="success and failure"):
        Evaluation(success=True, failure=True, progress=1.0, stage=3)
