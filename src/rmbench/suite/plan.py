"""What a benchmark table is made of: its tasks, its policy columns, the recipe every policy
trains with, and where each cell's data, checkpoint and evaluation live.

A policy column is a spec: ``mem0``, ``mem0:ABLATION[+ABLATION...]``, ``dp`` or ``act``, each
optionally ``@SEED``, the training seed (``mem0:no_key@1``; no suffix is seed 0). A column
trained with several seeds (``--train-seeds 0,1``) reads as their mean. Mem-0's
trained ablations (``no_anchor``, ``no_sliding``, ``no_memory``) train their own
checkpoint; ``no_key`` changes the planner alone, so its checkpoint is the ``mem0`` one's
executor beside a planner fitted without key frames (what its own full training writes, bit
for bit); ``gt_classifier`` changes only inference, so ``mem0:gt_classifier`` evaluates the
``mem0`` checkpoint. ``no_key`` and ``gt_classifier`` concern the planner and the subtask-end
classifier, which an M(1) task (one subtask: the goal) does not have: those columns are left
out of M(1) rows, as in the published ablation table.

Folders, per task under the table's ``OUT``::

    OUT/<task>/data                       the demonstrations (one dataset per task)
    OUT/<task>/data-copies<N>-r<reach>    with ``rendered_copies``: them and their rendered
                                          layout copies, what the policies train on
    OUT/<task>/train/<run>                a checkpoint, <run> named by spec, steps, batch, --set
                                          (and the copies)
    OUT/<task>/eval/<run>-e<episodes>     its evaluation (the harness's folder)
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from rmbench.envs.noise import NoiseSpec
from rmbench.seeds import SPLITS
from rmbench.tasks import get_task
from rmbench.tasks.registry import ordered
from rmbench.training.device import check_device
from rmbench.video_rule import keeps_video

POLICY_NAMES = ("mem0", "dp", "act")
# every column of the two tables: policies, then Mem-0's ablations. On an M(n) row
# ``no_memory`` keeps the planner's key memory; ``no_memory+no_key`` is Mem-0 with no memory of
# the past beyond the end classifier's window of recent frames, the row's memoryless control.
ALL_POLICIES = ("mem0", "mem0:no_anchor", "mem0:no_sliding", "mem0:no_memory", "dp", "act",
                "mem0:no_key", "mem0:gt_classifier", "mem0:no_memory+no_key")
M_N_ONLY = ("no_key", "gt_classifier")
OBSERVATIONS = ("state", "pixels")
# the columns ``rmbench table --obs OBS`` makes unless --policies names others: the state table
# every one; the camera table the policies and the ablations that test memory (no_anchor and
# no_sliding, which split the executor's memory in two, would cost two trainings more a row)
COLUMNS = {"state": ALL_POLICIES,
           "pixels": tuple(p for p in ALL_POLICIES
                           if p not in ("mem0:no_anchor", "mem0:no_sliding"))}
# what collection records for each observation: the state's smallest video (datasets hold at
# least one camera; nothing decodes it), or the three cameras as evaluation renders them
COLLECT_CAMERAS = {"state": (("head",), (16, 16)),
                   "pixels": (("head", "left_wrist", "right_wrist"), (320, 240))}


def split_seed(spec: str) -> tuple[str, int]:
    """``mem0:no_key@1`` -> ("mem0:no_key", 1); no suffix is training seed 0."""
    base, at, seed = spec.partition("@")
    if not at:
        return spec, 0
    if not seed.isdigit():
        raise ValueError(f"{spec}: the training seed after '@' must be a whole number")
    return base, int(seed)


def with_seed(spec: str, seed: int) -> str:
    """The spec trained with ``seed``: seed 0 carries no suffix, so its folders are the same
    whether a table asks for one seed or several."""
    return spec if seed == 0 else f"{spec}@{seed}"


def parse_policy(spec: str) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """``mem0:no_anchor+gt_classifier`` -> ("mem0", ("no_anchor",), ("gt_classifier",)): the
    policy, its trained ablations and its inference ablations (any ``@SEED`` aside). An unknown
    one is a ValueError."""
    from rmbench.policies.mem0.config import INFERENCE_ABLATIONS, TRAINED_ABLATIONS

    name, _, rest = split_seed(spec)[0].partition(":")
    if name not in POLICY_NAMES:
        raise ValueError(f"unknown policy {spec!r}; policies: {', '.join(ALL_POLICIES)}")
    ablations = tuple(a for a in rest.split("+") if a)
    if ablations and name != "mem0":
        raise ValueError(f"{spec}: only Mem-0 has ablations")
    unknown = [a for a in ablations if a not in TRAINED_ABLATIONS + INFERENCE_ABLATIONS]
    if unknown:
        raise ValueError(f"{spec}: unknown ablation {unknown[0]!r}; ablations: "
                         f"{', '.join(TRAINED_ABLATIONS + INFERENCE_ABLATIONS)}")
    return (name, tuple(a for a in ablations if a in TRAINED_ABLATIONS),
            tuple(a for a in ablations if a in INFERENCE_ABLATIONS))


def trained_spec(spec: str) -> str:
    """The spec whose checkpoint ``spec`` evaluates: ``mem0:gt_classifier@1`` -> ``mem0@1``."""
    name, trained, _ = parse_policy(spec)
    return with_seed(name + (":" + "+".join(trained) if trained else ""), split_seed(spec)[1])


def executor_spec(spec: str) -> str | None:
    """The spec whose trained executor ``spec``'s checkpoint takes (``mem0:no_key@1`` ->
    ``mem0@1``: ``no_key`` changes the planner alone), or None where it trains its own."""
    from rmbench.policies.mem0.config import PLANNER_ABLATIONS

    name, trained, _ = parse_policy(spec)
    kept = tuple(a for a in trained if a not in PLANNER_ABLATIONS)
    if kept == trained:
        return None
    return with_seed(name + (":" + "+".join(kept) if kept else ""), split_seed(spec)[1])


def applies(spec: str, tmc: str) -> bool:
    """Whether the column has a cell on a task of this TMC."""
    _, trained, inference = parse_policy(spec)
    return tmc == "M(n)" or not set(M_N_ONLY) & set(trained + inference)


def run_name(spec: str, steps: int, batch: int, sets: tuple[str, ...] | list[str] = ()) -> str:
    tag = "".join(f"-{s.replace('=', '')}" for s in sets)
    return f"{spec.replace(':', '-')}-s{steps}-b{batch}{tag}".replace("/", "_").replace('"', "")


NAME_MAX = 255  # bytes in one path component on Linux and macOS file systems


def bounded(name: str) -> str:
    """``name`` as a folder name: itself when it fits ``NAME_MAX``, else its head and a hash
    of the whole (a recipe with many ``--set`` items), so distinct names stay distinct and
    the names that always fitted do not move."""
    if len(name.encode()) <= NAME_MAX:
        return name
    digest = hashlib.sha1(name.encode()).hexdigest()[:10]
    return name.encode()[:NAME_MAX - 11].decode(errors="ignore") + "-" + digest


def policy_fields() -> dict[str, set[str]]:
    from rmbench.policies.trainable import TRAINABLE, trainable

    return {name: {f.name for f in fields(trainable(name)[0])} for name in TRAINABLE}


def target_of(item: str) -> tuple[str | None, str]:
    """``mem0.execute=20`` -> ("mem0", "execute"); ``execute=20`` -> (None, "execute")."""
    key = item.partition("=")[0]
    policy, dot, field = key.partition(".")
    return (policy, field) if dot else (None, key)


def check_sets(sets: tuple[str, ...] | list[str]) -> None:
    """Each ``--set`` is FIELD=VALUE with a field some policy's config has, or
    POLICY.FIELD=VALUE with a field of that policy's (ValueError if not)."""
    per_policy = policy_fields()
    known = set().union(*per_policy.values())
    for s in sets:
        policy, field = target_of(s)
        ok = "=" in s and (field in per_policy.get(policy, ()) if policy else field in known)
        if not ok:
            raise ValueError(f"--set {s!r}: expected FIELD=VALUE with a field of a policy's "
                             f"config, or POLICY.FIELD=VALUE (POLICY one of "
                             f"{', '.join(per_policy)}); fields: {', '.join(sorted(known))}")


