"""The policy server: evaluation through it, malformed messages, the wire format."""

import numpy as np
import pytest
from websockets.sync.client import connect

from rmbench.eval import EvalConfig, evaluate
from rmbench.eval.harness import read_records
from rmbench.serve.server import PolicyServer
from rmbench.serve.wire import WireError, pack, unpack
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
        assert meta["server"] == "rmbench" and meta["protocol"] == 1
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
