"""``remote:ws://HOST:PORT[?adapter=auto|rmbench|openpi&steps=N]``: a policy served elsewhere
(``rmbench serve``, or an openpi policy server), reached over a websocket.

The adapter is chosen by the server's greeting: ``rmbench serve`` announces itself and gets
rmbench observations and reset messages; any other server is taken to be openpi's and gets the
ALOHA layout (serve/openpi.py). ``adapter=`` overrides the guess; ``steps=N`` executes only the
first N actions of each returned chunk before asking again (openpi's ALOHA examples replan
after 10 to 25 of the 50).
"""

from __future__ import annotations

from contextlib import ExitStack
from typing import Any
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import numpy as np
from websockets.sync.client import connect

from rmbench.policies.base import BasePolicy
from rmbench.policies.registry import register_policy
from rmbench.serve import openpi
from rmbench.serve.wire import MAX_MESSAGE_BYTES, PROTOCOL, pack, unpack

ADAPTERS = ("auto", "rmbench", "openpi")


def parse_remote(url: str) -> tuple[str, str, int | None]:
    """(address to connect to, adapter, steps) from a ``remote:`` argument."""
    if not url.startswith(("ws://", "wss://")):
        raise ValueError(f"remote policy needs a ws:// or wss:// address, got {url!r}")
    parts = urlsplit(url)
    query = dict(parse_qsl(parts.query))
    adapter = query.pop("adapter", "auto")
    if adapter not in ADAPTERS:
        raise ValueError(f"unknown adapter {adapter!r}; adapters: {', '.join(ADAPTERS)}")
    steps = query.pop("steps", None)
    if steps is not None and (not steps.isdigit() or int(steps) < 1):
        raise ValueError(f"steps must be a positive integer, got {steps!r}")
    address = urlunsplit(parts._replace(query=urlencode(query)))
    return address, adapter, (int(steps) if steps else None)


class RemotePolicy(BasePolicy):
    def __init__(self, url: str, timeout: float = 60.0):
        self.url, adapter, self.steps = parse_remote(url)
        self.timeout = timeout
        self._stack = ExitStack()  # the connection is a context; close() leaves it
        self.ws = self._stack.enter_context(connect(
            self.url, max_size=MAX_MESSAGE_BYTES, open_timeout=timeout, compression=None))
        self.metadata = unpack(self.ws.recv(timeout=timeout))
        is_rmbench = isinstance(self.metadata, dict) and self.metadata.get("server") == "rmbench"
        self.adapter = ("rmbench" if is_rmbench else "openpi") if adapter == "auto" else adapter
        if self.adapter == "rmbench":
            if not is_rmbench or self.metadata.get("protocol") != PROTOCOL:
                raise RuntimeError(f"{self.url} is not an rmbench server of protocol {PROTOCOL} "
                                   f"(metadata {self.metadata!r})")
            self.cameras = tuple(self.metadata.get("cameras", ()))
        else:
            self.cameras = tuple(openpi.CAMERA_KEYS)
        self.prompt = ""

    def _call(self, msg: dict[str, Any]) -> Any:
        self.ws.send(pack(msg))
        raw = self.ws.recv(timeout=self.timeout)
        return raw if isinstance(raw, str) else unpack(raw)

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        self.prompt = instruction
        if self.adapter == "rmbench":
            self._rmbench_reply(self._call(
                {"reset": True, "instruction": instruction, "task_info": task_info}))

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        if self.adapter == "openpi":
            reply = self._call(openpi.observation_to_openpi(observation, self.prompt))
            return openpi.actions_from_openpi(reply, self.steps)
        actions = np.asarray(self._rmbench_reply(self._call(observation))["actions"])
        return actions[: self.steps] if actions.ndim == 2 else actions

    def _rmbench_reply(self, reply: Any) -> dict[str, Any]:
        if not isinstance(reply, dict):
            raise RuntimeError(f"server sent {type(reply).__name__}, expected a map")
        if "error" in reply:
            raise RuntimeError(f"server: {reply['error']}")
        return reply

    def close(self) -> None:
        self._stack.close()


register_policy("remote", "a policy behind a websocket: rmbench serve, or openpi's server "
                "(?adapter=openpi, ?steps=N)", needs_argument=True)(
    lambda arg, env: RemotePolicy(arg))
