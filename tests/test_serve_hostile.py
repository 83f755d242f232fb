"""The policy server against a hostile client: every message it controls is bounded before
any work, refusals are one-line errors to that client, and the others are served throughout."""

import threading
import time
from contextlib import ExitStack

import msgpack
import numpy as np
import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

from rmbench.policies.base import BasePolicy
from rmbench.policies.observation import image_tensors
from rmbench.policies.registry import POLICIES, register_policy
from rmbench.serve.contract import ENVELOPE_BYTES, Contract
from rmbench.serve.server import PolicyServer
from rmbench.serve.wire import Limits, WireError, pack, scan, unpack
from tests.conftest import DATA_TASK as TASK

CAMERAS = ("head", "left_wrist")
FRAME_MAX = (48, 64)


def head_mean(observation) -> float:
    """The head frame's mean brightness as the learned policies read frames (resized)."""
    return float(image_tensors(observation, CAMERAS, (24, 32))[0].double().mean()) / 255


class CameraMean(BasePolicy):
    """Reads two cameras: answers agent_pos with the head frame's mean brightness added to
    its first entry, so a reply shows which observation it answers."""

    def act(self, observation):
        action = np.array(observation["agent_pos"], np.float64)
        action[0] += head_mean(observation)
        return action


if "camera_mean_test" not in POLICIES:
    register_policy("camera_mean_test", "test policy reading two cameras", cameras=CAMERAS)(
        lambda arg, env: CameraMean())


def good_observation(rng):
    return {"agent_pos": rng.normal(size=14),
            "pixels": {cam: rng.integers(0, 256, (*FRAME_MAX, 3), dtype=np.uint8)
                       for cam in CAMERAS}}


def expected(obs):
    action = obs["agent_pos"].copy()
    action[0] += head_mean(obs)
    return action


def raw_array(data: bytes, dtype, shape) -> dict:
    return {b"__ndarray__": True, b"data": data, b"dtype": dtype, b"shape": shape}


def hostile_messages(rng, cap: int):
    """An endless cycle of malformed or hostile messages, each built fresh."""
    good = good_observation(rng)
    frame = good["pixels"]["head"]
    valid = pack(good)

    def obs(**change):
        return pack({**good, **change})

    def pixels(**change):
        return obs(pixels={**good["pixels"], **change})

    makers = [
        # shapes the policy does not read, some tiny messages that once became huge arrays
        lambda: pixels(head=np.zeros((1, 1, 2000), np.uint8)),
        lambda: pixels(head=np.zeros((FRAME_MAX[0] + 1, FRAME_MAX[1], 3), np.uint8)),
        lambda: pixels(head=np.zeros((*FRAME_MAX, 4), np.uint8)),
        lambda: pixels(head=np.zeros((0, 5, 3), np.uint8)),
        lambda: pixels(head=frame[None]),
        lambda: obs(agent_pos=np.zeros(15)),
        lambda: obs(agent_pos=np.zeros((14, 1))),
        lambda: obs(agent_pos=np.full(14, np.nan)),
        # wrong dtypes
        lambda: pixels(head=frame.astype(np.float64)),
        lambda: pixels(head=frame.astype(np.int16)),
        lambda: obs(agent_pos=np.zeros(14, np.int64)),
        lambda: obs(agent_pos=np.zeros(14, np.complex128)),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 8, "|O", [1])}),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 8, "(1000000000,)f8", [1])}),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 8, "<U2", [1])}),
        lambda: pack({**good, "agent_pos": {b"__npgeneric__": True, b"data": b"\0",
                                            b"dtype": "<f8"}}),
        # huge claimed shapes, shapes that are not shapes
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 112, "<f8", [2**30, 2**30, 3])}),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 112, "<f8", [-1])}),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 112, "<f8", [1] * 40)}),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 112, "<f8", "14")}),
        lambda: pack({**good, "agent_pos": raw_array(b"\0" * 112, "<f8", [2**40])}),
        # deep or wide containers
        lambda: b"\x91" * 5000 + b"\xc0",
        lambda: b"\x81\xa1k" * 3000 + b"\xc0",
        lambda: b"\xdd\x00\x01\x00\x00" + b"\x80" * 65536,
        lambda: b"\xdc\xff\xff" + b"\x80" * 65535,
        lambda: b"\xdf\xff\xff\xff\xff" + b"\xc0" * 1000,
        lambda: pack({"agent_pos": good["agent_pos"], "pixels": {f"c{i}": 1 for i in range(500)}}),
        lambda: pack({"agent_pos": good["agent_pos"], "x" * 5000: 1}),
        # truncated msgpack, trailing bytes, extension types, the reserved byte, raw noise
        lambda: valid[:int(rng.integers(1, len(valid)))],
        lambda: valid + b"\x00",
        lambda: b"\xc6\xff\xff\xff\xff" + b"x" * 10,
        lambda: msgpack.packb(msgpack.ExtType(1, b"x" * 100)),
        lambda: b"\xc1",
        lambda: rng.integers(0, 256, int(rng.integers(1, 4096)), dtype=np.uint8).tobytes(),
        # text frames
        lambda: "hello",
        lambda: '{"agent_pos": [0, 0]}',
        # maps that are no observation
        lambda: pack([1, 2, 3]),
        lambda: pack(None),
        lambda: pack({}),
        lambda: pack({"agent_pos": good["agent_pos"]}),
        lambda: pack({**good, "environment_state": np.zeros(10)}),
        lambda: pixels(right_wrist=frame),
        lambda: obs(pixels={"head": frame}),
        lambda: obs(pixels=[frame, frame]),
        # resets with bogus task facts
        lambda: pack({"reset": True, "task_info": "x"}),
        lambda: pack({"reset": True, "task_info": {"seed": "1"}}),
        lambda: pack({"reset": True, "task_info": {"seed": -1}}),
        lambda: pack({"reset": True, "task_info": {"seed": 2**64 - 1}}),
        lambda: pack({"reset": True, "task_info": {"task": "swap_t"}}),
        lambda: pack({"reset": True, "task_info": {"subtasks": [1, 2]}}),
        lambda: pack({"reset": True, "task_info": {"hidden": {"a": 1}}}),
        lambda: pack({"reset": True, "instruction": b"\xff" * 10}),
        lambda: pack({"reset": True, "instruction": "x" * 10000}),
        lambda: pack({"reset": 1}),
        # over the message cap: the connection is closed (1009)
        lambda: b"\xc6" + (cap).to_bytes(4, "big") + b"\0" * cap,
    ]
    while True:
        for make in makers:
            yield make()


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096


