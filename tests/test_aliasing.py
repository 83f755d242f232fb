"""Every task has aliasing points: pairs of moments its expert's plan revisits
(``Task.aliasing_pairs``) that look alike to the head camera but need different actions. That
is what makes the benchmark's tasks memory tasks. The camera is compared on the scene (the
robot's pixels left out) and the arms by their joints: a fraction of a degree between two
moments moves the arms' edges by a pixel, which the whole frame counts (battery_try, after the
inserts against after a flip: whole-frame ratio 0.53, the scene's 0.005, the arms 0.005 rad).

The same holds for the state observation (``Task.environment_state``): at the two moments no
flag, one-hot, colour, lamp or digit differs (what a cover, the screen or the holder hides is
zero in both), every object is within 2 cm of itself (a vector that listed two identical cubes
in a fixed order would put them a tray or a mat apart: 0.15 m in swap_blocks, 0.24 m in
rearrange_blocks), and the vectors are far closer than two layouts are. So a state policy
needs memory exactly where a pixel policy does.

Euclidean distances, measured at the headline pairs (seed 100000, ``benchmarks/aliasing.py``,
which measures every pair on four seeds): the pair's; the mean
over the first frames of seed 100000 and each of 100001-100008; their ratio; the ratio
without the headings of symmetric pieces ("core"). In brackets the ratios from seed 100004.

    task                pair     layouts  ratio             core
    observe_and_pickup  0.0      5.2372   0.0     [0.0]     0.0     [0.0]
    put_back_block      0.0136   1.263    0.0108  [0.0028]  0.0148  [0.0121]
    rearrange_blocks    0.0097   1.2612   0.0077  [0.0079]  0.0185  [0.0264]
    swap_T              0.001    0.8816   0.0012  [0.0017]  0.0012  [0.0017]
    swap_blocks         0.0763   0.6796   0.1122  [2.0126]  0.0846  [0.0733]
    battery_try         0.0037   2.3031   0.0016  [0.0004]  0.0001  [0.0004]
    blocks_ranking_try  0.8133   1.5649   0.5197  [0.0345]  0.0057  [0.0042]
    cover_blocks        0.0      2.597    0.0     [0.0]     0.0     [0.0]
    press_button        0.0      4.0665   0.0     [0.0]     0.0     [0.0]

The core residue is placement jitter (millimetres). The full ratio is high where the pair's
moments have cubes in each other's places (blocks_ranking_try at 100000, swap_blocks at
100004): a cube keeps the yaw it was drawn at reset when it is carried, so the two moments'
cubes show traded yaws (in the frames too), up to 0.4 rad apart. No frame tells a traded yaw
from a drawn one, so the test bounds the core ratio.

The arms' joints, which every policy reads, agree at the pairs as well (largest difference over
the twelve arm joints at most 0.005 rad, battery_try's pairs 1 and 2). battery_try's pairs are
the frames each try is counted at, where a planner chooses the next flip: the task counts a try only with both
arms home and settled (battery_try-v3; v4 averages the arms over half a second, so that a try
is counted under the collection's action noise too). Counted as the cell went in (v1), the arm that had set
it down was still over its slot there; counted as its gripper came within 3 cm of home (v2),
it was still turning its wrist back, 0.1-0.2 rad off: either showed which arm moved last, and
so which flip came next. ``test_battery_try_counts_show_no_arm`` checks every count. The
grippers agree too (at most 0.025 apart, swap_T's): swap_blocks' pair is the episode's first
step against its end, where its v1 expert had left a hand half open, 0.40 from the opening at
reset (swap_blocks-v2 reopens it). rearrange_blocks-v1's expert kept the pressing hand closed
on its way home, so that at home with both mats loaded the hand told whether the press was
made (0.96 apart); v2 reopens it there.
"""

import pytest

from rmbench.aliasing import measure
from rmbench.tasks.registry import ordered

STATE_RATIO = 0.2  # the core ratio's bound; measured at most 0.085 (swap_blocks)
ARM_GAP = 0.05  # rad, the arm joints' bound; measured at most 0.005 (battery_try)
GRIPPER_GAP = 0.05  # the grippers' (0 closed, 1 open); measured at most 0.025 (swap_T)