def sets_for(name: str, sets: tuple[str, ...] | list[str]) -> list[str]:
    """The ``--set`` items meant for policy ``name``, as FIELD=VALUE (``rmbench train``'s
    form): FIELD=VALUE where its config has the field (the others are another policy's), and
    POLICY.FIELD=VALUE naming it."""
    return [f"{target_of(item)[1]}={item.partition('=')[2]}" for item in meant_for(name, sets)]


def meant_for(name: str, sets: tuple[str, ...] | list[str]) -> list[str]:
    """The ``--set`` items among ``sets`` meant for policy ``name``, as given: those naming
    it, and those naming no policy whose field its config has."""
    fields = policy_fields()[name]
    targets = [(item, *target_of(item)) for item in sets]
    return [item for item, policy, field in targets
            if policy == name or (policy is None and field in fields)]


def config_for(spec: str, obs: str, sets: tuple[str, ...] | list[str] = ()):
    """The config ``spec`` trains with: ``observation``, its trained ablations and the ``--set``
    items meant for it: FIELD=VALUE where its config has the field (the others are another
    policy's), and POLICY.FIELD=VALUE naming it. A value it refuses is a ValueError naming
    the policy."""
    from rmbench.policies.config import parse_overrides
    from rmbench.policies.trainable import trainable

    name, trained, _ = parse_policy(spec)
    cls, _ = trainable(name)
    mine = sets_for(name, sets)
    extra = {"ablations": trained} if trained else {}
    try:
        return cls(**{"observation": obs, **parse_overrides(cls, mine), **extra})
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} with {' '.join(mine) or 'its defaults'}: {err}") from None


