"""``rmbench serve``: a policy behind a websocket.

Protocol (docs/guides/policy_server.md): on connect the server sends its greeting, which says what
the policy reads (``contract.py``); then each client message is a msgpack map.
``{"reset": true, "instruction": str, "task_info": {...}}`` starts an episode and is answered
``{"ok": true}``; any other map is an observation, answered ``{"actions": (k, 14) float64}``.
A policy with the batched form (policies/base.py) is also served in slots, its greeting's
``batch`` of them per connection: ``{"reset": true, "slot": i, ...}`` starts slot i's episode,
and ``{"batch": [observation or nil, ...]}`` is answered ``{"actions": [chunk or nil, ...]}``
from one call of the policy's ``act_batch``, so one request carries a step of many episodes
(with ``"status"``, each answered slot's ``status_batch``, where the policy reports one).
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
from dataclasses import dataclass, field, replace
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.server import Server, ServerConnection, serve

from rmbench.envs.registration import make
from rmbench.eval.episode import as_chunk, batches
from rmbench.policies.registry import (
    PIXELS_OBS_TYPE,
    env_options,
    make_policy,
    parse_spec,
    policy_cameras,
    reads_simulator,
)
from rmbench.serve.contract import FRAME_MAX, MAX_SLOTS, Contract
from rmbench.serve.wire import PROTOCOL, WireError, pack, unpack
from rmbench.sim.simulator import ACTION_DIM
from rmbench.tasks import get_task

log = logging.getLogger(__name__)
MAX_QUEUE = 2  # messages read ahead per connection; a client waits for each reply anyway
MAX_IDLE_TIMEOUT = 1e6  # seconds (11.6 days)


def fork(policy):
    """A policy with its own episode state around ``policy``'s loaded model: the policy's
    ``fork()`` if it has one, else a shallow copy. The built-in and learned policies rebind
    all their episode state in ``reset``, and a connection is served observations only after
    its first reset, so no episode state is ever shared."""
    return policy.fork() if hasattr(policy, "fork") else copy.copy(policy)


@dataclass
class Episode:
    """A connection's policy and the episodes a reset has started on it: the single one
    (``started``) or the slots of the batched form (``slots``). ``owned``: a ``reset`` has
    rebound the fork's episode state, which ``reset_batch`` alone may only update in place
    (a slot list shared with the loaded policy and every other connection's fork)."""

    policy: Any
    started: bool = False
    slots: set[int] = field(default_factory=set)
    owned: bool = False


class PolicyServer:
    def __init__(self, policy: str, task: str, host: str = "127.0.0.1", port: int = 8000, *,
                 max_connections: int = 4, idle_timeout: float = 300.0,
                 origins: list[str] | None = None, frame_max: tuple[int, int] = FRAME_MAX,
                 max_slots: int = MAX_SLOTS):
        entry, _ = parse_spec(policy)
        if entry.name == "remote":
            raise ValueError("policy 'remote' cannot be served: it is itself a remote policy")
        if reads_simulator(policy):
            raise ValueError(f"policy {policy!r} cannot be served: it reads the simulator "
                             f"(privileged state or the true subtask boundary), which a client "
                             f"sends no part of")
        # (a timeout near infinity overflows the socket's clock: every connection would fail)
        if max_connections < 1 or not 0 < idle_timeout <= MAX_IDLE_TIMEOUT:
            raise ValueError(f"max_connections must be >= 1 and idle_timeout in (0, "
                             f"{MAX_IDLE_TIMEOUT:g}] seconds, got {max_connections} and "
                             f"{idle_timeout}")
        if not 1 <= max_slots <= MAX_SLOTS:
            raise ValueError(f"max_slots must be in [1, {MAX_SLOTS}], got {max_slots}")
        self.spec, self.task, self.host, self.port = policy, get_task(task).name, host, port
        self.max_connections, self.idle_timeout = max_connections, idle_timeout
        # browsers always send their page's Origin; other clients (rmbench's, openpi's) none
        self.origins = [*origins, None] if origins else None
        # what the policy reads is its registration's to say, as for a local evaluation
        options = env_options(policy)
        obs_type = options.get("obs_type", PIXELS_OBS_TYPE)
        cameras = policy_cameras(policy)
        # the policy reads the env's bounds and task only: it is never stepped here
        self.env = make(self.task, render=False, obs_type=obs_type)
        self.policy = make_policy(policy, self.env)
        state = "environment_state" in obs_type
        size = (options["width"], options["height"]) if cameras and "width" in options else None
        self.contract = Contract(self.task, obs_type, cameras,
                                 len(get_task(task).state_names) if state else None,
                                 tuple(frame_max), frame_size=size)
        if batches(self.policy):  # the cap grows with the slots, so they are announced
            self.contract = replace(self.contract, batch=self.contract.slots_for(max_slots))
        self._infer = threading.Lock()  # one inference at a time on the shared model
        self._count = threading.Lock()
        self._connections = 0
        self._server: Server | None = None

    def metadata(self) -> dict[str, Any]:
        return {"server": "rmbench", "protocol": PROTOCOL, "policy": self.spec, "task": self.task,
                "gym_id": get_task(self.task).gym_id, "action_dim": ACTION_DIM,
                **self.contract.greeting()}

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
                if "slot" in msg:
                    return self.reset_slot(episode, msg)
                instruction, info = self.contract.check_reset(msg)
                # until this reset has rebound the episode state; the slots' go with it
                episode.started, episode.slots = False, set()
                with self._infer:
                    episode.policy.reset(instruction, info)
                episode.started = episode.owned = True
                return {"ok": True}
            if "batch" in msg:
                return self.act_batch(episode, msg)
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

    def _batched(self, what: str) -> None:
        if not self.contract.batch:
            raise WireError(f"this policy plays one episode at a time (its greeting's batch "
                            f"is 0): no {what}")

    def reset_slot(self, episode: Episode, msg: dict) -> dict[str, Any]:
        """``{"slot": i, "instruction": ..., "task_info": ...}``: a new episode in slot i."""
        self._batched("slot resets")
        slot = self.contract.check_slot(msg.pop("slot"))
        instruction, info = self.contract.check_reset(msg)
        # a single episode shares the policy's state with the slots: it ends here
        episode.started = False
        episode.slots.discard(slot)  # until this reset has rebound the slot's state
        with self._infer:
            if not episode.owned:
                # the fork's episode state is its own only after a reset rebinds it
                episode.policy.reset(instruction, info)
                episode.owned = True
            # a slot's policy reads the observation only: no env (simulator readers are refused)
            episode.policy.reset_batch(slot, instruction, info, None)
        episode.slots.add(slot)
        return {"ok": True}

    def act_batch(self, episode: Episode, msg: dict) -> dict[str, Any]:
        """``{"batch": [obs or nil, ...]}``: every given slot's next chunk from one call."""
        self._batched("batch messages")
        extra = sorted(str(k)[:40] for k in msg if k != "batch")
        if extra:
            raise WireError(f"unexpected entries {extra[:4]} beside 'batch'")
        batch = self.contract.check_batch(msg["batch"])
        asked = [i for i, obs in enumerate(batch) if obs is not None]
        fresh = [i for i in asked if i not in episode.slots]
        if fresh:
            raise WireError(f"send a reset of slot {fresh[0]} before its first observation")
        if episode.slots and max(episode.slots) >= len(batch):
            # a policy keeps as many slots as a batch has entries: a shorter one drops some
            raise WireError(f"slot {max(episode.slots)} has an episode: a batch needs an "
                            f"entry for each slot up to it, got {len(batch)}")
        if not asked:
            return {"actions": [None] * len(batch)}
        with self._infer:
            answers = list(episode.policy.act_batch(batch))
        if len(answers) != len(batch):
            raise ValueError(f"act_batch answered {len(answers)} of {len(batch)} slots")
        actions: list[Any] = [None] * len(batch)
        errors: list[str | None] = [None] * len(batch)
        # what the policy believes of each answered slot, which evaluation records
        status = getattr(episode.policy, "status_batch", None)
        statuses: list[dict | None] = [None] * len(batch)
        for i in asked:  # a bad answer ends its own slot's episode only, as in evaluation
            try:
                chunk = as_chunk(answers[i])
                if callable(status):
                    statuses[i] = dict(status(i))
                    pack(statuses[i])  # a status the wire cannot carry fails its slot here
                actions[i] = chunk
            except Exception as err:
                errors[i], statuses[i] = f"policy error: {type(err).__name__}: {err}"[:1000], None
        return {"actions": actions, **({"status": statuses} if callable(status) else {}),
                **({"errors": errors} if any(errors) else {})}

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
