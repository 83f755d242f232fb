"""The policy server: evaluation through it, malformed messages, the wire format."""

import numpy as np
import pytest
from websockets.sync.client import connect

from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.records import read_records
from rmbench.serve.server import PolicyServer
from rmbench.serve.wire import PROTOCOL, WireError, pack, unpack
from tests.conftest import DATA_TASK as TASK


@pytest.fixture
def server():
    s = PolicyServer("random", TASK, port=0).start()
    yield s
    s.stop()


def test_wire_round_trip_keeps_arrays_exact():
    msg = {"state": np.arange(14, dtype=np.float32), "img": np.zeros((3, 4, 5), np.uint8),
           "prompt": "pick", "k": np.int64(3)}
    back = unpack(pack(msg))
    np.testing.assert_array_equal(back["state"], msg["state"])
    assert back["state"].dtype == np.float32 and back["img"].shape == (3, 4, 5)
    assert back["prompt"] == "pick" and back["k"] == 3
    with pytest.raises(WireError):
        pack({"x": np.array([object()])})
    with pytest.raises(WireError):
        unpack(b"\xc1")


def test_remote_evaluation_equals_the_local_policy(server, tmp_path):
    common = {"episodes": 2, "video": "none", "progress": False, "seed_cache": tmp_path / "s"}
    local = evaluate(EvalConfig((TASK,), "random", tmp_path / "local", **common))
    remote = evaluate(EvalConfig((TASK,), f"remote:ws://127.0.0.1:{server.port}",
                                 tmp_path / "remote", **common))
    assert remote["tasks"] == local["tasks"]
    strip = lambda rs: [{k: v for k, v in r.items() if k != "wall_s"} for r in rs]  # noqa: E731
    assert strip(read_records(tmp_path / "remote" / TASK / "episodes.jsonl")) == \
        strip(read_records(tmp_path / "local" / TASK / "episodes.jsonl"))


def test_malformed_messages_get_an_error_and_the_server_keeps_serving(server):
    with connect(f"ws://127.0.0.1:{server.port}") as ws:
        meta = unpack(ws.recv(timeout=10))
        assert meta["server"] == "rmbench" and meta["protocol"] == PROTOCOL
        for bad in (b"\xc1\x00", "text", pack([1, 2]), pack({"reset": True, "task_info": "x"})):
            ws.send(bad)
            assert "error" in unpack(ws.recv(timeout=10))
        ws.send(pack({"reset": True, "instruction": "", "task_info": {"seed": 1}}))
        assert unpack(ws.recv(timeout=10)) == {"ok": True}
        ws.send(pack({"agent_pos": np.zeros(14)}))
        assert unpack(ws.recv(timeout=10))["actions"].shape == (1, 14)


def test_privileged_policies_are_not_served():
    with pytest.raises(ValueError, match="cannot be served"):
        PolicyServer("expert", TASK)


class OpenpiStandIn:
    """A stand-in for openpi's websocket policy server, for testing the adapter only: the same
    wire format and ALOHA input keys, answering a 50-step chunk that holds the given state. On
    a bad input it does what openpi's server does: send the traceback as text and close."""

    def __init__(self):
        from websockets.sync.server import serve
        self.seen: list[dict] = []
        self.fail = False
        self._server = serve(self.handle, "127.0.0.1", 0, compression=None)
        self.port = self._server.socket.getsockname()[1]
        import threading
        threading.Thread(target=self._server.serve_forever, daemon=True).start()

    def handle(self, ws):
        ws.send(pack({"action_horizon": 50}))  # openpi greets with its policy metadata
        for raw in ws:
            obs = unpack(raw)
            try:
                if self.fail:
                    raise ValueError("model exploded")
                assert set(obs) == {"state", "images", "prompt"}
                assert set(obs["images"]) == {"cam_high", "cam_left_wrist", "cam_right_wrist"}
                self.seen.append(obs)
                ws.send(pack({"actions": np.tile(np.pad(obs["state"], (0, 18)), (50, 1)),
                              "server_timing": {"infer_ms": 1.0}}))
            except Exception as err:
                ws.send(f"Traceback (most recent call last):\n  ...\nValueError: {err}")
                ws.close()
                return

    def stop(self):
        self._server.shutdown()


@pytest.fixture
def openpi_server():
    s = OpenpiStandIn()
    yield s
    s.stop()


