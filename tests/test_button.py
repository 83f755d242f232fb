"""Press counting on the shared spring button, driven through real physics."""

import mujoco
import pytest

from rmbench.sim.fixtures import Button
from rmbench.sim.station import TABLE_TOP


@pytest.fixture
def button():
    spec = mujoco.MjSpec()
    spec.option.timestep = 0.002
    b = Button("b")
    b.build(spec)
    model = spec.compile()
    data = mujoco.MjData(model)
    b.bind(model)
    b.reset()
    cap = model.body("b/cap").id
    return b, model, data, cap


def push(button, force, seconds):
    b, model, data, cap = button
    data.xfrc_applied[cap, 2] = -force
    for _ in range(int(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
        b.update(data)
    data.xfrc_applied[cap, 2] = 0.0


def test_spring_holds_the_cap_up_at_rest(button):
    b, model, data, _ = button
    push(button, 0.0, 0.5)
    assert abs(b.depth(data)) < 1e-3
    assert b.count == 0
    assert b.top(model)[2] == pytest.approx(TABLE_TOP + b.base_height + b.cap_height)


def test_a_push_counts_once_even_when_held(button):
    b, _, data, _ = button
    push(button, 20.0, 1.0)  # held down for a second
    assert b.depth(data) > b.press_depth
    assert b.count == 1
    push(button, 0.0, 0.3)  # released: spring returns it
    assert b.depth(data) < b.release_depth
    assert b.count == 1


def test_each_full_push_counts(button):
    b, _, _, _ = button
    for expected in (1, 2, 3):
        push(button, 20.0, 0.3)
        push(button, 0.0, 0.3)
        assert b.count == expected


def test_a_shallow_push_does_not_count(button):
    b, _, data, _ = button
    push(button, 2.0, 0.5)  # preload 1.2 N: moves ~3 mm, short of the 6 mm threshold
    assert 0 < b.depth(data) < b.press_depth
    assert b.count == 0


def test_no_second_count_without_returning_past_release(button):
    b, _, data, _ = button
    push(button, 20.0, 0.3)
    push(button, 4.0, 0.5)  # eases off but stays below the release depth
    assert b.depth(data) > b.release_depth
    push(button, 20.0, 0.3)
    assert b.count == 1


def test_a_shaky_push_counts_once(button):
    """A finger that bounces on the cap, letting it spring up for a few milliseconds at a
    time, is one press: the cap must stay up for ``rearm_time`` before a push counts again."""
    b, _, data, _ = button
    for _ in range(6):
        push(button, 20.0, 0.06)
        push(button, 0.0, 0.05)  # springs past the release depth, but not for long
    assert b.count == 1
    push(button, 0.0, b.rearm_time + 0.1)  # let go for good
    push(button, 20.0, 0.2)
    assert b.count == 2


def test_a_quick_deliberate_double_press_counts_twice(button):
    b, _, _, _ = button
    push(button, 20.0, 0.2)
    push(button, 0.0, b.rearm_time + 0.05)
    push(button, 20.0, 0.2)
    assert b.count == 2
