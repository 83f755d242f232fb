"""Subtask-boundary diagnostics: a policy's declared ends against the simulator's (eval/boundaries.py)."""

from rmbench.eval.boundaries import LATE, boundary_counts, classify, end_steps


def events(counted_after: list[int], declared_on: list[int]) -> list[list]:
    """Events as an evaluation records them: the task's step count seen after env step s, the
    policy's count of declared ends seen when it acted on frame d."""
    out = [[0, "task", "subtask_step", 0], [0, "policy", "subtask_ends", 0]]
    out += [[s, "task", "subtask_step", k + 1] for k, s in enumerate(counted_after)]
    out += [[d, "policy", "subtask_ends", k + 1] for k, d in enumerate(declared_on)]
    return sorted(out, key=lambda e: e[0])


def test_ends_are_matched_in_order_and_classified():
    # the simulator counts steps after env steps 41, 101, 161 (frames 40, 100, 160)
    counted, declared = end_steps(events([41, 101, 161], [40, 90, 190, 200]))
    assert counted == [40, 100, 160] and declared == [40, 90, 190, 200]
    verdicts = [e["verdict"] for e in classify(counted, declared)]
    assert verdicts == ["on_time", "early", "late", "false"]
    assert [e["verdict"] for e in classify([40, 100], [40 + LATE])] == ["on_time", "missed"]


def test_two_steps_counted_at_once_are_two_ends():
    counted, _ = end_steps([[0, "task", "subtask_step", 0], [31, "task", "subtask_step", 2]])
    assert counted == [30, 30]


def test_summary_counts_verdicts_and_first_wrong():
    records = [{"events": events([41, 101], [40, 101])}, {"events": events([41, 101], [35])}]
    s = boundary_counts(records)
    assert (s["on_time"], s["early"], s["missed"]) == (2, 1, 1)
    assert s["first_wrong"] == {"early": 1} and s["median_delay"] == 0.0
    assert boundary_counts([{"events": [[0, "task", "subtask_step", 0]]}]) is None  # no policy ends
    # an episode whose events passed the limit has gaps: left out, and counted
    capped = {"events": events([41], [40]) + [[None, "events", "left_out", 3]]}
    s = boundary_counts(records + [capped])
    assert s["episodes"] == 2 and s["capped"] == 1 and (s["on_time"], s["early"]) == (2, 1)
    assert "capped" not in boundary_counts(records)


def test_the_step_that_ends_the_episode_needs_no_declared_end():
    # a success is counted on the episode's last frame: no policy acts after it
    counted, declared = [40, 100], [40]
    assert [e["verdict"] for e in classify(counted, declared, last_frame=100)] == ["on_time"]
    assert [e["verdict"] for e in classify(counted, declared, last_frame=150)] == [
        "on_time", "missed"]
    s = boundary_counts([{"steps": 101, "events": events([41, 101], [40])}])
    assert (s["on_time"], s["missed"]) == (1, 0)
