"""Mem-0's settings: one frozen dataclass, stored in every checkpoint."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, ClassVar

from rmbench.policies.action_space import action_dim
from rmbench.policies.config import PolicyConfig
from rmbench.policies.observation import ReadsObservation, check_observation

# Ablations that change what is trained (a checkpoint is trained with them) and those that
# only change inference (any checkpoint can run them).
TRAINED_ABLATIONS = ("no_anchor", "no_sliding", "no_memory", "no_key")
INFERENCE_ABLATIONS = ("gt_classifier",)
# Trained ablations that change the planner alone: the executor trains the same computation
# without them (the planner is fitted first, frozen, and read by no executor loss), so such a
# checkpoint can pair the executor of the one without them with a planner fitted anew.
PLANNER_ABLATIONS = ("no_key",)
ABLATIONS = TRAINED_ABLATIONS + INFERENCE_ABLATIONS
END_CLASSIFIERS = ("event", "context")


@dataclass(frozen=True)
class Mem0Config(ReadsObservation, PolicyConfig):
    """Mem-0's settings, every field documented; the defaults are the CPU-sized model."""

    # changeable at evaluation without retraining: mem0:CKPT?execute=5&flow_steps=20
    INFERENCE_FIELDS: ClassVar[tuple[str, ...]] = ("execute", "flow_steps", "sample_noise",
                                                   "temporal_ensemble", "ensemble_every",
                                                   "event_phases", "codec_frames")
    # checkpoints written before these fields existed trained the "context" classifier and
    # their planner on the end frames themselves
    ABSENT_MEANS: ClassVar[dict[str, Any]] = {"end_classifier": "context", "planner_key_delay": 0}

    # --- observation
    observation: str = "auto"
    """What the policy reads. "pixels": the cameras below, each through its own CNN. "state":
    observation.environment_state (normalised with the dataset's statistics) and the joint
    state through an MLP (``state_tokens`` tokens of width ``dim``, in place of the camera
    tokens: the anchor holds them, the sliding memory their mean, the planner its own state
    embedding of o_0 and of the key frames); evaluation then runs the env with
    obs_type="environment_state_agent_pos". "auto" (the default) is settled by training from
    the dataset: "pixels" if it has camera videos, else "state"; ask for the state of a dataset
    with videos with --set observation=state. The checkpoint stores the choice (one from
    before this field reads as pixels)."""
    state_tokens: int = 2
    """With observation "state": tokens per step (the anchor's slots, as cameras are with pixels)."""
    state_hidden: int = 256
    """With observation "state": hidden width of the state encoder's two layers."""
    reach_input: tuple[str, ...] = ()
    """With observation "state": positions of the environment state (the names before
    ``_x`` / ``_y``, e.g. "cube") the encoder also reads as both arms' joints for a top-down
    grasp there (``sim.kinematics.ReachGrid``): where an object is, in the joint targets'
    terms. The anchor then holds, from the first frame, the joints that reach where the
    object was."""
    cameras: tuple[str, ...] = ("head", "left_wrist", "right_wrist")
    """Cameras the executor reads, each through its own CNN."""
    image_size: tuple[int, int] = (96, 128)
    """(height, width) the frames are resized to (4:3 like the 320x240 recordings)."""
    # --- encoder
    dim: int = 128
    """Width of every token: z_img, z_text, memory entries, the action head."""
    encoder_channels: tuple[int, ...] = (32, 64, 128, 128)
    """CNN stage widths; each stage halves the resolution. With a frozen ``backbone`` the last
    is the width of the heads over its features."""
    keypoints: int = 32
    """Spatial-softmax keypoints per camera, pooled beside the channel mean."""
    # --- memory
    sliding_window: int = 8
    """K: sliding memory holds the last K z_img."""
    memory_every: int = 5
    """z_img enters the sliding memory every this many control steps (at 20 Hz, K=8 spans 2 s);
    training walks each episode with this stride so it sees the memory inference builds. In
    the closed loop each phase of the stride keeps its own anchor and window, so a chunk drawn
    at any step reads a newest entry one stride old, as in training."""
    memory_noise: float = 0.0
    """With observation "state", training only: N(0, sigma) metres more on the environment
    state's positions in what enters the memories (the anchor and the sliding window), the
    current step's input unchanged. The memories then say which layout the episode began in
    only to about sigma, while the current step keeps what a grasp needs to the millimetre."""
    memory_noise_on: tuple[str, ...] = ()
    """Name prefixes of the position entries ``memory_noise`` applies to (empty: all of them),
    e.g. ("cube_",)."""
    heads: int = 4
    """Attention heads in the memory fusion and the action head."""
    # --- action head
    horizon: int = 30
    """H: actions predicted per chunk."""
    execute: int = 10
    """D: actions executed from each chunk before predicting again (1 <= D <= H)."""
    head_layers: int = 4
    """Transformer layers of the flow-matching action head."""
    action_patch: int = 1
    """Consecutive actions per action-head token (H / action_patch tokens): the head's cost
    falls with its token count."""
    relative_actions: bool = True
    """Joint targets as offsets from the current joint positions, grippers absolute (as openpi
    does for ALOHA): holding still is the zero prediction. False: absolute targets. From the
    state observation on put_back_block absolute targets did better once trained long enough
    (docs/history.md): a grasp pose is a function of the cube's pose alone, an
    offset to it changes at every step of the approach."""
    action_space: str = "joints"
    """What the action head predicts: "joints", the env's 14 joint targets, or "ee", each
    grasp site's target pose (position and 6D rotation) and the gripper, turned into joint
    targets by inverse kinematics at run time (policies/action_space.py); "ee" needs
    relative_actions false."""
    flow_steps: int = 10
    """Euler integration steps when sampling a chunk."""
    sample_noise: float = 1.0
    """Scale of the noise a chunk's sampling starts from: 1 draws from the distribution the
    head was trained on; below 1 leans towards the most likely chunk (0: deterministic)."""
    temporal_ensemble: float = 0.0
    """m > 0: ACT's temporal ensembling (policies/ensemble.py) in place of ``execute``: a chunk
    every ``ensemble_every`` steps, and each step's action the mean of every chunk's
    prediction for it weighted exp(-m i), i = 0 the oldest. 0: off."""
    ensemble_every: int = 1
    """With temporal_ensemble: steps between chunks (1 as in ACT; more costs less inference
    and averages fewer predictions)."""
    # --- end classifier
    end_classifier: str = "event"
    """What the subtask-end classifier reads and learns. "event": the current z_img and the
    event window (the last ``event_window`` z_img at the memory stride, kept across subtasks),
    positive on the frames just after each plan step ends (``end_span``): it detects that a
    step has ended from what changed. "context": the publication's MLP on c_t, positive on the
    last L frames of each subtask: it predicts the end before it happens, and c_t's sliding
    memory fills with the subtask's age, so a classifier on it can learn a clock (measured on
    press_button: it fired a median 32 steps before each push when the policy was slower
    than the demonstrations)."""
    event_window: int = 4
    """With end_classifier "event": z_img entries in the event window (4 at stride 5: 1 s)."""
    codec_frames: bool = False
    """Camera policies, in the closed loop: each camera's frames pass through the dataset codec
    (``video.FrameCodec``, one stream per episode) before they are read, near the frames the
    policy trained on as stored (not equal: the stream runs without the stored one's B-frames
    and lookahead); off, it reads them as rendered."""
    event_phases: bool = False
    """With end_classifier "event", in the closed loop: one event window per phase of the
    memory stride, each step's frame entering its phase's, and the classifier reading the
    window of the current step's phase, so that its entries are always 1, 2, ... strides old,
    as in training (which walks each episode at the stride). Off: one window, filled every
    ``memory_every`` steps and read at every step, its newest entry 0 to ``memory_every`` - 1
    steps old."""
    end_window: int = 8
    """L: a subtask ends after L consecutive positive steps. With end_classifier "context" the
    last L frames of each subtask are the positives; with "event" the ``end_span`` frames
    after each step's end."""
    end_threshold: float = 0.5
    classifier_weight: float = 1.0
    """Weight of the end classifier's loss beside the action loss."""
    classifier_trains_encoder: bool = False
    """Whether the end classifier's loss reaches the encoders and memory fusions through c_t.
    Off: the classifier reads c_t detached and learns on the features the action loss shapes.
    Its loss is positive-weighted up to 50x (a subtask's last L frames are few) and, measured
    early in training on battery_try, its gradient on the encoder was ~12x the action loss's."""
    # --- planner
    planner_backend: str = "small"
    """"small": the CPU planner (planner.py); "vlm": a language model with LoRA over the key
    memory (planner_vlm.py, the rmbench[vlm] extra)."""
    vlm_model: str = ""
    """For the vlm backend: a local Hugging Face causal-LM folder; empty = a tiny random Llama
    (tests only)."""
    vlm_lora_rank: int = 8
    planner_cameras: tuple[str, ...] = ("head",)
    """Cameras the planner sees for o_0 and the key memory's end frames."""
    planner_layers: int = 2
    planner_steps: int = 1500
    planner_batch: int = 16
    planner_lr: float = 1e-4
    planner_key_delay: int = 12
    """Training draws each key frame (and, with no_key, the decision frame) up to this many
    frames after its step's end, uniformly: at run time a key is the frame the end
    classifier declared the end at, up to ``end_span`` steps after the simulator counted it.
    0: the end frame itself (measured on press_button's demonstrations: with keys 2-12
    frames late, that planner got 13-36 of 50 episodes' decisions all right, against 47-49
    with the delay: benchmarks/results/planner_keys_press_button.json)."""
    # --- optimisation (the shared loop's TrainConfig holds steps, batch, clip, decay)
    lr_head: float = 1e-3
    """Heads, fusion and classifier. The published 1e-4 (min 5e-6) goes with batch 448 for 30k
    steps; at CPU scale (batch 32, a few thousand steps) 1e-3 was measured to fit: on 50
    put_back_block demonstrations, 1500 steps reached flow loss 0.049 and an open-loop error
    below holding still (0.047 vs 0.052 rad), where 1e-4 reached 0.20 and 0.114."""
    min_lr_head: float = 1e-5
    lr_backbone: float = 1e-3
    """CNN encoders, trained from scratch (published 1e-5 is for a pretrained backbone); with
    a frozen ``backbone``, the heads over its features."""
    min_lr_backbone: float = 1e-5
    ema: bool = False
    """Export the exponential moving average of the executor's weights (Diffusion Policy's
    warm-up, nn/ema.py) instead of the last step's."""
    ema_power: float = 0.75
    ema_max_decay: float = 0.9999
    jitter: tuple[float, float, float] = (0.1, 0.1, 0.1)
    """Colour jitter (brightness, contrast, saturation) in training; hue is not jittered.
    None with a frozen ``backbone`` (its features are cached once per frame)."""
    # --- ablations
    ablations: tuple[str, ...] = ()
    """Any of no_anchor, no_sliding, no_memory, no_key (trained) and gt_classifier (inference).
    no_memory turns off the executor's two memories; on an M(n) task the planner's key memory
    and the event end classifier's window (its last ``event_window`` frames) stay."""

    def __post_init__(self):
        super().__post_init__()
        unknown = set(self.ablations) - set(ABLATIONS)
        if unknown:
            raise ValueError(f"unknown ablation {sorted(unknown)}; ablations: {', '.join(ABLATIONS)}")
        if self.planner_backend not in ("small", "vlm"):
            raise ValueError(f"planner_backend must be 'small' or 'vlm', got {self.planner_backend!r}")
        check_observation(self.observation)
        if self.state_tokens < 1 or self.state_hidden < 1:
            raise ValueError("state_tokens and state_hidden must be >= 1")
        if not self.cameras and not self.reads_state:
            raise ValueError("Mem-0 needs at least one camera")
        if not set(self.planner_cameras) <= set(self.cameras):
            raise ValueError(f"planner cameras {self.planner_cameras} must be among {self.cameras}")
        if not 1 <= self.execute <= self.horizon:
            raise ValueError(f"execute (D={self.execute}) must be in [1, horizon={self.horizon}]")
        if self.heads < 1 or self.dim % self.heads:
            raise ValueError(f"dim {self.dim} must be divisible by heads {self.heads} (>= 1)")
        if self.action_patch < 1 or self.horizon % self.action_patch:
            raise ValueError(f"action_patch ({self.action_patch}) must be >= 1 and divide the "
                             f"horizon ({self.horizon})")
        action_dim(self.action_space)  # a one-line error for an unknown space
        if self.reach_input and self.observation == "pixels":
            raise ValueError("reach_input is read by the state encoder: it needs observation "
                             "'state'")
        if self.sample_noise < 0:
            raise ValueError(f"sample_noise must be >= 0, got {self.sample_noise}")
        if not self.memory_noise >= 0:
            raise ValueError(f"memory_noise must be >= 0, got {self.memory_noise}")
        if self.memory_noise > 0 and not self.reads_state:
            raise ValueError("memory_noise blurs the environment state: it needs observation "
                             "'state'")
        if self.temporal_ensemble < 0:
            raise ValueError("temporal_ensemble must be >= 0 (0 turns it off)")
        if not 1 <= self.ensemble_every <= self.horizon:
            raise ValueError(f"ensemble_every ({self.ensemble_every}) must be in [1, "
                             f"horizon={self.horizon}]")
        if self.action_space != "joints" and self.relative_actions:
            raise ValueError(f"relative_actions are offsets from the joints: with action_space "
                             f"{self.action_space!r} set relative_actions=false")
        if self.end_classifier not in END_CLASSIFIERS:
            raise ValueError(f"end_classifier must be one of {END_CLASSIFIERS}, got "
                             f"{self.end_classifier!r}")
        for name in ("sliding_window", "memory_every", "end_window", "flow_steps", "head_layers",
                     "event_window"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1")
        if self.planner_key_delay < 0:
            raise ValueError("planner_key_delay must be >= 0")

    @property
    def end_span(self) -> int:
        """With end_classifier "event": frames labelled positive after each step's end, 1.5 L.
        Longer than L, so one missed frame still leaves L in a row; shorter than 2 L, so the
        debounce, reset when it fires, cannot declare the same end twice."""
        return self.end_window + self.end_window // 2

    @property
    def action_dim(self) -> int:
        return action_dim(self.action_space)

    @property
    def use_anchor(self) -> bool:
        return not {"no_anchor", "no_memory"} & set(self.ablations)

    @property
    def use_sliding(self) -> bool:
        return not {"no_sliding", "no_memory"} & set(self.ablations)

    @property
    def use_key(self) -> bool:
        return "no_key" not in self.ablations

    @property
    def gt_classifier(self) -> bool:
        return "gt_classifier" in self.ablations

    def trained_ablations(self) -> tuple[str, ...]:
        return tuple(a for a in self.ablations if a in TRAINED_ABLATIONS)

    def executor_config(self) -> Mem0Config:
        """This config without its planner-only ablations: the one whose executor this one
        trains, step for step."""
        return replace(self, ablations=tuple(a for a in self.ablations
                                             if a not in PLANNER_ABLATIONS))
