"""The policy server: evaluation through it, malformed messages, the wire format."""

import numpy as np
import pytest
from websockets.sync.client import connect

from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.harness import read_records
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


def test_openpi_server_error_is_a_policy_error(openpi_server, tmp_path):
    openpi_server.fail = True
    evaluate(EvalConfig((TASK,), f"remote:ws://127.0.0.1:{openpi_server.port}", tmp_path / "pi",
                        episodes=1, video="none", progress=False, seed_cache=tmp_path / "s"))
    (record,) = read_records(tmp_path / "pi" / TASK / "episodes.jsonl")
    assert record["reason"] == "policy_error"
    assert "model exploded" in record["message"]


def test_remote_arguments_are_checked():
    from rmbench.serve.client import parse_remote
    assert parse_remote("ws://h:1/p?adapter=openpi&steps=5&x=1") == ("ws://h:1/p?x=1", "openpi", 5)
    for bad in ("http://h:1", "ws://h:1?adapter=grpc", "ws://h:1?steps=0"):
        with pytest.raises(ValueError):
            parse_remote(bad)
