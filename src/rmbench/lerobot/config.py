"""The ``rmbench`` environment of LeRobot: ``lerobot-eval --env.type=rmbench``.

LeRobot's way to add a benchmark (as LIBERO and Meta-World are added): an ``EnvConfig``
subclass registered under a name, whose ``package_name`` ``make_env`` imports (registering
the gym ids, ``env.py``) before ``gym.make(gym_id, **gym_kwargs)``, and whose ``features`` /
``features_map`` say what the env's observation holds and under which of LeRobot's names: the
same names an rmbench dataset's ``meta/info.json`` declares (``observation.images.<camera>``,
``observation.state``, ``observation.environment_state``, ``action``), so a policy trained by
``lerobot-train`` on an rmbench dataset reads the env as it read the dataset. LeRobot's own
observation preprocessing already reads gym-aloha's layout, which rmbench's is: no extra
processor step is needed.

Load it with ``--env.discover_packages_path=rmbench.lerobot`` (LeRobot imports the package
and its modules before it parses ``--env.type``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from rmbench.envs.env import OBS_TYPES
from rmbench.lerobot.env import NAMESPACE
from rmbench.sim.simulator import ACTION_DIM
from rmbench.tasks import get_task


@EnvConfig.register_subclass("rmbench")
@dataclass
class RMBenchEnv(EnvConfig):
    task: str | None = "put_back_block"
    fps: int = 20  # rmbench's control rate
    # every dataset rmbench collects holds the state vector, which LeRobot's policies read
    obs_type: str = "pixels_environment_state_agent_pos"
    cameras: str = "head,left_wrist,right_wrist"  # comma-separated, as on the command line
    observation_width: int = 320
    observation_height: int = 240
    eval_seed: int = 0  # LeRobot's episode seed k runs this evaluation seed's k-th layout
    instructions: str = "seen"  # or "unseen": the held-out phrasings
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"obs_type must be one of {OBS_TYPES}, got {self.obs_type!r}")
        cls = get_task(self.task or "")
        self.task = cls.name
        self.features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(ACTION_DIM,)),
                         "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(ACTION_DIM,))}
        self.features_map = {ACTION: ACTION, "agent_pos": OBS_STATE}
        if "environment_state" in self.obs_type:
            self.features["environment_state"] = PolicyFeature(
                type=FeatureType.ENV, shape=(len(cls.state_names),))
            self.features_map["environment_state"] = OBS_ENV_STATE
        if self.obs_type.startswith("pixels"):
            for cam in self.camera_names:
                self.features[f"pixels/{cam}"] = PolicyFeature(
                    type=FeatureType.VISUAL,
                    shape=(self.observation_height, self.observation_width, 3))
                self.features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"

    @property
    def camera_names(self) -> tuple[str, ...]:
        return tuple(c.strip() for c in self.cameras.split(",") if c.strip())

    @property
    def package_name(self) -> str:
        return "rmbench.lerobot.env"

    @property
    def gym_id(self) -> str:
        return f"{NAMESPACE}/{self.task}"

    @property
    def gym_kwargs(self) -> dict:
        return {"obs_type": self.obs_type, "cameras": self.camera_names,
                "width": self.observation_width, "height": self.observation_height,
                "eval_seed": self.eval_seed, "instructions": self.instructions,
                "render_mode": self.render_mode}
