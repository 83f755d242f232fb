"""Every task has an aliasing point: two moments that look alike to the head camera but need
different actions. That is what makes the benchmark's tasks memory tasks."""

from rmbench.aliasing import measure


def test_aliasing_point(task_name):
    r = measure(task_name, seed=100000)
    # near-identical: far closer than the same moment in an unrelated layout
    assert r.pixel_distance < 0.5 * r.unrelated_distance, r
    # and yet the expert goes on differently
    assert r.next_subtasks[0] != r.next_subtasks[1] or r.action_divergence > 0.1, r
