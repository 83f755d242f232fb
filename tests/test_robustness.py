"""Action noise, the expert under it, grasps that hold, and DART recording."""

import json

import numpy as np
import pytest

import rmbench
from rmbench.data import CollectConfig
from rmbench.data.record import run_expert as record_episode
from rmbench.envs.noise import NoiseSpec
from rmbench.experts import make_expert
from rmbench.rollout import run_episode
from rmbench.sim.simulator import ARM_ENTRIES

DT = 0.05


def draws(spec: NoiseSpec, n: int, seed: int = 7) -> np.ndarray:
    process = spec.process(seed, DT)
    return np.array([process.next() for _ in range(n)])


def test_noise_spec_rejects_bad_values():
    for bad in ({"kind": "pink"}, {"sigma": -0.1}, {"sigma": float("nan")}, {"tau": 0.0}):
        with pytest.raises(ValueError, match="noise"):
            NoiseSpec(**bad)


@pytest.mark.parametrize("kind", ["white", "smooth", "offset"])
def test_noise_touches_only_arm_joints_and_is_reproducible(kind):
    spec = NoiseSpec(kind, 0.02)
    x = draws(spec, 200)
    assert np.array_equal(x, draws(spec, 200))
    assert not np.array_equal(x, draws(spec, 200, seed=8))
    assert np.all(x[:, [6, 13]] == 0.0)  # grippers untouched
    assert np.all(x[:, ARM_ENTRIES] != 0.0)


def test_noise_kinds_have_their_statistics():
    white = draws(NoiseSpec("white", 0.02), 4000)[:, ARM_ENTRIES]
    smooth = draws(NoiseSpec("smooth", 0.02, tau=0.5), 20000)[:, ARM_ENTRIES]
    offset = draws(NoiseSpec("offset", 0.02), 50)[:, ARM_ENTRIES]
    assert white.std() == pytest.approx(0.02, rel=0.05)
    assert smooth.std() == pytest.approx(0.02, rel=0.15)
    lag1 = np.mean([np.corrcoef(smooth[:-1, j], smooth[1:, j])[0, 1] for j in range(12)])
    assert lag1 == pytest.approx(np.exp(-DT / 0.5), abs=0.02)  # time constant tau
    assert abs(np.corrcoef(white[:-1, 0], white[1:, 0])[0, 1]) < 0.05
    assert np.all(offset == offset[0])  # one draw per episode


@pytest.mark.parametrize("kind", ["white", "smooth"])
def test_no_expert_raises_under_heavy_noise(task_name, kind):
    """Under noise far rougher than a learner's (0.05 rad) an expert may fail or give up with
    a reason, but never crash."""
    env = rmbench.make(task_name, render=False)
    result = run_episode(env, make_expert(env), 100000, noise=NoiseSpec(kind, 0.05))
    assert not result.reason.startswith("expert error"), result.reason


# (task, the carried piece) for every kind of object an expert carries
CARRIED = [("put_back_block", lambda t: t.cube), ("swap_T", lambda t: t.blocks[0]),
           ("battery_try", lambda t: t.batteries[0]), ("cover_blocks", lambda t: t.covers[0]),
           ("observe_and_pickup", lambda t: t.objects[t.target])]


@pytest.mark.parametrize("task_name, piece_of", CARRIED, ids=[c[0] for c in CARRIED])
def test_a_held_piece_stays_in_the_gripper_under_jitter(task_name, piece_of):
    """Once the expert has lifted a piece, 3 s of white noise of 0.02 rad on the arm joints
    around the held pose leave it in the fingers."""
    env = rmbench.make(task_name, render=False)
    task, sim = env.unwrapped.task, env.unwrapped.sim
    expert = make_expert(env)
    obs, info = env.reset(seed=100001)
    expert.reset(info["instruction"], info)
    piece = piece_of(task)
    rest_z = piece.pos(task.data)[2]
    for _ in range(400):
        action = expert.act(obs)
        obs, *_ = env.step(action)
        if piece.pos(task.data)[2] > rest_z + 0.03:  # off the table, short of any success
            break
    else:
        pytest.fail("the expert never lifted the piece")
    site = min(sim.grasp_sites, key=lambda s: np.linalg.norm(  # the hand holding it
        task.data.site_xpos[s] - piece.pos(task.data)))
    offset = piece.pos(task.data) - task.data.site_xpos[site]
    noise = NoiseSpec("white", 0.02).process(0, DT)
    for _ in range(60):  # 3 s
        obs, _, terminated, truncated, info = env.step(noise.perturb(action))
        assert not (terminated or truncated), info.get("failure_reason")
    moved = np.linalg.norm(piece.pos(task.data) - task.data.site_xpos[site] - offset)
    assert piece.pos(task.data)[2] > rest_z + 0.02, "the piece fell"
    assert moved < 0.015


