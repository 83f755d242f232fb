"""rmbench inside LeRobot: the env LeRobot evaluates (no LeRobot needed), the lerobot: spec's
observation, and (slow, its own environment) scripts/lerobot_check.sh end to end."""

import json
import os
import subprocess
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from rmbench.eval.seeds import verified_seeds

ROOT = Path(__file__).resolve().parents[1]


def test_the_lerobot_env_runs_rmbench_verified_seeds_with_the_instruction(tmp_path):
    from rmbench.lerobot.env import NAMESPACE

    env = gym.make(f"{NAMESPACE}/put_back_block", obs_type="environment_state_agent_pos",
                   seed_cache=str(tmp_path))
    try:
        # found by hasattr on what gym.make returns, as LeRobot looks for it
        assert hasattr(env, "task_description") and env._max_episode_steps == 500
        obs, info = env.reset(seed=1)
        assert info["rmbench_seed"] == verified_seeds("put_back_block", 0, 2, tmp_path)[1]
        assert env.task_description == info["instruction"] and env.task == "put_back_block"
        plain = gym.make("rmbench/PutBackBlock-v1", obs_type="environment_state_agent_pos")
        same, _ = plain.reset(seed=info["rmbench_seed"])
        np.testing.assert_array_equal(obs["environment_state"], same["environment_state"])
        plain.close()
        _, _, _, _, info = env.step(obs["agent_pos"])
        assert info["is_success"] is False or info["is_success"] == np.False_
        with pytest.raises(ValueError, match="index into rmbench's verified seeds"):
            env.reset(seed=-1)
    finally:
        env.close()


def test_a_lerobot_checkpoint_names_the_observation_it_reads(tmp_path):
    from rmbench.lerobot.policy import checkpoint_cameras, obs_type

    def ckpt(*keys):
        (tmp_path / "config.json").write_text(json.dumps(
            {"type": "act", "input_features": {k: {"type": "X", "shape": [1]} for k in keys}}))
        return str(tmp_path)

    assert obs_type(ckpt("observation.state", "observation.images.head")) == "pixels_agent_pos"
    assert obs_type(ckpt("observation.state", "observation.environment_state")) == \
        "environment_state_agent_pos"
    assert obs_type(ckpt("observation.images.head", "observation.environment_state")) == \
        "pixels_environment_state_agent_pos"
    with pytest.raises(ValueError, match="no config.json"):
        obs_type(str(tmp_path / "missing"))
    # and the cameras whose images it reads: its env renders those, or nothing
    assert checkpoint_cameras(ckpt("observation.images.head", "observation.images.left_wrist",
                                   "observation.state")) == ("head", "left_wrist")
    assert checkpoint_cameras(ckpt("observation.state", "observation.environment_state")) == ()


def test_a_spec_that_is_no_lerobot_checkpoint_is_refused_before_anything_runs(tmp_path):
    import importlib.util

    from rmbench.policies.registry import check_policy

    config = tmp_path / "config.json"
    for text, said in (("{bad", r"config\.json: unreadable"),
                       ("[1]", r"config\.json: not a LeRobot policy config"),
                       (json.dumps({"format": 1, "policy": "mem0", "config": {}}),
                        r"not a LeRobot policy config .* mem0:, dp: or act:")):
        config.write_text(text)
        with pytest.raises(ValueError, match=said):
            check_policy(f"lerobot:{tmp_path}")
    config.write_text(json.dumps({"type": "act", "input_features": {}}))
    if importlib.util.find_spec("lerobot") is None:
        with pytest.raises(RuntimeError, match="LeRobot is not installed here"):
            check_policy(f"lerobot:{tmp_path}")


def test_a_served_copy_of_a_lerobot_policy_keeps_its_own_temporal_ensemble():
    """LeRobot's ACT clears its temporal ensembler in place at reset: copies for the server's
    connections must not share it."""
    import types

    from rmbench.lerobot.policy import LeRobotPolicy

    policy = object.__new__(LeRobotPolicy)
    policy.policy = types.SimpleNamespace(temporal_ensembler=types.SimpleNamespace(sums=[1]))
    other = policy.fork()
    assert other.policy is not policy.policy
    assert other.policy.temporal_ensembler is not policy.policy.temporal_ensembler
    assert other.policy.temporal_ensembler.sums == [1]


@pytest.mark.slow
def test_lerobot_trains_and_evaluates_on_rmbench(tmp_path):
    """Builds LeRobot's environment from the package index (minutes the first time)."""
    env = {**os.environ, "RMBENCH_LEROBOT_WORK": str(tmp_path / "work")}
    done = subprocess.run(["bash", str(ROOT / "scripts" / "lerobot_check.sh")], env=env,
                          capture_output=True, text=True, timeout=3600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "ran different episodes" not in done.stdout
    assert "lerobot-eval: success" in done.stdout
