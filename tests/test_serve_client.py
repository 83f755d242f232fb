"""The ``remote:`` client: exact or loud after a timeout, and an env built from what the
server says its policy reads."""

import time

import numpy as np
import pytest

from rmbench.envs.registration import make
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.episode import run_policy_episode
from rmbench.eval.records import read_records
from rmbench.policies.base import BasePolicy, PolicyUnavailable
from rmbench.policies.registry import POLICIES, env_options, make_policy, register_policy
from rmbench.serve.client import RemotePolicy
from rmbench.serve.server import PolicyServer
from rmbench.tasks import get_task
from tests.conftest import DATA_TASK as TASK

SLOW = 9.0  # an agent_pos[0] the echo policy answers late
DELAY = 2.0  # s; a prompt reply has half of it (a loaded machine answers in time)


class SlowEcho(BasePolicy):
    """Answers the observation's agent_pos (so a reply names the observation it answers),
    late for one marked observation or at the second step of seed 7's episode."""

    def reset(self, instruction, task_info):
        self.t, self.seed = 0, task_info.get("seed")

    def act(self, observation):
        pos = np.array(observation["agent_pos"], np.float64)
        if pos[0] == SLOW or (self.seed == 7 and self.t == 1):
            time.sleep(DELAY)
        self.t += 1
        return pos


class StateReader(BasePolicy):
    """Reads the environment state: holds still, after checking it got the task's state."""

    def __init__(self, env):
        self.dim = len(type(env.unwrapped.task).state_names)

    def act(self, observation):
        assert observation["environment_state"].shape == (self.dim,)
        return np.array(observation["agent_pos"], np.float64)


if "slow_echo_test" not in POLICIES:
    register_policy("slow_echo_test", "test policy: echoes agent_pos, sometimes late",
                    cameras=())(lambda arg, env: SlowEcho())
    register_policy("state_reader_test", "test policy reading the environment state",
                    obs_type=lambda arg: "environment_state_agent_pos")(
        lambda arg, env: StateReader(env))


@pytest.fixture
def slow_server():
    s = PolicyServer("slow_echo_test", TASK, port=0).start()
    yield s
    s.stop()


def test_a_timeout_never_yields_the_late_action(slow_server):
    policy = RemotePolicy(f"ws://127.0.0.1:{slow_server.port}", timeout=DELAY / 2)
    try:
        policy.reset("", {"seed": 0})
        first = np.arange(14.0)
        np.testing.assert_array_equal(policy.act({"agent_pos": first}), first[None])
        with pytest.raises(RuntimeError, match="no reply within"):
            policy.act({"agent_pos": np.r_[SLOW, np.zeros(13)]})
        time.sleep(DELAY * 1.5)  # the late reply has been sent by now
        with pytest.raises(RuntimeError, match="next reset reconnects"):
            policy.act({"agent_pos": first})
        policy.reset("", {"seed": 1})
        for k in range(3):
            obs = np.full(14, float(k + 1))
            np.testing.assert_array_equal(policy.act({"agent_pos": obs}), obs[None])
    finally:
        policy.close()


def test_a_timeout_ends_that_episode_and_the_next_is_exact(slow_server):
    env = make(TASK, render=False)
    policy = RemotePolicy(f"ws://127.0.0.1:{slow_server.port}", timeout=DELAY / 2)
    try:
        late = run_policy_episode(env, policy, seed=7)
        assert late["reason"] == "policy_error" and "no reply within" in late["message"]
        time.sleep(DELAY * 1.5)
        seen = []
        record = run_policy_episode(env, RecordingProxy(policy, seen), seed=8)
        assert record["reason"] != "policy_error", record
        for obs, action in seen:  # every action answers the observation it was asked for
            np.testing.assert_array_equal(action, obs[None])
    finally:
        policy.close()
        env.close()


class RecordingProxy(BasePolicy):
    def __init__(self, policy, seen):
        self.policy, self.seen = policy, seen

    def reset(self, instruction, task_info):
        self.policy.reset(instruction, task_info)

    def act(self, observation):
        action = self.policy.act(observation)
        self.seen.append((np.array(observation["agent_pos"]), action))
        return action


def test_remote_env_is_built_from_the_greeting(tmp_path):
    servers = {spec: PolicyServer(spec, TASK, port=0).start()
               for spec in ("random", "state_reader_test")}
    try:
        url = {spec: f"remote:ws://127.0.0.1:{s.port}" for spec, s in servers.items()}
        assert env_options(url["random"]) == {"obs_type": "pixels_agent_pos", "render": False}
        assert env_options(url["state_reader_test"]) == {
            "obs_type": "environment_state_agent_pos"}
        summary = evaluate(EvalConfig((TASK,), url["state_reader_test"], tmp_path / "state",
                                      episodes=1, video="none", progress=False,
                                      seed_cache=tmp_path / "s"))
        (record,) = read_records(tmp_path / "state" / TASK / "episodes.jsonl")
        assert record["reason"] != "policy_error", record
        assert summary["tasks"][TASK]["episodes"] == 1
        # an env without the state the server reads is refused when the policy is built
        env = make(TASK, render=False)
        with pytest.raises(ValueError, match="reads environment_state"):
            make_policy(url["state_reader_test"], env)
        env.close()
        greeting = RemotePolicy(url["state_reader_test"][len("remote:"):])
        assert greeting.metadata["state_dim"] == len(get_task(TASK).state_names)
        greeting.close()
    finally:
        for s in servers.values():
            s.stop()


def test_a_served_policy_s_frames_render_at_its_resolution():
    register_policy("small_frames_test", "test policy reading 128x96 head frames",
                    cameras=("head",), frame_size=lambda arg: (128, 96))(
        lambda arg, env: BasePolicy())
    try:
        assert env_options("small_frames_test") == {"width": 128, "height": 96,
                                                    "cameras": ("head",)}
        server = PolicyServer("small_frames_test", TASK, port=0).start()
        try:
            url = f"remote:ws://127.0.0.1:{server.port}"
            assert env_options(url) == {"obs_type": "pixels_agent_pos", "cameras": ("head",),
                                        "width": 128, "height": 96}
        finally:
            server.stop()
        with pytest.raises(ValueError, match=r"reads 128x96 frames, larger than frame_max"):
            PolicyServer("small_frames_test", TASK, port=0, frame_max=(64, 64))
    finally:
        POLICIES.pop("small_frames_test", None)


@pytest.mark.parametrize("greeting, said", [
    (b"\x91" * 40 + b"\x90", "does not read"),  # nested 40 deep: past the client's limits
    ({"server": "rmbench", "protocol": 2, "obs_type": "pixels_agent_pos",
      "cameras": ["head"], "frame_size": [0, 0]}, "frame_size is not"),
])
def test_a_greeting_the_client_cannot_read_is_one_line(greeting, said):
    import threading

    from websockets.sync.server import serve

    from rmbench.serve.wire import pack

    def handle(ws):
        ws.send(greeting if isinstance(greeting, bytes) else pack(greeting))
        for _ in ws:
            pass

    server = serve(handle, "127.0.0.1", 0, compression=None)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with pytest.raises((RuntimeError, ValueError, PolicyUnavailable), match=said):
            env_options(f"remote:ws://127.0.0.1:{server.socket.getsockname()[1]}")
    finally:
        server.shutdown()
