"""The policy server and the ``remote:`` client carrying batches: a batched policy answers
every slot of a step in one request, as it would locally; a policy without the batched form
gets a client without it; the batch messages are bounded as single ones are."""

import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from rmbench.envs.registration import make
from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.episode import batches
from rmbench.eval.records import read_records
from rmbench.policies.base import BasePolicy
from rmbench.policies.registry import POLICIES, make_policy, register_policy
from rmbench.serve.client import BatchedRemotePolicy, RemotePolicy, open_remote
from rmbench.serve.contract import (
    ENVELOPE_BYTES,
    MAX_BATCH_BYTES,
    MAX_SLOTS,
    Contract,
)
from rmbench.serve.server import PolicyServer
from rmbench.serve.wire import pack, unpack
from tests.conftest import DATA_TASK as TASK

BAD = -99.0  # an agent_pos[0] the test policy answers with NaN
ASKED: list[int] = []  # the length of every act_batch call, wherever the policy runs


class Counter(BasePolicy):
    """One episode: holds still at agent_pos, in chunks of a seed-dependent length; NaN for a
    marked observation and at a seed-dependent step of every third seed. Told to ``count``,
    it adds its seed and step count (so an answer names the episode and step it answers)."""

    def reset(self, instruction, task_info):
        self.seed, self.t = task_info.get("seed", 0), 0
        self.count = instruction == "count"

    def act(self, observation):
        self.t += 1
        action = np.array(observation["agent_pos"], np.float64)
        if action[0] == BAD or (self.seed % 3 == 0 and self.t == 3 + self.seed % 4):
            return np.full(14, np.nan)
        if self.count:
            action[0] += self.seed * 1e-3
            action[1] += self.t * 1e-4
        return np.repeat(action[None], 4 + self.seed % 3, 0)

    def status(self):
        return {"calls": self.t // 3, "seed": self.seed}


class CounterBatch(BasePolicy):
    """Counter with the batched form: one Counter per slot."""

    def __init__(self):
        self.reset("", {})

    def reset(self, instruction, task_info):
        self.slots, self.one = {}, Counter()  # rebinds all episode state, as a server needs
        self.one.reset(instruction, task_info)

    def act(self, observation):
        return self.one.act(observation)

    def reset_batch(self, slot, instruction, task_info, env=None):
        self.slots[slot] = Counter()
        self.slots[slot].reset(instruction, task_info)

    def act_batch(self, observations):
        ASKED.append(len(observations))
        return [None if o is None else self.slots[i].act(o) for i, o in enumerate(observations)]

    def status_batch(self, slot):
        return self.slots[slot].status()


if "counter_batch_test" not in POLICIES:
    register_policy("counter_batch_test", "test policy with the batched form", cameras=())(
        lambda arg, env: CounterBatch())


@pytest.fixture
def batch_server():
    s = PolicyServer("counter_batch_test", TASK, port=0).start()
    yield s
    s.stop()


def url(server) -> str:
    return f"ws://127.0.0.1:{server.port}"


def test_a_batch_is_answered_per_slot_as_the_policy_answers_locally(batch_server):
    rng = np.random.default_rng(0)
    remote = open_remote(url(batch_server))
    local = CounterBatch()
    try:
        assert type(remote) is BatchedRemotePolicy and batches(remote)
        assert remote.served_slots == MAX_SLOTS == remote.metadata["batch"]
        seeds = [10, 11, 12, 13, 14]
        for slot, seed in enumerate(seeds):
            for policy in (remote, local):
                policy.reset_batch(slot, "count", {"seed": seed})
        for step in range(6):
            observations = [None if (slot + step) % 3 == 0 else {"agent_pos": rng.normal(size=14)}
                            for slot in range(len(seeds))]
            if step == 4:
                observations[1] = {"agent_pos": np.r_[BAD, np.zeros(13)]}
            if step == 5:  # a slot starts over mid-run; the others keep their episodes
                for policy in (remote, local):
                    policy.reset_batch(2, "count", {"seed": 20})
            got, want = remote.act_batch(observations), local.act_batch(observations)
            for slot, (g, w) in enumerate(zip(got, want, strict=True)):
                if observations[slot] is None:
                    assert g is None and w is None
                elif not np.isfinite(w).all():  # a bad answer fails its own slot only
                    assert isinstance(g, RuntimeError) and "NaN" in str(g), g
                else:
                    np.testing.assert_array_equal(g, w)
                    assert remote.status_batch(slot) == local.status_batch(slot)
        # the single-episode messages still work on the same connection
        remote.reset("count", {"seed": 3})
        np.testing.assert_array_equal(remote.act({"agent_pos": np.zeros(14)})[:, 1], 1e-4)
        with pytest.raises(ValueError, match="slot 64"):
            remote.reset_batch(MAX_SLOTS, "", {"seed": 0})
    finally:
        remote.close()
    cut = open_remote(url(batch_server) + "?steps=2")
    try:
        cut.reset_batch(0, "", {"seed": 2})  # chunks of 6
        (chunk,) = cut.act_batch([{"agent_pos": np.zeros(14)}])
        assert chunk.shape == (2, 14)
    finally:
        cut.close()


def test_connections_keep_their_own_slots(batch_server):
    a, b = open_remote(url(batch_server)), open_remote(url(batch_server))
    try:
        a.reset_batch(0, "count", {"seed": 1})
        b.reset_batch(0, "count", {"seed": 2})
        obs = [{"agent_pos": np.zeros(14)}]
        assert a.act_batch(obs)[0][0, 0] == pytest.approx(1e-3)
        assert b.act_batch(obs)[0][0, 0] == pytest.approx(2e-3)
        assert a.act_batch(obs)[0][0, 1] == pytest.approx(2e-4)  # a's second step
    finally:
        a.close()
        b.close()


def test_a_lost_connection_fails_the_slots_it_held_and_a_reset_reconnects(batch_server):
    remote = open_remote(url(batch_server))
    obs = {"agent_pos": np.zeros(14)}
    try:
        for slot in (0, 1):
            remote.reset_batch(slot, "count", {"seed": slot + 1})
        remote.act_batch([obs, obs])
        remote._disconnect()  # as a timeout or a broken connection leaves it
        lost = remote.act_batch([obs, None])
        assert isinstance(lost[0], RuntimeError) and "next reset reconnects" in str(lost[0])
        assert lost[1] is None
        remote.reset_batch(0, "count", {"seed": 7})  # a new connection, slot 0's new episode
        fresh, old = remote.act_batch([obs, obs])
        np.testing.assert_allclose(fresh[0, :2], [7e-3, 1e-4])
        assert isinstance(old, RuntimeError)  # slot 1's episode went with the old connection
    finally:
        remote.close()


def test_a_server_without_the_batched_form_gets_a_client_without_it(tmp_path):
    from tests.test_serve import OpenpiStandIn

    server, openpi = PolicyServer("random", TASK, port=0).start(), OpenpiStandIn()
    env = make(TASK, render=False)
    try:
        plain = open_remote(url(server))
        assert type(plain) is RemotePolicy and not batches(plain)
        assert plain.metadata["batch"] == 0 and plain.served_slots == 0
        plain.close()
        pi = open_remote(f"ws://127.0.0.1:{openpi.port}")
        assert type(pi) is RemotePolicy and not batches(pi)
        pi.close()
        made = make_policy(f"remote:{url(server)}", env)
        assert not batches(made)
        made.close()
        with connect(url(server)) as ws:  # nor does the server take batch messages
            ws.recv(timeout=10)
            for msg in ({"reset": True, "slot": 0}, {"batch": [None]}):
                ws.send(pack(msg))
                assert "one episode at a time" in unpack(ws.recv(timeout=10))["error"]
    finally:
        env.close()
        server.stop()
        openpi.stop()


def test_bad_batch_messages_get_an_error_and_the_connection_stays_usable(batch_server):
    obs = {"agent_pos": np.zeros(14)}

    def exchange(ws, msg):
        ws.send(pack(msg))
        return unpack(ws.recv(timeout=10))

    with connect(url(batch_server), max_size=None) as ws:
        meta = unpack(ws.recv(timeout=10))
        assert meta["batch"] == MAX_SLOTS
        assert meta["max_message_bytes"] == batch_server.contract.max_message_bytes
        assert exchange(ws, {"reset": True, "slot": 1, "task_info": {"seed": 5}}) == {"ok": True}
        bad = [
            ({"reset": True, "slot": MAX_SLOTS}, "slot must be an integer in"),
            ({"reset": True, "slot": -1}, "slot must be an integer in"),
            ({"reset": True, "slot": True}, "slot must be an integer in"),
            ({"reset": True, "slot": "0"}, "slot must be an integer in"),
            ({"reset": True, "slot": 0, "task_info": {"seed": "x"}}, "seed must be int"),
            ({"batch": [None] * (MAX_SLOTS + 1)}, f"1 to {MAX_SLOTS} entries"),
            ({"batch": []}, f"1 to {MAX_SLOTS} entries"),
            ({"batch": obs}, "must be a list"),
            ({"batch": [obs, obs]}, "send a reset of slot 0"),  # slot 0 was never reset
            ({"batch": [None, obs, obs]}, "send a reset of slot 2"),
            ({"batch": [None]}, "slot 1 has an episode"),  # too short for slot 1
            ({"batch": [None, {"agent_pos": np.zeros(15)}]}, "batch entry 1: agent_pos"),
            ({"batch": [None, 3]}, "batch entry 1: an observation must be a map"),
            ({"batch": [None, {**obs, "x": 1}]}, "batch entry 1: unexpected entries"),
            ({"batch": [None, obs], "extra": 1}, "beside 'batch'"),
            ({"agent_pos": np.zeros(14)}, "send a reset before"),  # no single episode yet
        ]
        for msg, why in bad:
            reply = exchange(ws, msg)
            assert set(reply) == {"error"} and why in reply["error"], (msg, reply)
            # the connection still answers, and slot 1's episode goes on
            answer = exchange(ws, {"batch": [None, obs]})["actions"]
            assert answer[0] is None and answer[1].shape == (6, 14)  # seed 5: chunks of 6
        # a single reset ends the slots' episodes, which share the policy's state
        assert exchange(ws, {"reset": True, "task_info": {"seed": 4}}) == {"ok": True}
        assert exchange(ws, {"agent_pos": np.zeros(14)})["actions"].shape == (5, 14)
        assert "send a reset of slot 1" in exchange(ws, {"batch": [None, obs]})["error"]
        # a message over the cap closes the connection, as for single messages
        cap = batch_server.contract.max_message_bytes
        ws.send(b"\xc6" + cap.to_bytes(4, "big") + b"\0" * cap)
        with pytest.raises(ConnectionClosed) as err:
            ws.recv(timeout=10)
        assert err.value.rcvd.code == 1009


def test_a_full_batch_fits_the_cap_and_large_frames_get_fewer_slots():
    cameras, frame_max = ("head", "left_wrist"), (48, 64)
    single = Contract(TASK, "pixels_agent_pos", cameras, None, frame_max)
    contract = Contract(TASK, "pixels_agent_pos", cameras, None, frame_max, batch=MAX_SLOTS)
    largest = {"agent_pos": np.zeros(14),
               "pixels": {cam: np.zeros((*frame_max, 3), np.uint8) for cam in cameras}}
    message = pack({"batch": [largest] * MAX_SLOTS})
    assert len(message) <= contract.max_message_bytes
    # the cap grows with the slots: one observation's bound each, and the envelope once
    assert contract.max_message_bytes > MAX_SLOTS * single.observation_bytes
    assert contract.max_message_bytes - len(message) <= ENVELOPE_BYTES + MAX_SLOTS * 2**11
    assert len(contract.check_batch(unpack(message, contract.limits)["batch"])) == MAX_SLOTS
    # huge frames: fewer slots, so that a batch's cap stays within MAX_BATCH_BYTES
    huge = Contract(TASK, "pixels_agent_pos", ("head", "left_wrist", "right_wrist"), None,
                    (2160, 3840))
    slots = huge.slots_for()
    assert 1 <= slots < MAX_SLOTS
    from dataclasses import replace
    assert replace(huge, batch=slots).max_message_bytes <= MAX_BATCH_BYTES
    assert PolicyServer("counter_batch_test", TASK, port=0, max_slots=4).contract.batch == 4
    with pytest.raises(ValueError, match="max_slots"):
        PolicyServer("counter_batch_test", TASK, port=0, max_slots=MAX_SLOTS + 1)


def strip(records):
    return [{k: v for k, v in r.items() if k not in ("wall_s", "message")} for r in records]


def test_batched_remote_evaluation_equals_the_local_policy(batch_server, tmp_path):
    common = {"episodes": 6, "video": "none", "progress": False, "seed_cache": tmp_path / "s",
              "batch": 4}
    ASKED.clear()
    local = evaluate(EvalConfig((TASK,), "counter_batch_test", tmp_path / "local", **common))
    assert set(ASKED) == {4}
    ASKED.clear()
    remote = evaluate(EvalConfig((TASK,), f"remote:{url(batch_server)}", tmp_path / "remote",
                                 **common))
    assert set(ASKED) == {4}  # the server's policy was asked for four slots at a time
    assert remote["tasks"] == local["tasks"]
    here = read_records(tmp_path / "local" / TASK / "episodes.jsonl")
    there = read_records(tmp_path / "remote" / TASK / "episodes.jsonl")
    assert strip(there) == strip(here)
    assert {r["reason"] for r in here} >= {"policy_error"}  # a NaN ended its own episode
    assert len({r["reason"] for r in here}) >= 2
    assert any(e[1] == "policy" for e in there[0]["events"])  # the status came over the wire
    for a, b in zip(here, there, strict=True):  # the server names the policy's error
        assert b["message"].endswith(a["message"]), (a["message"], b["message"])


def test_a_batch_beyond_the_servers_slots_stops_before_any_episode(tmp_path):
    """--batch above the slots a server announced is a one-line error before the first
    episode (not a folder of failed ones); the same folder then takes the right --batch.
    One connection at a time is enough for a batched evaluation: the worker asks the
    server what its policy reads once, not once per env."""
    server = PolicyServer("counter_batch_test", TASK, port=0, max_slots=2,
                          max_connections=1).start()
    common = {"episodes": 2, "video": "none", "progress": False, "seed_cache": tmp_path / "s"}
    try:
        with pytest.raises(ValueError, match="plays at most 2 episodes at once; evaluate it "
                                             "with --batch 2 or fewer"):
            evaluate(EvalConfig((TASK,), f"remote:{url(server)}", tmp_path / "e", batch=4,
                                **common))
        assert not read_records(tmp_path / "e" / TASK / "episodes.jsonl")
        summary = evaluate(EvalConfig((TASK,), f"remote:{url(server)}", tmp_path / "e", batch=2,
                                      **common))
    finally:
        server.stop()
    assert summary["tasks"][TASK]["episodes"] == 2
