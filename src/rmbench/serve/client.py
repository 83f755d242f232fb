"""``remote:ws://HOST:PORT[?adapter=auto|rmbench|openpi&steps=N]``: a policy served elsewhere
(``rmbench serve``, or an openpi policy server), reached over a websocket.

The adapter is chosen by the server's greeting: ``rmbench serve`` announces itself and gets
rmbench observations and reset messages; any other server is taken to be openpi's and gets the
ALOHA layout (serve/openpi.py). ``adapter=`` overrides the guess; ``steps=N`` executes only the
first N actions of each returned chunk before asking again (openpi's ALOHA examples replan
after 10 to 25 of the 50). An rmbench server's greeting also says what its policy reads (the
observation type, the cameras): evaluation builds the env from it (``remote_env_options``),
and the client sends only those entries.

An rmbench server whose greeting announces ``batch`` slots (its policy has the batched form)
gets a ``BatchedRemotePolicy``: it has ``reset_batch``/``act_batch`` too, so evaluation asks it
once per step for every episode of a worker's batch, in one request. Any other server gets a
``RemotePolicy``, which has no ``act_batch``: evaluation plays it one episode at a time, as the
server does.
"""

from __future__ import annotations

from contextlib import ExitStack
from typing import Any
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import numpy as np
from websockets.exceptions import ConnectionClosed, InvalidHandshake, InvalidURI
from websockets.sync.client import connect

