"""Where failed episodes end: the plan's stage and how, from evaluation records."""

from rmbench.eval.endings import ending, failure_kind, failures_by_stage


def record(success, reason, message, stages):
    events = [[0, "task", "subtask", stages[0]]] + [
        [10 * (i + 1), "task", "subtask", s] for i, s in enumerate(stages[1:])]
    events.insert(1, [0, "policy", "subtask", "the goal"])  # a policy's own text is not a stage
    return {"success": success, "reason": reason, "message": message, "events": events}


def test_failures_are_counted_by_the_stage_they_ended_in_and_how():
    records = [
        record(True, "success", "", ["reach", "press", "return", "done"]),
        record(False, "timeout", "", ["reach", "press", "return"]),
        record(False, "timeout", "", ["reach", "press", "return"]),
        record(False, "task_failure", "block put back on the wrong mat (right instead of left)",
               ["reach", "press", "return"]),
        record(False, "task_failure", "button pressed before the block was at the centre",
               ["reach"]),
        record(False, "policy_error", "NaN action", ["reach", "press"]),
    ]
    got = failures_by_stage(records)
    # stages in the plan's order, endings most frequent first, per-episode details cut
    assert list(got) == ["reach", "press", "return"]
    assert got["return"] == {"timeout": 2, "block put back on the wrong mat": 1}
    assert got["reach"] == {"button pressed before the block was at the centre": 1}
    assert got["press"] == {"policy_error": 1}
    assert sum(sum(v.values()) for v in got.values()) == 5  # every failure, once
    assert failures_by_stage(records[:1]) == {}
    assert ending({"reason": "task_failure", "message": "fell to [0.1, 0.2]"}) == "fell to"


def test_a_failure_kind_keeps_the_words_and_drops_the_episodes_particulars():
    # the expert's messages (the robustness tables) and the tasks' (the failure tables) alike
    assert failure_kind("expert gave up: left arm cannot reach [0.1 -0.2 0.9] (IK error 0.031 m)"
                        ) == "expert gave up: left arm cannot reach"
    assert failure_kind("expert gave up: could not move a piece to [0.12, -0.1] in 3 tries"
                        ) == "expert gave up: could not move a piece to"
    assert failure_kind("picked up a wrong object (red cube)") == "picked up a wrong object"
    assert failure_kind("cover state went 100 -> 000; expected 110") == \
        "cover state went 100 -> 000; expected 110"