class PeakRss:
    """The process's resident memory, sampled every few milliseconds in a thread."""

    def __init__(self):
        self.peak, self._stop = rss_bytes(), threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.wait(0.002):
            self.peak = max(self.peak, rss_bytes())

    def stop(self) -> int:
        self._stop.set()
        self._thread.join()
        return max(self.peak, rss_bytes())


@pytest.fixture
def camera_server():
    s = PolicyServer("camera_mean_test", TASK, port=0, frame_max=FRAME_MAX).start()
    yield s
    s.stop()


def test_a_thousand_hostile_messages_leave_the_server_serving(camera_server):
    rng = np.random.default_rng(0)
    url = f"ws://127.0.0.1:{camera_server.port}"
    cap = camera_server.contract.max_message_bytes
    stack = ExitStack()  # the connections, closed whatever happens
    good = stack.enter_context(connect(url, max_size=None))
    assert unpack(good.recv(timeout=10))["cameras"] == list(CAMERAS)

    def good_exchange():
        obs = good_observation(rng)
        good.send(pack(obs))
        np.testing.assert_array_equal(unpack(good.recv(timeout=5))["actions"], expected(obs)[None])

    good.send(pack({"reset": True, "instruction": "", "task_info": {"seed": 0}}))
    assert unpack(good.recv(timeout=5)) == {"ok": True}
    good_exchange()  # everything the answers need is built before memory is measured
    hostile = stack.enter_context(connect(url, max_size=None))
    hostile.recv(timeout=10)
    before, meter = rss_bytes(), PeakRss()
    slowest, closed = 0.0, 0
    messages = hostile_messages(rng, cap)
    try:
        for i in range(1000):
            message = next(messages)
            t0 = time.perf_counter()
            hostile.send(message)
            if len(message) > cap:  # refused by closing the connection (1009)
                with pytest.raises(ConnectionClosed) as err:
                    hostile.recv(timeout=1.0)
                assert err.value.rcvd.code == 1009, err.value
                closed += 1
                hostile = stack.enter_context(connect(url, max_size=None))
                hostile.recv(timeout=10)
            else:
                reply = unpack(hostile.recv(timeout=1.0))
                assert set(reply) == {"error"}, (i, message[:60], reply)
                assert "\n" not in reply["error"], reply
            slowest = max(slowest, time.perf_counter() - t0)
            if i % 20 == 0:
                good_exchange()
        good_exchange()
    finally:
        grown = meter.stop() - before
        stack.close()
    assert slowest < 1.0
    assert closed > 0
    assert grown < 200 * 2**20, f"server memory grew by {grown / 2**20:.0f} MB"


def test_a_legal_message_fits_the_cap():
    contract = Contract(TASK, "pixels_agent_pos", CAMERAS, None, FRAME_MAX)
    largest = pack({"agent_pos": np.zeros(14),
                    "pixels": {cam: np.zeros((*FRAME_MAX, 3), np.uint8) for cam in CAMERAS}})
    assert len(largest) <= contract.max_message_bytes
    assert contract.max_message_bytes - len(largest) <= ENVELOPE_BYTES
    contract.check_observation(unpack(largest, contract.limits))


