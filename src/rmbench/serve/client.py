"""``remote:ws://HOST:PORT``: a policy served elsewhere (``rmbench serve`` or an openpi-style
server), reached over a websocket."""

from __future__ import annotations

from typing import Any

import numpy as np
from websockets.sync.client import connect

from rmbench.policies.base import BasePolicy
from rmbench.policies.registry import register_policy
from rmbench.serve.wire import MAX_MESSAGE_BYTES, PROTOCOL, pack, unpack


class RemotePolicy(BasePolicy):
    def __init__(self, url: str, timeout: float = 60.0):
        if not url.startswith(("ws://", "wss://")):
            raise ValueError(f"remote policy needs a ws:// or wss:// address, got {url!r}")
        self.url = url
        self.ws = connect(url, max_size=MAX_MESSAGE_BYTES, open_timeout=timeout,
                          compression=None)
        self.metadata = unpack(self.ws.recv(timeout=timeout))
        if self.metadata.get("server") == "rmbench" and self.metadata.get("protocol") != PROTOCOL:
            raise RuntimeError(f"{url} speaks protocol {self.metadata.get('protocol')}, "
                               f"this client {PROTOCOL}")
        self.cameras = tuple(self.metadata.get("cameras", ()))
        self.timeout = timeout

    def _call(self, msg: dict[str, Any]) -> dict[str, Any]:
        self.ws.send(pack(msg))
        reply = unpack(self.ws.recv(timeout=self.timeout))
        if "error" in reply:
            raise RuntimeError(f"server: {reply['error']}")
        return reply

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        if self.metadata.get("server") == "rmbench":
            self._call({"reset": True, "instruction": instruction, "task_info": task_info})

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        return np.asarray(self._call(observation)["actions"])

    def close(self) -> None:
        self.ws.close()


register_policy("remote", "a policy behind a websocket (rmbench serve)", needs_argument=True)(
    lambda arg, env: RemotePolicy(arg))