def test_openpi_adapter_sends_the_aloha_layout(openpi_server, tmp_path):
    summary = evaluate(EvalConfig((TASK,), f"remote:ws://127.0.0.1:{openpi_server.port}?steps=10",
                                  tmp_path / "pi", episodes=1, video="none", progress=False,
                                  seed_cache=tmp_path / "s"))
    (record,) = read_records(tmp_path / "pi" / TASK / "episodes.jsonl")
    assert record["reason"] in ("timeout", "task_failure"), record
    seen = openpi_server.seen
    # one request per 10 executed steps: the chunk was cut to ?steps=10
    assert len(seen) == -(-record["steps"] // 10)
    first = seen[0]
    assert first["state"].dtype == np.float32 and first["state"].shape == (14,)
    img = first["images"]["cam_high"]
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[0] == 3  # CHW
    assert first["prompt"] == record["instruction"] and first["prompt"]
    assert summary["tasks"][TASK]["episodes"] == 1


def test_openpi_server_error_is_a_policy_error_of_that_episode_alone(openpi_server, tmp_path):
    """openpi's server sends its error as text and closes: that episode ends as policy_error,
    and the next one connects again instead of failing on the closed connection."""
    from rmbench.serve.client import open_remote

    policy = open_remote(f"ws://127.0.0.1:{openpi_server.port}")
    obs = {"agent_pos": np.zeros(14), "pixels": {cam: np.zeros((8, 8, 3), np.uint8) for cam in
                                                 ("head", "left_wrist", "right_wrist")}}
    try:
        openpi_server.fail = True
        policy.reset("pick", {})
        with pytest.raises(RuntimeError, match="model exploded"):
            policy.act(obs)
        openpi_server.fail = False
        policy.reset("pick", {})
        assert policy.act(obs).shape == (50, 14)
    finally:
        policy.close()
    openpi_server.fail = True
    evaluate(EvalConfig((TASK,), f"remote:ws://127.0.0.1:{openpi_server.port}", tmp_path / "pi",
                        episodes=1, video="none", progress=False, seed_cache=tmp_path / "s"))
    (record,) = read_records(tmp_path / "pi" / TASK / "episodes.jsonl")
    assert record["reason"] == "policy_error"
    assert "model exploded" in record["message"]


def test_a_server_gone_stops_the_evaluation_and_a_rerun_resumes(server, tmp_path, monkeypatch):
    """A server that cannot be reached at an episode's reset says nothing about the episode:
    the evaluation stops there in one line (instead of recording every remaining seed as a
    policy error), and run again once the server is back it plays what is missing."""
    import rmbench.eval.episode as episode
    import rmbench.serve.client as client
    from rmbench.policies.base import PolicyUnavailable

    cfg = EvalConfig((TASK,), f"remote:ws://127.0.0.1:{server.port}", tmp_path / "e",
                     episodes=3, video="none", progress=False, seed_cache=tmp_path / "s")
    real_reset, real_connect, resets, down = episode._Episode.reset_policy, client.connect, [], []

    def reset(self, policy, slot):  # the server goes down before the second episode
        remote = getattr(policy, "policy", policy)
        if isinstance(remote, client.RemotePolicy):  # (not the seed search's expert)
            resets.append(self.seed)
            if len(resets) == 2:
                down.append(True)
                remote.ws.close()
        real_reset(self, policy, slot)

    def connect(*args, **kwargs):
        if down:
            raise ConnectionRefusedError(111, "Connection refused")
        return real_connect(*args, **kwargs)

    monkeypatch.setattr(episode._Episode, "reset_policy", reset)
    monkeypatch.setattr(client, "connect", connect)
    with pytest.raises(PolicyUnavailable, match=f"127.0.0.1:{server.port}: Connection refused"):
        evaluate(cfg)
    kept = read_records(tmp_path / "e" / TASK / "episodes.jsonl")
    assert len(kept) == 1 and kept[0]["reason"] != "policy_error"
    down.clear()  # back up: the same command plays the two missing seeds
    summary = evaluate(cfg)
    records = read_records(tmp_path / "e" / TASK / "episodes.jsonl")
    assert summary["tasks"][TASK]["episodes"] == 3 and len(records) == 3
    assert not any(r["reason"] == "policy_error" for r in records)


def test_something_else_at_the_address_is_a_one_line_error():
    """A port where no websocket server answers (here a banner and a close) is the address
    said with what went wrong, not a traceback."""
    import socket
    import threading

    from rmbench.policies.base import PolicyUnavailable
    from rmbench.serve.client import open_remote

    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen()

    def banner():
        conn, _ = listener.accept()
        conn.sendall(b"SSH-2.0-OpenSSH_9.2\r\n")
        conn.close()

    threading.Thread(target=banner, daemon=True).start()
    port = listener.getsockname()[1]
    try:
        with pytest.raises(PolicyUnavailable, match=f"127.0.0.1:{port} is not a websocket server"):
            open_remote(f"ws://127.0.0.1:{port}", timeout=10)
    finally:
        listener.close()


def test_a_reset_is_checked_like_an_observation(server):
    with connect(f"ws://127.0.0.1:{server.port}") as ws:
        unpack(ws.recv(timeout=10))
        from rmbench.tasks import get_task
        for bad, said in (({"reset": True, "bogus": 3}, "unexpected entries ['bogus']"),
                          ({"reset": True, "task_info": []}, "task_info must be a map"),
                          ({"reset": True, "task_info": {"gym_id": "rmbench/Other-v0"}},
                           f"serves {get_task(TASK).gym_id}, not rmbench/Other-v0")):
            ws.send(pack(bad))
            assert said in unpack(ws.recv(timeout=10))["error"]
        ws.send(pack({"reset": True, "task_info": {"gym_id": get_task(TASK).gym_id}}))
        assert unpack(ws.recv(timeout=10)) == {"ok": True}


def test_remote_arguments_are_checked():
    from rmbench.serve.client import parse_remote
    assert parse_remote("ws://h:1/p?adapter=openpi&steps=5&x=1") == ("ws://h:1/p?x=1", "openpi", 5)
    for bad in ("http://h:1", "ws://h:1?adapter=grpc", "ws://h:1?steps=0"):
        with pytest.raises(ValueError):
            parse_remote(bad)
