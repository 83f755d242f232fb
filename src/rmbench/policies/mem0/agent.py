"""``--policy mem0:CKPT[?ablation=A,B]``: Mem-0's closed loop.

Every step: encode the frames (through the frozen backbone first, for a checkpoint trained
with one), or for a checkpoint trained on the state the observation's ``environment_state``
and ``agent_pos``; at a subtask's first step the anchor is set and the sliding window emptied
(one anchor and window per phase of the memory stride, each step reading its own phase's, as
training's walks at the stride build them); c_t from the memories; a new chunk of H actions
when the last D are used (or, with temporal ensembling, every few steps, averaged over the
chunks that overlap); the end classifier's debounced verdict (or, with gt_classifier, the
simulator's subtask boundary).
When a subtask ends its text and end frame go to key memory and the planner names the next
one. M(1) tasks run as one subtask, the goal: no planner, no classifier.

Several episodes side by side (``act_batch``, policies/base.py): each slot keeps its own
episode (memories as rows of the stores, event window, debounce, planner state, subtask,
chunk queue and a generator seeded from its task seed), and each step runs the encoder, the
context, the end classifier and, when a slot needs a chunk, the action head once over all B
slots, padded with copies of a live slot's observation to B rows. A float kernel may sum in
another order for another row count, so the rows are always B; at a given B a row's numbers
do not depend on what the other rows hold (tests/test_batched_eval.py checks it), so an
episode's actions, and its record, are the same whichever episodes share its batch. The
planner (rare: an episode's first step and each subtask end) runs per slot on one row. One
episode alone (``reset``/``act``) is a batch of one, and gives the actions this policy gave
before it had batches; at another B a row's numbers may differ from it in the last bits,
which a closed loop can carry into another episode: compare evaluations at one batch size.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rmbench.policies.action_space import EEActions
from rmbench.policies.base import BasePolicy
from rmbench.policies.checkpoint import CheckpointError, load_policy
from rmbench.policies.config import parse_argument
from rmbench.policies.ensemble import TemporalEnsemble
from rmbench.policies.mem0.classifier import Debounce
from rmbench.policies.mem0.config import TRAINED_ABLATIONS, Mem0Config
from rmbench.policies.mem0.memory import EventWindow, MemoryStore
from rmbench.policies.mem0.planner import DONE
from rmbench.policies.mem0.train import build_model, goal_text
from rmbench.policies.nn.inference import inference
from rmbench.policies.observation import camera_inputs, state_inputs, state_tensor
from rmbench.video import FrameCodec


def load_mem0(path: str | Path, ablations: tuple[str, ...] = (),
              overrides: dict[str, Any] | None = None, env=None):
    """(model, config, describe) from a checkpoint; inference ablations added and inference
    fields (``Mem0Config.INFERENCE_FIELDS``) overridden; with ``env``, its task checked."""

    def add_ablations(cfg: Mem0Config) -> Mem0Config:
        missing = [a for a in ablations if a in TRAINED_ABLATIONS and a not in cfg.ablations]
        if missing:
            raise CheckpointError(f"{path} was trained without {missing[0]}, which changes "
                                  f"training: rmbench train mem0 --ablation {missing[0]}")
        return replace(cfg, ablations=tuple(dict.fromkeys(cfg.ablations + ablations)))

    return load_policy(path, "mem0", Mem0Config, build_model, overrides, add_ablations, env)


class _Slot:
    """One episode's state beside its rows of the policy's memory stores."""

    def __init__(self, cfg: Mem0Config, goal: int, seed: int = 0, env=None):
        self.generator = torch.Generator().manual_seed(seed)
        self.env = env  # the simulator, for gt_classifier
        self.debounce = Debounce(cfg.end_window)
        self.t = 0
        self.subtask_t = 0  # steps since the subtask began: the sliding window's phase
        self.queue: list[np.ndarray] = []
        self.ensemble = TemporalEnsemble(cfg.horizon, cfg.temporal_ensemble)
        self.next_chunk_at = 0  # with temporal ensembling: the step the next chunk is due
        self.first: torch.Tensor | None = None  # planner embedding of o_0
        self.keys: list[tuple[int, torch.Tensor]] = []
        self.subtask = goal
        self.start_subtask = True
        self.stage = 0
        self.ends = 0  # subtask ends declared this episode (eval/boundaries.py reads them)
        self.codecs: dict[str, FrameCodec] = {}  # per camera, with codec_frames


def _first_slot(name: str) -> property:
    """One episode's attribute, as ``reset``/``act`` play it: slot 0's."""
    return property(lambda self: getattr(self.slots[0], name),
                    lambda self, value: setattr(self.slots[0], name, value))


class Mem0Policy(BasePolicy):
    """A Mem-0 checkpoint in the closed loop: each 20 Hz step's observation in, one 14-d joint
    target out. It keeps the memories across the episode and, on an M(n) task, the planner's
    current subtask (``status()``), which moves on when the end classifier says it has ended.
    Several episodes at once through ``reset_batch``/``act_batch`` (the module's docstring)."""

    # one episode's state that analyses read or set (benchmarks/policy_speed.py, the tests)
    t = _first_slot("t")
    first = _first_slot("first")
    keys = _first_slot("keys")
    start_subtask = _first_slot("start_subtask")

    def __init__(self, arg: str, env=None):
        path, overrides, options = parse_argument(arg, Mem0Config, extra=("ablation",))
        ablations = tuple(a for a in options.get("ablation", "").split(",") if a)
        model, cfg, describe = load_mem0(path, ablations, overrides, env)
        self._setup(model, cfg, describe, env)

    @classmethod
    def from_model(cls, model, describe: dict[str, Any], env=None) -> Mem0Policy:
        """A policy around an in-memory model (benchmarks, notebooks)."""
        policy = cls.__new__(cls)
        policy._setup(model.eval(), model.cfg, describe, env)
        return policy

    def _setup(self, model, cfg: Mem0Config, describe: dict[str, Any], env) -> None:
        self.model, self.cfg, self.describe = model, cfg, describe
        self.state_dim = len(describe.get("state_names") or ())
        self.env = env.unwrapped if env is not None else None
        if self.cfg.gt_classifier and self.env is None:
            raise ValueError("gt_classifier reads the simulator's subtask boundary: it cannot be "
                             "served remotely")
        self.ee = EEActions() if cfg.action_space == "ee" else None
        if cfg.codec_frames and cfg.reads_state:
            raise ValueError("codec_frames passes camera frames through the dataset codec; this "
                             "checkpoint reads the state observation")
        self.decompose = self.describe["tmc"] == "M(n)"
        self.goal = self.describe["executor_texts"].index(goal_text(self.describe["task"]))
        self.done = self.describe["planner_texts"].index(DONE)
        self.planner_cams = (None if cfg.reads_state else
                             [cfg.cameras.index(c) for c in cfg.planner_cameras])
        self.reset("", {})

    # ----------------------------------------------------------------- interface
    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        """One episode: a batch of one slot."""
        self.slots: list[_Slot] = []
        self._resize(1)
        self.reset_batch(0, instruction, task_info, self.env)

    def reset_batch(self, slot: int, instruction: str, task_info: dict[str, Any],
                    env=None) -> None:
        """A new episode in ``slot``; its memories start at its first ``act_batch``."""
        self._resize(max(len(self.slots), slot + 1))
        env = env.unwrapped if env is not None else None
        if self.cfg.gt_classifier and env is None:
            raise ValueError("gt_classifier reads the simulator's subtask boundary: it needs "
                             "each slot's env")
        self.slots[slot] = _Slot(self.cfg, self.goal, int(task_info.get("seed", 0)), env)

    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """One control step: the observation in, the next 14-d joint target out. A new chunk is
        sampled when the last one's ``execute`` actions are used up (with temporal ensembling,
        every ``ensemble_every`` steps)."""
        return self.act_batch([observation])[0]

    @inference
    def act_batch(self, observations: list[dict[str, Any] | None]) -> list[np.ndarray | None]:
        """One control step of every slot whose observation is given (``act``'s, per slot),
        the network run over ``len(observations)`` rows."""
        cfg, ex = self.cfg, self.model.executor
        n = len(observations)
        live = [i for i, o in enumerate(observations) if o is not None]
        if not live:
            return [None] * n
        self._resize(n)
        if cfg.codec_frames:  # the frames as a dataset stores them
            observations = [o if o is None else self._stored(o, self.slots[i])
                            for i, o in enumerate(observations)]
        # idle rows copy a live one: every call runs on n rows of real inputs
        rows = [o if o is not None else observations[live[0]] for o in observations]
        converted = {i: self.inputs(observations[i]) for i in live}  # idle rows reuse one
        per_row = [converted.get(i, converted[live[0]]) for i in range(n)]
        inputs = [torch.cat(x) for x in zip(*per_row, strict=True)]
        tokens, z = ex.encode(inputs)
        slots = self.slots
        is_live = torch.zeros(n, dtype=torch.bool)
        is_live[live] = True
        for w, window in enumerate(self.event_windows):  # each from its phase's first step
            window.reset(self._mask(lambda s, w=w: s.t == w, live, n), z)
        for i in live:
            s = slots[i]
            if s.t == 0:
                if self.decompose:
                    s.first = self.model.planner.embed(self.planner_inputs(per_row[i]))
                    s.subtask = self.plan(s.first, i)
            elif (self.decompose and cfg.gt_classifier
                  and s.env.subtask_stage > s.stage):
                # The simulator counts the step done after the action that did it: this frame
                # is the next step's first, as in the demonstrations' labels.
                s.stage = s.env.subtask_stage
                self.subtask_ended(per_row[i], i)
        for i in live:
            s = slots[i]
            if s.start_subtask:
                s.queue, s.start_subtask, s.next_chunk_at = [], False, s.t
                s.subtask_t = 0
                s.ensemble.reset()  # a new subtask's chunks do not average with the last one's
        # Training walks each subtask at the memory stride from a first frame 0 to stride - 1
        # steps into it: the anchor is that frame, the window every frame visited since, so c_t
        # always reads a newest entry one stride old. Each phase of the stride keeps such a
        # walk's memory (its anchor the phase's first frame), and a step reads its own phase's.
        for p, store in enumerate(self.memories):
            store.reset(self._mask(lambda s, p=p: s.subtask_t == p, live, n), tokens)
        c = ex.context(z, self._memory_read(n), torch.tensor([s.subtask for s in slots]))
        for p, store in enumerate(self.memories):
            store.push(z, self._mask(lambda s, p=p: s.subtask_t % cfg.memory_every == p, live, n))
        actions: list[np.ndarray | None] = [None] * n
        if cfg.temporal_ensemble > 0:
            due = [i for i in live if slots[i].t >= slots[i].next_chunk_at]
            for i, chunk in self.chunks(c, rows, due, cfg.horizon).items():
                slots[i].ensemble.add(slots[i].t, chunk)
                slots[i].next_chunk_at = slots[i].t + cfg.ensemble_every
            for i in live:
                actions[i] = slots[i].ensemble.action(slots[i].t)
        else:
            due = [i for i in live if not slots[i].queue]
            for i, chunk in self.chunks(c, rows, due, cfg.execute).items():
                slots[i].queue = list(chunk)
            for i in live:
                actions[i] = slots[i].queue.pop(0)
        if self.decompose and not cfg.gt_classifier:
            p = self.end_probabilities(c, z)
            for i in live:
                if slots[i].debounce.update(p[i].item() > cfg.end_threshold):
                    self.subtask_ended(per_row[i], i)
        # The event window is filled on the episode's phase, as training walks it: the
        # classifier compares each step with the last entries, whichever subtask wrote them.
        for w, window in enumerate(self.event_windows):
            window.push(z, self._mask(lambda s, w=w: s.t % cfg.memory_every == w, live, n))
        for i in live:
            slots[i].t += 1
            slots[i].subtask_t += 1
        return actions

    def status(self) -> dict[str, Any]:
        """The subtask the executor is on (an M(n) task's planner choice; the goal on M(1))
        and how many subtask ends it has declared."""
        return self.status_batch(0)

    def status_batch(self, slot: int) -> dict[str, Any]:
        s = self.slots[slot]
        return {"subtask": self.describe["executor_texts"][s.subtask], "subtask_ends": s.ends}

    # ------------------------------------------------------------------ helpers
    def _resize(self, n: int) -> None:
        """n slots: the memory stores get n rows (the rows kept keep their contents)."""
        if len(self.slots) == n:
            return
        cfg, keep = self.cfg, min(len(self.slots), n)
        memories = [MemoryStore(n, cfg.step_tokens, cfg.sliding_window, cfg.dim)
                    for _ in range(cfg.memory_every)]
        phases = cfg.memory_every if cfg.event_phases else 1
        windows = [EventWindow(n, cfg.event_window, cfg.dim) for _ in range(phases)]
        if keep:
            for new, old in zip(memories + windows, self.memories + self.event_windows,
                                strict=True):
                new.load_state({k: torch.cat([v[:keep], getattr(new, k)[keep:]])
                                for k, v in old.state().items()})
        self.memories, self.event_windows = memories, windows
        self.slots = self.slots[:n] + [_Slot(cfg, self.goal) for _ in range(n - keep)]

    def _memory_read(self, n: int) -> MemoryStore:
        """The memory each of the n rows reads this step: its phase's (``subtask_t`` modulo
        the stride). Chunks drawn on the stride (``execute`` and ``ensemble_every`` multiples
        of it) and the "event" classifier read phase 0's alone, as before phases were kept."""
        phase = [s.subtask_t % self.cfg.memory_every for s in self.slots[:n]]
        if not any(phase):
            return self.memories[0]
        rows, which = torch.arange(n), torch.tensor(phase)
        read = MemoryStore(n, self.cfg.step_tokens, self.cfg.sliding_window, self.cfg.dim)
        read.load_state({k: torch.stack([m.state()[k] for m in self.memories])[which, rows]
                         for k in ("anchor", "sliding", "valid")})
        return read

    def _mask(self, test, live: list[int], n: int) -> torch.Tensor:
        """(n,) bool: the live slots whose state passes ``test``."""
        mask = torch.zeros(n, dtype=torch.bool)
        for i in live:
            mask[i] = bool(test(self.slots[i]))
        return mask

    def chunks(self, c: torch.Tensor, observations: list[dict[str, Any]], due: list[int],
               length: int) -> dict[int, np.ndarray]:
        """The first ``length`` joint targets of a chunk sampled from context c for each slot
        in ``due``, every row through the head at once; each due slot's noise from its own
        generator, the other rows' a copy of the first's (their chunks are not used)."""
        if not due:
            return {}
        ex, cfg = self.model.executor, self.cfg
        state = torch.cat([state_tensor(o) for o in observations])
        shape = (1, cfg.horizon, cfg.action_dim)
        drawn = {i: torch.randn(shape, generator=self.slots[i].generator, device="cpu")
                 for i in due}
        start = torch.cat([drawn.get(i, drawn[due[0]]) for i in range(len(observations))])
        normalised = ex.head.sample(ex.condition(c, state), cfg.flow_steps,
                                    noise=cfg.sample_noise, start=start)
        actions = ex.normalizer.unaction(normalised, state)
        out = {}
        for i in due:
            chunk = actions[i, :length].double().numpy()
            if self.ee is not None:  # grasp poses -> joint targets
                chunk = self.ee.to_joints(chunk, np.asarray(observations[i]["agent_pos"],
                                                            np.float64))
            out[i] = chunk
        return out

    def inputs(self, observation: dict[str, Any]) -> list[torch.Tensor]:
        """What the executor encodes: one image (or its frozen backbone's feature map) per
        camera, or [environment_state, agent_pos] (a one-line ValueError if the observation
        lacks what the policy reads)."""
        if self.cfg.reads_state:
            return state_inputs(observation, self.state_dim)
        return camera_inputs(observation, self.cfg)

    def planner_inputs(self, inputs: list[torch.Tensor]) -> list[torch.Tensor]:
        """The planner's share of the step's inputs: its cameras' images, or the states."""
        return inputs if self.planner_cams is None else [inputs[i] for i in self.planner_cams]

    def end_probabilities(self, c: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """P(the subtask has ended) per row, before the debounce."""
        return torch.sigmoid(self.model.executor.end_logit(c, z, self.events_now()))

    def _stored(self, observation: dict[str, Any], slot: _Slot) -> dict[str, Any]:
        """``observation`` with the policy's cameras through the slot's codec streams."""
        pixels = dict(observation.get("pixels") or {})
        for cam in self.cfg.cameras:
            if cam in pixels:
                pixels[cam] = slot.codecs.setdefault(cam, FrameCodec())(np.asarray(pixels[cam]))
        return {**observation, "pixels": pixels}

    def events_now(self) -> EventWindow:
        """The event window each slot's classifier reads at its current step: the one window,
        or with ``event_phases`` the window of the step's phase."""
        windows = self.event_windows
        if len(windows) == 1:
            return windows[0]
        view = EventWindow(len(self.slots), self.cfg.event_window, self.cfg.dim)
        view.entries.copy_(torch.stack([windows[s.t % len(windows)].entries[i]
                                        for i, s in enumerate(self.slots)]))
        return view

    def subtask_ended(self, inputs: list[torch.Tensor], slot: int = 0) -> None:
        """The end of ``slot``'s subtask, ``inputs`` its end frame's (one row)."""
        planner, s = self.model.planner, self.slots[slot]
        s.ends += 1
        frame = planner.embed(self.planner_inputs(inputs))
        s.keys.append((s.subtask, frame[0]))
        nxt = self.plan(frame if not self.cfg.use_key else s.first, slot)
        if nxt != self.done:
            s.subtask, s.start_subtask = nxt, True
        # the debounce is not re-armed here: the run of positives that declared this end
        # must break before another can count

    def plan(self, first: torch.Tensor, slot: int = 0) -> int:
        planner, keys_ = self.model.planner, self.slots[slot].keys
        if keys_ and self.cfg.use_key:
            keys = torch.stack([f for _, f in keys_])[None]
            text = torch.tensor([[s for s, _ in keys_]])
            valid = torch.ones(1, len(keys_), dtype=torch.bool)
        else:
            keys, text = torch.zeros(1, 0, self.cfg.dim), torch.zeros(1, 0, dtype=torch.long)
            valid = torch.zeros(1, 0, dtype=torch.bool)
        logits = planner(first, keys, text, valid)[0]
        if not keys_:
            logits[self.done] = -torch.inf  # an episode starts with a subtask
        return int(logits.argmax())
