"""``rmbench serve``: a policy behind a websocket.

Protocol (docs/guides/policy_server.md): on connect the server sends its greeting, which says what
the policy reads (``contract.py``); then each client message is a msgpack map.
``{"reset": true, "instruction": str, "task_info": {...}}`` starts an episode and is answered
``{"ok": true}``; any other map is an observation, answered ``{"actions": (k, 14) float64}``.
A malformed message or a failing policy is answered ``{"error": str}`` and the connection
stays open; a message over the cap closes it (websocket code 1009).

Everything a client controls is bounded: the message's size (``Contract.max_message_bytes``),
what it holds (``wire.scan``), each entry (``Contract``, before the policy sees it), the
messages queued per connection, the connections at once and how long one may stay idle. The
policy is loaded once; each connection gets its own episode state around the shared model
(``fork``), and one inference runs at a time.
"""

from __future__ import annotations

import copy
import logging
import threading
from dataclasses import dataclass
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.server import Server, ServerConnection, serve

from rmbench.envs.registration import make
from rmbench.eval.episode import as_chunk
from rmbench.policies.registry import (
    PIXELS_OBS_TYPE,
    env_options,
    make_policy,
    parse_spec,
    reads_simulator,
)
from rmbench.serve.contract import FRAME_MAX, Contract
from rmbench.serve.wire import PROTOCOL, WireError, pack, unpack
from rmbench.sim.simulator import ACTION_DIM
from rmbench.tasks import get_task

log = logging.getLogger(__name__)
MAX_QUEUE = 2  # messages read ahead per connection; a client waits for each reply anyway


def fork(policy):
    """A policy with its own episode state around ``policy``'s loaded model: the policy's
    ``fork()`` if it has one, else a shallow copy. The built-in and learned policies rebind
    all their episode state in ``reset``, and a connection is served observations only after
    its first reset, so no episode state is ever shared."""
    return policy.fork() if hasattr(policy, "fork") else copy.copy(policy)


@dataclass
class Episode:
    """A connection's policy and whether a reset has started its episode."""

    policy: Any
    started: bool = False


class PolicyServer:
    def __init__(self, policy: str, task: str, host: str = "127.0.0.1", port: int = 8000, *,
                 max_connections: int = 4, idle_timeout: float = 300.0,
                 origins: list[str] | None = None, frame_max: tuple[int, int] = FRAME_MAX):
        entry, _ = parse_spec(policy)
        if entry.name == "remote":
            raise ValueError("policy 'remote' cannot be served: it is itself a remote policy")
        if reads_simulator(policy):
            raise ValueError(f"policy {policy!r} cannot be served: it reads the simulator "
                             f"(privileged state or the true subtask boundary), which a client "
                             f"sends no part of")
        if max_connections < 1 or not idle_timeout > 0:
            raise ValueError(f"max_connections must be >= 1 and idle_timeout > 0, got "
                             f"{max_connections} and {idle_timeout}")
        self.spec, self.task, self.host, self.port = policy, get_task(task).name, host, port
        self.max_connections, self.idle_timeout = max_connections, idle_timeout
        # browsers always send their page's Origin; other clients (rmbench's, openpi's) none
        self.origins = [*origins, None] if origins else None
        options = env_options(policy)
        obs_type = options.get("obs_type", PIXELS_OBS_TYPE)
        # the policy reads the env's bounds and task only: it is never stepped here
        self.env = make(self.task, render=False, obs_type=obs_type)
        self.policy = make_policy(policy, self.env)
        state = "environment_state" in obs_type
        cameras = tuple(getattr(self.policy, "cameras", ()) or ()) if obs_type.startswith(
            "pixels") else ()
        self.contract = Contract(self.task, obs_type, cameras,
                                 len(get_task(task).state_names) if state else None,
                                 tuple(frame_max))
        self._infer = threading.Lock()  # one inference at a time on the shared model
        self._count = threading.Lock()
        self._connections = 0
        self._server: Server | None = None

    def metadata(self) -> dict[str, Any]:
        return {"server": "rmbench", "protocol": PROTOCOL, "policy": self.spec, "task": self.task,
                "action_dim": ACTION_DIM, **self.contract.greeting()}

    def handle(self, ws: ServerConnection) -> None:
        with self._count:
            admitted = self._connections < self.max_connections
            self._connections += admitted
        if not admitted:
            ws.send(pack({"error": f"server busy: {self.max_connections} connections at once"}))
            ws.close(1013, "server busy")
            return
        try:
            episode = Episode(fork(self.policy))
            ws.send(pack(self.metadata()))
            while True:
                try:
                    message = ws.recv(timeout=self.idle_timeout)
                except TimeoutError:
                    ws.close(1000, f"idle for {self.idle_timeout:g} s")
                    return
                ws.send(pack(self.respond(episode, message)))
        except ConnectionClosed:
            pass
        finally:
            with self._count:
                self._connections -= 1

    def respond(self, episode: Episode, message) -> dict[str, Any]:
        try:
            msg = unpack(message, self.contract.limits)
            if not isinstance(msg, dict):
                raise WireError("a message must be a map")
            if "reset" in msg:
                if msg.pop("reset") is not True:
                    raise WireError("reset must be true")
                instruction, info = self.contract.check_reset(msg)
                episode.started = False  # until this reset has rebound the episode state
                with self._infer:
                    episode.policy.reset(instruction, info)
                episode.started = True
                return {"ok": True}
            obs = self.contract.check_observation(msg)
            if not episode.started:
                raise WireError("send a reset before the episode's first observation")
            with self._infer:
                return {"actions": as_chunk(episode.policy.act(obs))}
        except WireError as err:
            return {"error": f"bad message: {err}"}
        except Exception as err:
            log.warning("policy error: %s", err)
            return {"error": f"policy error: {type(err).__name__}: {err}"[:1000]}

    def _serve(self) -> Server:
        return serve(self.handle, self.host, self.port, max_size=self.contract.max_message_bytes,
                     max_queue=MAX_QUEUE, compression=None, origins=self.origins)

    def start(self) -> PolicyServer:
        """Serve in a background thread (``port=0`` picks a free port)."""
        self._server = self._serve()
        self.port = self._server.socket.getsockname()[1]
        threading.Thread(target=self._server.serve_forever, daemon=True).start()
        return self

    def serve_forever(self) -> None:
        with self._serve() as server:
            self._server = server
            self.port = server.socket.getsockname()[1]
            log.warning("serving %s for %s on ws://%s:%d", self.spec, self.task, self.host,
                        self.port)
            server.serve_forever()

    def stop(self) -> None:
        if self._server is not None:
            self._server.shutdown()
        self.env.close()