def test_dart_records_the_experts_action_and_executes_it_plus_noise():
    noise = NoiseSpec("white", 0.02)
    env = rmbench.make("put_back_block", render=False)
    traj = record_episode(env, make_expert(env), 3, noise=noise)
    assert len(traj) > 50
    process = noise.process(3, DT)
    expected = [np.asarray(a + process.next(), np.float32).astype(np.float64)
                for a in traj.action]
    assert np.array_equal(np.array(traj.executed), np.array(expected))
    assert not np.array_equal(np.array(traj.executed), np.array(traj.action))
    # without noise, what is executed is what is recorded
    clean = record_episode(env, make_expert(env), 3)
    assert np.array_equal(np.array(clean.executed), np.array(clean.action))


def test_collect_with_noise_says_so_in_the_dataset(tmp_path):
    from rmbench.data import collect

    clean = CollectConfig("observe_and_pickup", tmp_path / "a", episodes=1)
    assert "action_noise" not in clean.identity()  # clean datasets keep their identity
    cfg = CollectConfig("observe_and_pickup", tmp_path / "ds", episodes=1, cameras=("head",),
                        width=32, height=24, progress=False,
                        noise=NoiseSpec("smooth", 0.01, 0.5))
    collect(cfg)
    meta = json.loads((tmp_path / "ds" / "meta" / "rmbench.json").read_text())
    assert json.dumps({"kind": "smooth", "sigma": 0.01, "tau": 0.5}) in json.dumps(meta)


def test_an_expert_gives_up_with_a_reason_when_a_piece_is_out_of_reach():
    env = rmbench.make("put_back_block", render=False)
    task = env.unwrapped.task
    expert = make_expert(env)
    obs, info = env.reset(seed=100000)
    expert.reset(info["instruction"], info)
    task.cube.place(task.data, (0.47, 0.27))  # the table's far corner: beyond either arm
    for _ in range(100):
        obs, *_ = env.step(expert.act(obs))
        if expert.gave_up:
            break
    assert "cannot reach" in expert.gave_up


def test_a_push_that_does_not_register_is_made_again():
    """The expert feels for the click: a first push that does not click (the button's click
    point moved out of reach for it) is made again, and the episode still succeeds."""
    env = rmbench.make("press_button", render=False)
    task = env.unwrapped.task
    expert = make_expert(env)
    obs, info = env.reset(seed=100000)
    expert.reset(info["instruction"], info)
    click = task.left.press_depth
    task.left.press_depth = 1.0  # no push can click
    bottomed = False
    for _ in range(task.step_limit):
        obs, _, terminated, truncated, info = env.step(expert.act(obs))
        depth = task.left.depth(task.data)
        bottomed = bottomed or depth > click
        if bottomed and depth < 0.001 and task.left.press_depth != click:
            task.left.press_depth = click  # the first push is over, unregistered
            assert task.left.count == 0
        if terminated or truncated:
            break
    assert task.left.press_depth == click and info["is_success"], info.get("failure_reason")


def test_robustness_command_reports_success_per_sigma(capsys):
    from rmbench.cli.main import main

    assert main(["robustness", "observe_and_pickup", "--kind", "offset", "--noise", "0,0.02",
                 "--episodes", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert [r["sigma"] for r in out["results"]] == [0.0, 0.02]
    assert all(r["episodes"] == 2 and 0.0 <= r["success_rate"] <= 1.0 for r in out["results"])
    assert out["results"][0]["success_rate"] == 1.0  # the clean expert


def test_robustness_command_refuses_bad_noise_in_one_line(capsys):
    from rmbench.cli.main import main

    assert main(["robustness", "put_back_block", "--kind", "smooth", "--tau", "0",
                 "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "tau" in err