PAIRS = [(cls.name, k) for cls in ordered() for k in range(len(cls.aliasing_pairs))]


@pytest.mark.parametrize("task_name, pair", PAIRS, ids=[f"{t}-{k}" for t, k in PAIRS])
def test_aliasing_pair(task_name, pair):
    """Every pair of moments a task's plan revisits (``Task.aliasing_pairs``) looks alike to
    the head camera, in the state vector and in the arms, while the expert goes on differently.
    """
    r = measure(task_name, seed=100000, pair=pair)
    # the scene near-identical: far closer than the same moment in an unrelated layout (the
    # robot's pixels left out; the arms are held to their joints below)
    assert r.scene_distance < 0.5 * r.unrelated_scene_distance, r
    # and yet the expert goes on differently
    assert r.next_subtasks[0] != r.next_subtasks[1] or r.action_divergence > 0.1, r
    # the state observation aliases too
    assert not r.state_discrete_differ, r
    assert r.state_position_jitter < 0.02, r
    assert r.state_ratio_core < STATE_RATIO, r
    # and so do the arms and the hands (rearrange_blocks-v1 left the pressing hand closed:
    # 0.96 apart before and after the press)
    assert r.arm_gap < ARM_GAP and r.gripper_gap < GRIPPER_GAP, r


def test_aliasing_pair_out_of_range_is_a_clear_error():
    with pytest.raises(ValueError, match="aliasing pairs 0-0, not 1"):
        measure("observe_and_pickup", pair=1)


def test_battery_try_counts_show_no_arm():
    """Every frame battery_try counts a step at (a planner's decision: which flip next) shows
    both arms at home, on two seeds and both orders of flips: no pair of those frames tells
    by the arms which arm moved last (v2 counted with the last one 0.1-0.2 rad off)."""
    import numpy as np

    from rmbench.envs.registration import make
    from rmbench.experts import make_expert

    env = make("battery_try", render=False)
    for seed in (100000, 100001):
        for correct in ((1, 1), (0, 1)):
            expert = make_expert(env)
            obs, info = env.reset(seed=seed, options={"hidden": {"correct": correct}})
            expert.reset(info["instruction"], info)
            stage, at_counts = info["subtask_step"], []
            for _ in range(env.unwrapped.step_limit):
                obs, _, terminated, truncated, info = env.step(expert.act(obs))
                if info["subtask_step"] != stage and not terminated:
                    stage = info["subtask_step"]
                    at_counts.append(np.asarray(obs["agent_pos"], float))
                if terminated or truncated:
                    break
            assert info["is_success"] and len(at_counts) >= 3, (seed, correct)
            arms = np.stack(at_counts)[:, [i for i in range(14) if i not in (6, 13)]]
            assert np.abs(arms[:, None] - arms[None]).max() < 0.01, (seed, correct)


def test_battery_try_counts_every_try_under_the_collections_noise():
    """The datasets are collected with executed action noise (white, 0.02 rad: the tables'
    recipe); each try must still be counted there, or the dataset holds one subtask and the
    planner has nothing to decide (v3 read the arms per step and counted none)."""
    from rmbench.envs.noise import NoiseSpec, perturber
    from rmbench.envs.registration import make
    from rmbench.experts import make_expert

    env = make("battery_try", render=False)
    # seeds the expert solves under this noise (on others it gives up, as a collection skips)
    for seed, correct in ((100000, (0, 1)), (100002, (1, 1))):
        expert = make_expert(env)
        obs, info = env.reset(seed=seed, options={"hidden": {"correct": correct}})
        expert.reset(info["instruction"], info)
        noisy = perturber(NoiseSpec(kind="white", sigma=0.02), seed, env)
        steps = [info["subtask_step"]]
        for _ in range(env.unwrapped.step_limit):
            obs, _, terminated, truncated, info = env.step(noisy(expert.act(obs)))
            if info["subtask_step"] != steps[-1]:
                steps.append(info["subtask_step"])
            if terminated or truncated:
                break
        plan = env.unwrapped.task.plan()
        assert info["is_success"], (seed, correct)
        # every step of the plan counted in turn, then done
        assert steps == list(range(len(plan) + 1)), (seed, correct, steps)