from rmbench.policies.base import BasePolicy, PolicyUnavailable
from rmbench.policies.registry import register_policy
from rmbench.serve import openpi
from rmbench.serve.wire import MAX_MESSAGE_BYTES, PROTOCOL, REPLY, WireError, pack, unpack

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
    """Exact or loud: a timeout or a broken connection closes the connection and raises, so
    a late reply can never be taken for the answer to a later observation. The next
    ``reset`` connects again (an rmbench server's episode starts over); an ``act`` before it
    raises, which ends the episode as ``policy_error``. An openpi server keeps no episode
    state, so its next ``act`` connects again."""

    def __init__(self, url: str, timeout: float = 60.0):
        self.url, self.requested_adapter, self.steps = parse_remote(url)
        self.timeout = timeout
        self._stack = ExitStack()  # the connection is a context; close() leaves it
        self.ws = None
        self.metadata: Any = None
        self.prompt = ""
        self._connect()

    def _connect(self) -> None:
        try:
            self.ws = self._stack.enter_context(connect(
                self.url, max_size=MAX_MESSAGE_BYTES, open_timeout=self.timeout,
                compression=None))
        except OSError as err:  # (refused, no such host): the address said with the reason
            raise PolicyUnavailable(f"{self.url}: {err.strerror or err}") from None
        # (something else answers there; a peer that closes mid-handshake, such as a banner
        # and a close, reads as a closed connection or as a bad handshake depending on timing,
        # and on a loaded machine as the websockets sync client's own AssertionError: its
        # reader thread saw the broken pipe while the handshake was still writing)
        except (InvalidHandshake, InvalidURI, ConnectionClosed, AssertionError) as err:
            raise PolicyUnavailable(f"{self.url} is not a websocket server: {err}") from None
        try:
            metadata = unpack(self.ws.recv(timeout=self.timeout), REPLY)
        except (TimeoutError, ConnectionClosed) as err:
            self._disconnect()
            raise PolicyUnavailable(f"{self.url} sent no greeting: {type(err).__name__}: "
                                    f"{err}") from None
        except WireError as err:
            self._disconnect()
            raise PolicyUnavailable(f"{self.url} sent a greeting this client does not read: "
                                    f"{err}") from None
        except Exception:
            self._disconnect()
            raise
        if isinstance(metadata, dict) and "error" in metadata:
            self._disconnect()
            raise RuntimeError(f"{self.url} refused the connection: {metadata['error']}")
        is_rmbench = isinstance(metadata, dict) and metadata.get("server") == "rmbench"
        adapter = (("rmbench" if is_rmbench else "openpi") if self.requested_adapter == "auto"
                   else self.requested_adapter)
        if adapter == "rmbench" and (not is_rmbench or metadata.get("protocol") != PROTOCOL):
            self._disconnect()
            raise RuntimeError(f"{self.url} is not an rmbench server of protocol {PROTOCOL} "
                               f"(metadata {metadata!r:.200})")
        if self.metadata is not None and metadata != self.metadata:
            self._disconnect()
            raise RuntimeError(f"{self.url} now serves another policy than at the first "
                               f"connection ({metadata!r:.200})")
        self.metadata, self.adapter = metadata, adapter
        # the slots the server serves side by side on a connection (0: one episode at a time)
        batch = metadata.get("batch") if adapter == "rmbench" else 0
        self.served_slots = batch if type(batch) is int and batch > 0 else 0
        self.max_batch = self.served_slots or None
        # the cameras the served policy reads, which the observations sent carry
        self.served_cameras = (tuple(metadata.get("cameras", ())) if adapter == "rmbench"
                               else tuple(openpi.CAMERA_KEYS))
        self.episode_open = False  # a reset on this connection starts the episode
        self.open_slots: set[int] = set()  # and a slot reset starts that slot's
        self.statuses: dict[int, dict[str, Any]] = {}  # each slot's last status from the server

    def _disconnect(self) -> None:
        self._stack.close()
        self._stack = ExitStack()
        self.ws = None
        self.episode_open, self.open_slots = False, set()  # the server dropped them

    def _call(self, msg: dict[str, Any], again: bool = False) -> Any:
        """The reply to ``msg``. ``again``: a message that starts an episode, which a broken
        connection is sent once more on a fresh one (nothing of an episode was on it), so a
        restarted server is reached again and a server gone is ``PolicyUnavailable``."""
        if self.ws is None:
            self._connect()
        try:
            self.ws.send(pack(msg))
            raw = self.ws.recv(timeout=self.timeout)
        except (TimeoutError, ConnectionClosed, OSError) as err:
            # the reply may still come: only a fresh connection is sure not to read it
            self._disconnect()
            if again and not isinstance(err, TimeoutError):
                return self._call(msg)
            what = (f"no reply within {self.timeout:g} s" if isinstance(err, TimeoutError)
                    else f"{type(err).__name__}: {err}")
            raise RuntimeError(f"{self.url}: {what}; connection closed, the next episode "
                               f"reconnects") from None
        if isinstance(raw, str):  # (openpi's server sends its error as text, then closes)
            self._disconnect()
            return raw
        return unpack(raw, REPLY)

    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        self.prompt = instruction
        if self.adapter == "rmbench":
            # the server ends the slots' episodes too, as they share the policy's state
            self.episode_open, self.open_slots = False, set()
            self._rmbench_reply(self._call(
                {"reset": True, "instruction": instruction, "task_info": task_info}, again=True))
            self.episode_open = True

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        if self.adapter == "openpi":
            reply = self._call(openpi.observation_to_openpi(observation, self.prompt))
            return openpi.actions_from_openpi(reply, self.steps)
        if self.ws is None or not self.episode_open:
            raise RuntimeError(f"{self.url}: the connection was lost in this episode; the "
                               f"next reset reconnects")
        reply = self._rmbench_reply(self._call(self._served(observation)))
        if "actions" not in reply:
            raise RuntimeError(f"server replied without actions: {sorted(reply)[:8]}")
        return self._cut(np.asarray(reply["actions"]))

    def _cut(self, actions: np.ndarray) -> np.ndarray:
        """The first ``steps`` actions of a chunk (``?steps=N``)."""
        return actions[: self.steps] if actions.ndim == 2 else actions

    def _served(self, observation: dict[str, Any]) -> dict[str, Any]:
        """The entries of ``observation`` the server announced that its policy reads."""
        out = {"agent_pos": observation["agent_pos"]}
        if self.metadata.get("state_dim") is not None:
            out["environment_state"] = observation.get("environment_state")
        if self.served_cameras:
            pixels = observation.get("pixels") or {}
            out["pixels"] = {cam: pixels.get(cam) for cam in self.served_cameras}
        return out

    def _rmbench_reply(self, reply: Any) -> dict[str, Any]:
        if not isinstance(reply, dict):
            raise RuntimeError(f"server sent {type(reply).__name__}, expected a map")
        if "error" in reply:
            raise RuntimeError(f"server: {reply['error']}")
        return reply

    def env_options(self) -> dict[str, Any]:
        """``rmbench.make`` options for an env whose observation is what the server reads."""
        if self.adapter == "openpi":
            return {"cameras": tuple(openpi.CAMERA_KEYS)}
        obs_type = self.metadata.get("obs_type", "pixels_agent_pos")
        if not isinstance(obs_type, str):
            raise RuntimeError(f"{self.url}: the greeting's obs_type is not a name: "
                               f"{obs_type!r:.60}")
        if not obs_type.startswith("pixels"):
            return {"obs_type": obs_type}
        if not self.served_cameras:
            return {"obs_type": obs_type, "render": False}
        size = self.metadata.get("frame_size")  # (a server before it said one: the default)
        if size is None:
            return {"obs_type": obs_type, "cameras": self.served_cameras}
        if not (isinstance(size, list) and len(size) == 2
                and all(type(v) is int and 16 <= v <= 4096 for v in size)):
            raise RuntimeError(f"{self.url}: the greeting's frame_size is not [W, H] in pixels: "
                               f"{size!r:.60}")
        return {"obs_type": obs_type, "cameras": self.served_cameras,
                "width": size[0], "height": size[1]}

    def close(self) -> None:
        self._disconnect()


