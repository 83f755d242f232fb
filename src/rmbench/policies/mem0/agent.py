"""``--policy mem0:CKPT[?ablation=A,B]``: Mem-0's closed loop.

Every step: encode the frames (through the frozen backbone first, for a checkpoint trained
with one), or for a checkpoint trained on the state the observation's ``environment_state``
and ``agent_pos``; at a subtask's first step the anchor is set and the sliding window emptied;
c_t from the memories; a new chunk of H actions when the last D are used (or, with temporal
ensembling, every few steps, averaged over the chunks that overlap); the end classifier's
debounced verdict (or, with gt_classifier, the simulator's subtask boundary).
When a subtask ends its text and end frame go to key memory and the planner names the next
one. M(1) tasks run as one subtask, the goal: no planner, no classifier.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from rmbench.policies.action_space import EEActions
from rmbench.policies.base import BasePolicy
from rmbench.policies.checkpoint import CheckpointError, check_task, load_weights, read_config
from rmbench.policies.config import parse_argument
from rmbench.policies.ensemble import TemporalEnsemble
from rmbench.policies.mem0.classifier import Debounce
from rmbench.policies.mem0.config import TRAINED_ABLATIONS, Mem0Config
from rmbench.policies.mem0.memory import EventWindow, MemoryStore
from rmbench.policies.mem0.planner import DONE
from rmbench.policies.mem0.train import build_model, goal_text
from rmbench.policies.nn.inference import inference
from rmbench.policies.observation import camera_inputs, state_inputs, state_tensor


def load_mem0(path: str | Path, ablations: tuple[str, ...] = (),
              overrides: dict[str, Any] | None = None):
    """(model, config, describe) from a checkpoint; inference ablations added and inference
    fields (``Mem0Config.INFERENCE_FIELDS``) overridden."""
    describe = read_config(path, "mem0")
    cfg = Mem0Config.from_dict(describe["config"])
    missing = [a for a in ablations if a in TRAINED_ABLATIONS and a not in cfg.ablations]
    if missing:
        raise CheckpointError(f"{path} was trained without {missing[0]}, which changes training: "
                              f"rmbench train mem0 --ablation {missing[0]}")
    try:
        cfg = replace(cfg, ablations=tuple(dict.fromkeys(cfg.ablations + ablations)),
                      **(overrides or {}))
    except (TypeError, ValueError) as err:
        raise CheckpointError(f"{path}: {err}") from None
    model = build_model(cfg, describe)
    load_weights(path, model, describe["step"])
    model.eval()
    return model, cfg, describe


class Mem0Policy(BasePolicy):
    """A Mem-0 checkpoint in the closed loop: each 20 Hz step's observation in, one 14-d joint
    target out. It keeps the memories across the episode and, on an M(n) task, the planner's
    current subtask (``status()``), which moves on when the end classifier says it has ended."""

    def __init__(self, arg: str, env=None):
        path, overrides, options = parse_argument(arg, Mem0Config, extra=("ablation",))
        ablations = tuple(a for a in options.get("ablation", "").split(",") if a)
        model, cfg, describe = load_mem0(path, ablations, overrides)
        check_task(path, describe, env)
        self._setup(model, cfg, describe, env)

    @classmethod
    def from_model(cls, model, describe: dict[str, Any], env=None) -> Mem0Policy:
        """A policy around an in-memory model (benchmarks, notebooks)."""
        policy = cls.__new__(cls)
        policy._setup(model.eval(), model.cfg, describe, env)
        return policy

    def _setup(self, model, cfg: Mem0Config, describe: dict[str, Any], env) -> None:
        self.model, self.cfg, self.describe = model, cfg, describe
        # the cameras it reads: none for a state checkpoint (its env need not render)
        self.cameras = () if cfg.reads_state else cfg.cameras
        self.state_dim = len(describe.get("state_names") or ())
        self.env = env.unwrapped if env is not None else None
        if self.cfg.gt_classifier and self.env is None:
            raise ValueError("gt_classifier reads the simulator's subtask boundary: it cannot be "
                             "served remotely")
        self.ee = EEActions() if cfg.action_space == "ee" else None
        self.decompose = self.describe["tmc"] == "M(n)"
        self.goal = self.describe["executor_texts"].index(goal_text(self.describe["task"]))
        self.done = self.describe["planner_texts"].index(DONE)
        self.planner_cams = (None if cfg.reads_state else
                             [cfg.cameras.index(c) for c in cfg.planner_cameras])
        self.reset("", {})

    # ----------------------------------------------------------------- interface
    def reset(self, instruction: str, task_info: dict[str, Any]) -> None:
        cfg = self.cfg
        self.generator = torch.Generator().manual_seed(int(task_info.get("seed", 0)))
        self.memory = MemoryStore(1, cfg.step_tokens, cfg.sliding_window, cfg.dim)
        self.events = EventWindow(1, cfg.event_window, cfg.dim)
        self.debounce = Debounce(cfg.end_window)
        self.t = 0
        self.subtask_t = 0  # steps since the subtask began: the sliding window's phase
        self.queue: list[np.ndarray] = []
        self.ensemble = TemporalEnsemble(cfg.horizon, cfg.temporal_ensemble)
        self.next_chunk_at = 0  # with temporal ensembling: the step the next chunk is due
        self.first: torch.Tensor | None = None  # planner embedding of o_0
        self.keys: list[tuple[int, torch.Tensor]] = []
        self.subtask = self.goal
        self.start_subtask = True
        self.stage = 0
        self.ends = 0  # subtask ends declared this episode (eval/boundaries.py reads them)

    @inference
    def act(self, observation: dict[str, Any]) -> np.ndarray:
        """One control step: the observation in, the next 14-d joint target out. A new chunk is
        sampled when the last one's ``execute`` actions are used up (with temporal ensembling,
        every ``ensemble_every`` steps)."""
        cfg, ex = self.cfg, self.model.executor
        inputs = self.inputs(observation)
        tokens, z = ex.encode(inputs)
        if self.t == 0:
            self.events.reset(torch.ones(1, dtype=torch.bool), z)
            if self.decompose:
                self.first = self.model.planner.embed(self.planner_inputs(inputs))
                self.subtask = self.plan(self.first)
        elif self.decompose and cfg.gt_classifier and self.env.subtask_stage > self.stage:
            # The simulator counts the step done after the action that did it: this frame is
            # the next step's first, as in the demonstrations' labels.
            self.stage = self.env.subtask_stage
            self.subtask_ended(inputs)
        if self.start_subtask:
            self.memory.reset(torch.ones(1, dtype=torch.bool), tokens)
            self.queue, self.start_subtask, self.next_chunk_at = [], False, self.t
            self.subtask_t = 0
            self.ensemble.reset()  # a new subtask's chunks do not average with the last one's
        c = ex.context(z, self.memory, torch.tensor([self.subtask]))
        # Training walks each subtask from its first frame with this stride and pushes every
        # frame it visits; the window here is filled on the same phase.
        if self.subtask_t % cfg.memory_every == 0:
            self.memory.push(z)
        if cfg.temporal_ensemble > 0:
            if self.t >= self.next_chunk_at:
                self.ensemble.add(self.t, self.chunk(c, observation, cfg.horizon))
                self.next_chunk_at = self.t + cfg.ensemble_every
            action = self.ensemble.action(self.t)
        else:
            if not self.queue:
                self.queue = list(self.chunk(c, observation, cfg.execute))
            action = self.queue.pop(0)
        if self.decompose and not cfg.gt_classifier and self.ended(c, z):
            self.subtask_ended(inputs)
        # The event window is filled on the episode's phase, as training walks it: the
        # classifier compares each step with the last entries, whichever subtask wrote them.
        if self.t % cfg.memory_every == 0:
            self.events.push(z)
        self.t += 1
        self.subtask_t += 1
        return action

    def status(self) -> dict[str, Any]:
        """The subtask the executor is on (an M(n) task's planner choice; the goal on M(1))
        and how many subtask ends it has declared."""
        return {"subtask": self.describe["executor_texts"][self.subtask], "subtask_ends": self.ends}

    # ------------------------------------------------------------------ helpers
    def chunk(self, c: torch.Tensor, observation: dict[str, Any], length: int) -> np.ndarray:
        """The first ``length`` joint targets of a chunk sampled from context c."""
        ex, cfg = self.model.executor, self.cfg
        state = state_tensor(observation)
        normalised = ex.head.sample(ex.condition(c, state), cfg.flow_steps, self.generator,
                                    cfg.sample_noise)
        chunk = ex.normalizer.unaction(normalised, state)[0, :length].double().numpy()
        if self.ee is not None:  # grasp poses -> joint targets
            chunk = self.ee.to_joints(chunk, np.asarray(observation["agent_pos"], np.float64))
        return chunk

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

    def ended(self, c: torch.Tensor, z: torch.Tensor) -> bool:
        """The end classifier's debounced verdict on this step."""
        p = torch.sigmoid(self.model.executor.end_logit(c, z, self.events))[0].item()
        return self.debounce.update(p > self.cfg.end_threshold)

    def subtask_ended(self, inputs: list[torch.Tensor]) -> None:
        planner = self.model.planner
        self.ends += 1
        frame = planner.embed(self.planner_inputs(inputs))
        self.keys.append((self.subtask, frame[0]))
        nxt = self.plan(frame if not self.cfg.use_key else self.first)
        if nxt != self.done:
            self.subtask, self.start_subtask = nxt, True
        # the debounce is not re-armed here: the run of positives that declared this end
        # must break before another can count

    def plan(self, first: torch.Tensor) -> int:
        planner = self.model.planner
        if self.keys and self.cfg.use_key:
            keys = torch.stack([f for _, f in self.keys])[None]
            text = torch.tensor([[s for s, _ in self.keys]])
            valid = torch.ones(1, len(self.keys), dtype=torch.bool)
        else:
            keys, text = torch.zeros(1, 0, self.cfg.dim), torch.zeros(1, 0, dtype=torch.long)
            valid = torch.zeros(1, 0, dtype=torch.bool)
        logits = planner(first, keys, text, valid)[0]
        if not self.keys:
            logits[self.done] = -torch.inf  # an episode starts with a subtask
        return int(logits.argmax())