def memory_of(spec: str, tmc: str, cfg) -> str:
    """What carries information across steps in this policy (``cfg``, its config), in words."""
    name, _, inference = parse_policy(spec)
    if name == "dp":
        return f"observation window only ({cfg.obs_steps} steps)"
    if name == "act":
        return "observation window only (1 step; temporal ensembling averages past chunks)"
    parts = []
    if tmc == "M(n)":
        parts.append("planner phase (subtask text" + (" + key memory)" if cfg.use_key else ")")
                     + (", simulator's subtask boundaries" if inference else ""))
    if cfg.use_anchor:
        parts.append("anchor (subtask's first step)")
    if cfg.use_sliding:
        parts.append(f"sliding window ({cfg.sliding_window} x {cfg.memory_every} steps)")
    return " + ".join(parts) or "current step only"


TABLE_EPISODES = 100  # a table's cell: its task's first 100 test episodes


@dataclass(frozen=True)
class Plan:
    """One table: every (task, policy) cell trained with the same recipe and evaluated on the
    same expert-verified seeds. Its fields name its folders, so tables with different recipes
    can share an ``OUT``."""

    obs: str
    tasks: tuple[str, ...]
    policies: tuple[str, ...] = ALL_POLICIES
    demos: int = 50
    steps: int = 3000
    batch: int = 32
    episodes: int = TABLE_EPISODES
    noise: float = 0.0
    """Action noise executed during collection (DART), radians; ``noise_kind`` white|smooth."""
    noise_kind: str = "white"
    sets: tuple[str, ...] = ()
    """``FIELD=VALUE`` overrides of every policy config that has the field (``rmbench train
    --set``), ``POLICY.FIELD=VALUE`` of one policy's (``mem0.execute=20``)."""
    task_sets: dict[str, tuple[str, ...]] = field(default_factory=dict)
    """More such items for one task's cells alone, after ``sets`` (``sets_of``): a setting
    that only that task's environment state has a use for (the state recipe's shuffle of
    observe_and_pickup's objects)."""
    video: str = "none"
    """The evaluation's videos (``rmbench eval --video``)."""
    device: str = "cpu"
    """Where the cells train (cpu, cuda, cuda:N). Like ``video``, not part of any folder's
    name: a checkpoint is the same run wherever it trained, and one started on a GPU resumes
    on a CPU."""
    rendered_copies: int = 0
    """Layout copies rendered of each demonstration (``data/layout_copies.py``): the policies
    train on the demonstrations and these copies, each scene moved by up to ``rendered_reach``
    metres in x and y. The state's ``--set layout_copies`` needs no rendering; pixels do."""
    rendered_reach: float = 0.04
    split: str = "test"
    """The evaluations' episodes: the test ones a table reports, or the validation ones a
    recipe is chosen on (``rmbench.seeds``); validation cells have folders of their own."""

    def __post_init__(self):
        if self.obs not in OBSERVATIONS:
            raise ValueError(f"obs must be one of {', '.join(OBSERVATIONS)}, got {self.obs!r}")
        if not self.tasks or not self.policies:
            raise ValueError("a table needs at least one task and one policy")
        object.__setattr__(self, "tasks", tuple(get_task(t).name for t in self.tasks))
        object.__setattr__(self, "policies", tuple(dict.fromkeys(
            with_seed(*split_seed(p)) for p in self.policies)))  # "@0" is the plain spec
        object.__setattr__(self, "sets", tuple(self.sets))
        object.__setattr__(self, "task_sets", {get_task(t).name: tuple(items)
                                               for t, items in self.task_sets.items()})
        for spec in self.policies:
            parse_policy(spec)
        if min(self.demos, self.steps, self.batch, self.episodes) < 1:
            raise ValueError("demos, steps, batch and episodes must be >= 1")
        if self.rendered_copies < 0 or not (math.isfinite(self.rendered_reach)
                                            and self.rendered_reach > 0):
            raise ValueError(f"rendered copies must be >= 0 and their reach a finite number "
                             f"> 0, got {self.rendered_copies} and {self.rendered_reach}")
        if self.split not in SPLITS:
            raise ValueError(f"split must be one of {', '.join(SPLITS)}, got {self.split!r}")
        NoiseSpec(self.noise_kind, self.noise)  # a bad kind or sigma: one line
        keeps_video(self.video, 0, True)  # (read by the evaluations, hours in: checked now)
        check_device(self.device)
        check_sets(self.sets)
        for items in self.task_sets.values():
            check_sets(items)
        for task in self.tasks:  # a config refusing a value
            for spec in {trained_spec(s) for s in self.policies}:
                self.config(task, spec)

    def sets_of(self, task: str) -> tuple[str, ...]:
        """The ``--set`` items the task's cells train with: ``sets``, then its ``task_sets``."""
        return self.sets + self.task_sets.get(task, ())

    def config(self, task: str, spec: str):
        """The config the task's ``spec`` cell trains with (its trained spec's)."""
        return config_for(trained_spec(spec), self.obs, self.sets_of(task))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Plan:
        d = {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}
        if "task_sets" in d:
            d["task_sets"] = {t: tuple(items) for t, items in d["task_sets"].items()}
        return cls(**d)

    def to_dict(self) -> dict[str, Any]:
        d = {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
        d["task_sets"] = {t: list(items) for t, items in self.task_sets.items()}
        return d

    def cells(self) -> list[tuple[str, str]]:
        """(task, spec) of every cell, tasks in the benchmark's order (M(1), then M(n))."""
        order = [t.name for t in ordered() if t.name in self.tasks]
        return [(t, s) for t in order for s in self.policies if applies(s, get_task(t).tmc)]

    def data_dir(self, out: Path, task: str) -> Path:
        """The task's demonstrations."""
        return Path(out) / task / "data"

    def _copies_tag(self) -> str:
        return f"-copies{self.rendered_copies}-r{self.rendered_reach:g}" if self.rendered_copies else ""

    def train_data_dir(self, out: Path, task: str) -> Path:
        """What the task's policies train on: the demonstrations, or with ``rendered_copies``
        the dataset of them and their copies."""
        return Path(out) / task / f"data{self._copies_tag()}"

    def copies_record(self, out: Path, task: str) -> Path:
        """Where a finished rendering of the rendered copies leaves its summary (beside their
        dataset)."""
        data = self.train_data_dir(out, task)
        return data.with_name(data.name + ".json")

    def train_dir(self, out: Path, task: str, spec: str) -> Path:
        run = run_name(trained_spec(spec), self.steps, self.batch, self.sets_of(task))
        return Path(out) / task / "train" / bounded(f"{run}{self._copies_tag()}")

    def eval_dir(self, out: Path, task: str, spec: str) -> Path:
        run = run_name(spec, self.steps, self.batch, self.sets_of(task))
        split = "" if self.split == "test" else f"-{self.split}"
        return Path(out) / task / "eval" / bounded(
            f"{run}{self._copies_tag()}-e{self.episodes}{split}")

    def eval_policy(self, out: Path, task: str, spec: str) -> str:
        """The ``--policy`` argument of the cell's evaluation."""
        name, _, inference = parse_policy(spec)
        query = f"?ablation={','.join(inference)}" if inference else ""
        return f"{name}:{self.train_dir(out, task, spec)}{query}"
