"""``rmbench serve``: a policy behind a websocket, one policy instance per connection.

Protocol (docs/guides/policy_server.md): on connect the server sends its metadata; then each client
message is a msgpack map. ``{"reset": true, "instruction": str, "task_info": {...}}`` resets
the policy and is answered ``{"ok": true}``; any other map is an observation, answered
``{"actions": (k, 14) float64}``. A malformed message or a failing policy is answered
``{"error": str}`` and the connection stays open.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.server import Server, serve

from rmbench.envs.registration import make
from rmbench.eval.episode import as_chunk
from rmbench.policies.registry import make_policy, parse_spec
from rmbench.serve.wire import MAX_MESSAGE_BYTES, PROTOCOL, WireError, pack, unpack
from rmbench.sim.simulator import ACTION_DIM

log = logging.getLogger(__name__)


class PolicyServer:
    def __init__(self, policy: str, task: str, host: str = "127.0.0.1", port: int = 8000):
        entry, _ = parse_spec(policy)
        if entry.name in ("expert", "remote"):
            raise ValueError(f"policy {entry.name!r} cannot be served: it needs the simulator "
                             f"state or is itself remote")
        self.spec, self.task, self.host, self.port = policy, task, host, port
        self._server: Server | None = None

    def metadata(self, policy) -> dict[str, Any]:
        return {"server": "rmbench", "protocol": PROTOCOL, "policy": self.spec, "task": self.task,
                "cameras": list(getattr(policy, "cameras", ())), "action_dim": ACTION_DIM}

    def handle(self, ws) -> None:
        env = make(self.task, render=False)  # what the policy is built for (bounds, task)
        try:
            policy = make_policy(self.spec, env)
            ws.send(pack(self.metadata(policy)))
            for message in ws:
                ws.send(pack(self.respond(policy, message)))
        except ConnectionClosed:
            pass
        finally:
            env.close()

    @staticmethod
    def respond(policy, message) -> dict[str, Any]:
        try:
            msg = unpack(message)
            if not isinstance(msg, dict):
                raise WireError("a message must be a map")
            if msg.get("reset"):
                policy.reset(str(msg.get("instruction", "")), dict(msg.get("task_info") or {}))
                return {"ok": True}
            return {"actions": as_chunk(policy.act(msg))}
        except WireError as err:
            return {"error": f"bad message: {err}"}
        except Exception as err:
            log.warning("policy error: %s", err)
            return {"error": f"policy error: {type(err).__name__}: {err}"}

    def start(self) -> PolicyServer:
        """Serve in a background thread (``port=0`` picks a free port)."""
        self._server = serve(self.handle, self.host, self.port, max_size=MAX_MESSAGE_BYTES,
                             compression=None)
        self.port = self._server.socket.getsockname()[1]
        threading.Thread(target=self._server.serve_forever, daemon=True).start()
        return self

    def serve_forever(self) -> None:
        with serve(self.handle, self.host, self.port, max_size=MAX_MESSAGE_BYTES,
                   compression=None) as server:
            self._server = server
            log.warning("serving %s for %s on ws://%s:%d", self.spec, self.task, self.host, self.port)
            server.serve_forever()

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()