def test_scan_bounds_a_message_by_its_limits():
    limits = Limits(bytes=2**20, items=100, depth=3, text=10)
    scan(pack({"a": [1, 2, {"b": b"x" * 1000}]}), limits)
    for bad, why in ((pack(list(range(200))), "more than 100 values"),
                     (pack([[[[1]]]]), "deeper than 3"),
                     (pack("x" * 11), "string of 11 bytes"),
                     (pack([1, 2])[:-1], "truncated"),
                     (pack(1) + b"\x01", "follow"),
                     (msgpack.packb(msgpack.ExtType(5, b"")), "not accepted")):
        with pytest.raises(WireError, match=why):
            scan(bad, limits)


def test_connections_beyond_the_cap_are_refused_and_others_served():
    s = PolicyServer("random", TASK, port=0, max_connections=1).start()
    try:
        url = f"ws://127.0.0.1:{s.port}"
        with connect(url) as first:
            first.recv(timeout=10)
            with connect(url) as second:
                assert "server busy" in unpack(second.recv(timeout=10))["error"]
            first.send(pack({"agent_pos": np.zeros(14)}))
            assert "send a reset before" in unpack(first.recv(timeout=10))["error"]
            first.send(pack({"reset": True, "task_info": {"seed": 3}}))
            assert unpack(first.recv(timeout=10)) == {"ok": True}
            first.send(pack({"agent_pos": np.zeros(14)}))
            assert unpack(first.recv(timeout=10))["actions"].shape == (1, 14)
        with connect(url) as third:  # the slot is free again
            assert unpack(third.recv(timeout=10))["server"] == "rmbench"
    finally:
        s.stop()


def test_an_idle_connection_is_closed():
    s = PolicyServer("random", TASK, port=0, idle_timeout=0.3).start()
    try:
        with connect(f"ws://127.0.0.1:{s.port}") as ws:
            ws.recv(timeout=10)
            with pytest.raises(ConnectionClosed) as err:
                ws.recv(timeout=5)
            assert "idle" in err.value.rcvd.reason
    finally:
        s.stop()


def test_origins_are_checked_when_given():
    from websockets.exceptions import InvalidStatus

    s = PolicyServer("random", TASK, port=0, origins=["https://ok.example"]).start()
    try:
        url = f"ws://127.0.0.1:{s.port}"
        with pytest.raises(InvalidStatus, match="403"):
            connect(url, origin="https://evil.example")
        for origin in ("https://ok.example", None):  # a listed page, a client that is no page
            with connect(url, origin=origin) as ws:
                assert unpack(ws.recv(timeout=10))["server"] == "rmbench"
    finally:
        s.stop()


def test_policies_reading_the_simulator_are_refused_with_a_reason():
    for spec in ("expert", "mem0:/nonexistent?ablation=no_anchor,gt_classifier"):
        with pytest.raises(ValueError, match="reads the simulator"):
            PolicyServer(spec, TASK)
    with pytest.raises(ValueError, match="itself a remote policy"):
        PolicyServer("remote:ws://127.0.0.1:1", TASK)


def test_connections_share_the_loaded_policy_not_its_episodes(dataset):
    """replay: one dataset loaded for all; each connection replays the seed it reset to."""
    from rmbench.data.reader import Dataset

    ds = Dataset(dataset)
    s = PolicyServer(f"replay:{dataset}", TASK, port=0).start()
    try:
        url = f"ws://127.0.0.1:{s.port}"
        with connect(url) as a, connect(url) as b:
            a.recv(timeout=10), b.recv(timeout=10)
            for ws, seed in ((a, 0), (b, 2)):
                ws.send(pack({"reset": True, "task_info": {"seed": seed}}))
                assert unpack(ws.recv(timeout=10)) == {"ok": True}
            for ws, episode in ((b, 2), (a, 0)):
                ws.send(pack({"agent_pos": np.zeros(14)}))
                np.testing.assert_array_equal(unpack(ws.recv(timeout=10))["actions"],
                                              ds.episode(episode, cameras=[]).action)
    finally:
        s.stop()


def test_serve_cli_refuses_bad_flags_in_one_line(capsys):
    from rmbench.cli.main import main

    assert main(["serve", "--policy", "expert", "--task", TASK]) == 2
    assert "reads the simulator" in capsys.readouterr().err
    assert main(["serve", "--policy", "random", "--task", TASK, "--max-connections", "0"]) == 2
    assert "max_connections must be >= 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["serve", "--policy", "random", "--task", TASK, "--frame-max", "640"])
    assert "expected WIDTHxHEIGHT" in capsys.readouterr().err


@pytest.mark.parametrize("timeout", [0, -1, float("nan"), float("inf"), 1e10])
def test_an_idle_timeout_the_socket_cannot_hold_is_refused(timeout):
    with pytest.raises(ValueError, match=r"idle_timeout in \(0, 1e\+06\] seconds"):
        PolicyServer("random", TASK, port=0, idle_timeout=timeout)
