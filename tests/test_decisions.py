"""The planner's choices at the ends a policy declared, against the task's plan
(eval/decisions.py)."""

from rmbench.eval.decisions import choices, decision_counts

PRESS, SWAP_MR, SWAP_LR = "press", "swap middle and right", "swap left and right"


def _record(events: list[list], steps: int = 2000) -> dict:
    return {"events": events, "steps": steps}


def test_a_choice_is_judged_at_an_end_declared_on_time_against_the_next_step():
    """blocks_ranking_try's pattern: after the second press the plan wants the second swap;
    the planner repeats the first. Each end is declared 7 frames after the task counts it."""
    events = [[0, "task", "subtask", PRESS], [0, "task", "subtask_step", 0],
              [0, "policy", "subtask", PRESS], [0, "policy", "subtask_ends", 0],
              [38, "task", "subtask", SWAP_MR], [38, "task", "subtask_step", 1],
              [45, "policy", "subtask", SWAP_MR], [45, "policy", "subtask_ends", 1],
              [443, "task", "subtask", PRESS], [443, "task", "subtask_step", 2],
              [448, "policy", "subtask", PRESS], [448, "policy", "subtask_ends", 2],
              [534, "task", "subtask", SWAP_LR], [534, "task", "subtask_step", 3],
              [541, "policy", "subtask", SWAP_MR], [541, "policy", "subtask_ends", 3]]
    assert choices(_record(events)) == [(SWAP_MR, SWAP_MR), (PRESS, PRESS), (SWAP_LR, SWAP_MR)]
    counts = decision_counts([_record(events)])
    assert (counts["judged"], counts["right"]) == (3, 2)
    assert counts["by_next"][SWAP_LR] == {"right": 0, "of": 1, "chose_instead": {SWAP_MR: 1}}


def test_an_early_or_false_end_is_not_the_planner_s_choice():
    """An end declared before the task counted its step (early), or beyond every counted step
    (false), chooses on an unfinished step: the end classifier's error, not judged here."""
    events = [[0, "task", "subtask", PRESS], [0, "task", "subtask_step", 0],
              [0, "policy", "subtask", PRESS], [0, "policy", "subtask_ends", 0],
              [20, "policy", "subtask", SWAP_LR], [20, "policy", "subtask_ends", 1],
              [38, "task", "subtask", SWAP_MR], [38, "task", "subtask_step", 1],
              [300, "policy", "subtask", PRESS], [300, "policy", "subtask_ends", 2]]
    assert choices(_record(events)) == []
    assert decision_counts([_record(events)]) == {"judged": 0, "right": 0, "by_next": {}}


def test_no_policy_subtask_is_no_count_and_capped_events_are_left_out():
    plain = [[0, "task", "subtask", PRESS], [0, "task", "subtask_step", 0]]
    assert decision_counts([_record(plain)]) is None
    events = [[0, "task", "subtask", PRESS], [0, "task", "subtask_step", 0],
              [0, "policy", "subtask", PRESS], [0, "policy", "subtask_ends", 0],
              [38, "task", "subtask", SWAP_MR], [38, "task", "subtask_step", 1],
              [45, "policy", "subtask", SWAP_LR], [45, "policy", "subtask_ends", 1]]
    capped = _record(events + [[None, "events", "left_out", 3]])
    assert decision_counts([_record(events), capped])["judged"] == 1