def remote_env_options(arg: str | None) -> dict[str, Any]:
    """What the served policy reads, from the server's greeting (one short connection)."""
    policy = RemotePolicy(arg or "", timeout=30.0)
    try:
        return policy.env_options()
    finally:
        policy.close()


def _remote(arg: str | None, env) -> RemotePolicy:
    policy = open_remote(arg or "")
    if env is not None and policy.adapter == "rmbench":
        u = env.unwrapped
        task = type(u.task).name
        if task != policy.metadata.get("task"):
            policy.close()
            raise ValueError(f"{policy.url} serves {policy.metadata.get('task')!r}, not {task!r}")
        served = policy.metadata.get("gym_id")
        if served is not None and served != type(u.task).gym_id:
            policy.close()
            raise ValueError(f"{policy.url} serves {served}, this rmbench's {task} is "
                             f"{type(u.task).gym_id} (CHANGELOG.md)")
        if policy.metadata.get("state_dim") is not None and not u.with_state:
            policy.close()
            raise ValueError(f"{policy.url} reads environment_state: make the env with "
                             f"obs_type={policy.metadata.get('obs_type')!r}")
    return policy


class BatchedRemotePolicy(RemotePolicy):
    """A ``RemotePolicy`` whose server announced ``served_slots`` slots: the batched form of the
    interface (policies/base.py), one request per step for every slot. A slot that lost its
    episode to a broken connection gets that error as its answer (ending its episode only);
    an error reply for the whole batch, or a broken connection, raises (ending every episode
    asked). The next slot reset connects again."""

    def reset_batch(self, slot: int, instruction: str, task_info: dict[str, Any],
                    env: Any = None) -> None:
        if not 0 <= slot < self.served_slots:
            raise ValueError(f"{self.url} serves {self.served_slots} slots, not slot {slot}")
        self.episode_open = False  # the server ends a single episode at a slot reset
        self.open_slots.discard(slot)
        self.statuses.pop(slot, None)
        self._rmbench_reply(self._call({"reset": True, "slot": slot, "instruction": instruction,
                                        "task_info": task_info}, again=True))
        self.open_slots.add(slot)

    def act_batch(self, observations: list[dict[str, Any] | None]) -> list[Any]:
        n = len(observations)
        if not 1 <= n <= self.served_slots:
            raise ValueError(f"{self.url} serves batches of 1 to {self.served_slots} slots, "
                             f"got {n}")
        asked = [i for i, o in enumerate(observations) if o is not None]
        lost = [i for i in asked if i not in self.open_slots]
        answers: list[Any] = [None] * n
        for i in lost:
            answers[i] = RuntimeError(f"{self.url}: the connection was lost in this episode; "
                                      f"the next reset reconnects")
        if len(lost) == len(asked):
            return answers
        batch = [self._served(o) if o is not None and i not in lost else None
                 for i, o in enumerate(observations)]
        reply = self._rmbench_reply(self._call({"batch": batch}))
        actions = reply.get("actions")
        errors, statuses = reply.get("errors") or [None] * n, reply.get("status") or [None] * n
        if not all(isinstance(x, list) and len(x) == n for x in (actions, errors, statuses)):
            raise RuntimeError(f"server answered a batch of {n} with {actions!r:.80}")
        for i, o in enumerate(batch):
            if o is None:
                continue
            if errors[i] is not None:
                answers[i] = RuntimeError(f"server: {errors[i]}")
            else:
                answers[i] = self._cut(np.asarray(actions[i]))
                if isinstance(statuses[i], dict):
                    self.statuses[i] = statuses[i]
        return answers

    def status_batch(self, slot: int) -> dict[str, Any]:
        """What the served policy reported of ``slot`` with its last answer (its
        ``status_batch``; empty where it reports none)."""
        return self.statuses.get(slot, {})


def open_remote(url: str, timeout: float = 60.0) -> RemotePolicy:
    """The client for the server at ``url``: a ``BatchedRemotePolicy`` where the greeting
    announces slots, else a ``RemotePolicy`` (which has no ``act_batch``, so evaluation never
    takes it for a batched policy)."""
    policy = RemotePolicy(url, timeout)
    if policy.served_slots:
        # the same connection and state, with the batched methods the greeting allows
        policy.__class__ = BatchedRemotePolicy
    return policy


register_policy("remote", "a policy behind a websocket: rmbench serve, or openpi's server "
                "(?adapter=openpi, ?steps=N)", needs_argument=True,
                env_options=remote_env_options)(_remote)
