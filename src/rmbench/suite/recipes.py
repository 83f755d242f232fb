"""The recipes a table trains and evaluates with: the generic defaults, each observation's
table recipe (what ``rmbench table --obs OBS`` uses unless an option says otherwise), and the
command-line options that override them (``rmbench table``, benchmarks/learning.py)."""

from __future__ import annotations

from typing import Any

from rmbench.suite.plan import target_of
from rmbench.tasks import TASKS, get_task

# Plan's recipe fields when nothing says otherwise (benchmarks/learning.py starts from these).
GENERIC = {"demos": 50, "steps": 3000, "batch": 32, "episodes": 100, "noise": 0.0,
           "noise_kind": "white", "sets": (), "task_sets": {}, "rendered_copies": 0,
           "rendered_reach": 0.04}
# The recipe each observation's table is made with, what ``rmbench table --obs OBS`` uses
# unless an option says otherwise (``--set`` items are added after the recipe's: a later item
# for the same field wins). The state table's (docs/results/benchmark_state.md): 50
# demonstrations with DART noise, 18,000 steps at batch 128, Mem-0's head and chunk
# settings, 2 cm of noise on the mats' positions, the grasp poses as input, 16 layout copies.
# Mem-0's two M(n) settings (the event end classifier, the 12-frame key delay) are its
# config's defaults.
RECIPES = {
    "state": {**GENERIC, "steps": 18000, "batch": 128, "noise": 0.02, "sets": (
        "mem0.head_layers=2", "mem0.execute=20", "relative_actions=false",
        "mem0.action_patch=3", "state_noise=0.02", 'state_noise_on=["mat_"]',
        "grasp_pose_input=true", "layout_copies=16", "layout_shift=0.04",
        "mem0.sample_noise=0"),
        # observe_and_pickup's five table objects sit in slots drawn at random and match the
        # reference by look alone: Mem-0 trains with their slots shuffled, their colours
        # renamed and their positions also given as reach joints, the best of three probes on
        # the validation episodes though inside their noise (docs/results/benchmark_state.md,
        # "Recipe probes on the validation episodes")
        # blocks_ranking_try's executor closes its grasp beside the cube and then stands still
        # (89% of its timeouts on the validation episodes), and its planner fits 76% of its
        # training decisions in 1,500 steps: Mem-0 reads the three cubes' positions also as
        # reach joints and fits its planner 15,000 steps, chosen on the validation episodes
        # (docs/results/benchmark_state.md, "Recipe probes on the validation episodes").
        # rearrange_blocks' failures on the validation episodes are mostly timeouts carrying
        # the middle block to the empty mat: Mem-0 reads the two cubes' and two mats'
        # positions also as reach joints, chosen there (the same section).
        "task_sets": {"observe_and_pickup": (
            'mem0.shuffle_entities=["object"]', 'mem0.relabel_one_hots=["colour"]',
            'mem0.reach_input=["object0","object1","object2","object3","object4"]'),
            "blocks_ranking_try": (
            "mem0.planner_steps=15000",
            'mem0.reach_input=["cube_left","cube_middle","cube_right"]'),
            "rearrange_blocks": (
            'mem0.reach_input=["cube_left","cube_right","mat_left","mat_right"]',)}},
    # The camera table's (docs/results/benchmark_pixels.md): the same demonstrations, each
    # with 8 rendered layout copies (the scene moved up to 4 cm), the three cameras through the
    # frozen EfficientNet-Lite0 to stride 16 (features cached once per dataset), Mem-0's head
    # and chunk settings, 54,000 steps at batch 128 (docs/results/pixels.md: put_back_block
    # reached 31, 57 and 62 at 18,000, 54,000 and 90,000 steps; 54,000 is the length that
    # fits about an hour of two cores per cell).
    # On the M(n) rows Mem-0's planner, reading the head camera, fits 15,000 steps in place of
    # the 1,500 the state planner needs. Measured on press_button alone, its checkpoint's
    # planner fitted again: every decision right on 8 of 30 held-out demonstrations in place
    # of 1 (benchmarks/results/planner_keys_press_button_pixels.json), and 18 [12, 27] in
    # place of 9 [5, 16] on the validation episodes, inside their noise
    # (benchmarks/results/validation_probes.json).
    "pixels": {**GENERIC, "steps": 54000, "batch": 128, "noise": 0.02, "rendered_copies": 8,
               "rendered_reach": 0.04, "sets": (
        'backbone="efficientnet_lite0"', "backbone_stride=16", "mem0.head_layers=2",
        "mem0.execute=20", "relative_actions=false", "mem0.action_patch=3",
        "mem0.sample_noise=0"),
        "task_sets": {name: ("mem0.planner_steps=15000",)
                      for name, cls in TASKS.items() if cls.tmc == "M(n)"}},
}


def add_recipe_arguments(parser, defaults: str = "generic") -> None:
    """The command-line options of a table's recipe (``Plan``'s fields beyond its tasks and
    columns), shared by ``rmbench table`` and benchmarks/learning.py; an option left out takes
    its value from ``recipe_of``'s defaults (``defaults`` says which, for the help)."""
    where = ("the --obs recipe's (rmbench.suite.recipes.RECIPES)" if defaults == "recipe"
             else "default")
    parser.add_argument("--demos", type=int, help=f"demonstrations per task ({where}: 50)")
    parser.add_argument("--steps", type=int, help=f"training steps ({where})")
    parser.add_argument("--batch", type=int, help=f"training batch size ({where})")
    parser.add_argument("--episodes", type=int, help=f"evaluation episodes per cell ({where}: 100)")
    parser.add_argument("--noise", type=float,
                        help=f"action noise executed during collection (DART), radians ({where})")
    parser.add_argument("--noise-kind", choices=("white", "smooth"),
                        help=f"({where}: white)")
    parser.add_argument("--set", action="append", default=[], metavar="[POLICY.]FIELD=VALUE",
                        help="override every policy config that has the field, or POLICY's "
                             "alone (mem0.execute=20); VALUE as JSON; repeatable; added after "
                             f"the {where.removeprefix('the ')} items")
    parser.add_argument("--task-set", action="append", default=[],
                        metavar="TASK:[POLICY.]FIELD=VALUE",
                        help="as --set, for TASK's cells alone (observe_and_pickup:mem0.execute=10); "
                             "repeatable; added after that task's recipe items")
    parser.add_argument("--rendered-copies", type=int, metavar="N",
                        help="train on each demonstration and N rendered copies of it with the "
                             "scene moved (`rmbench dataset copy-layouts`; the pixel track's "
                             "counterpart of --set layout_copies)")
    parser.add_argument("--rendered-reach", type=float, metavar="METRES",
                        help="with --rendered-copies: the largest move along each table axis "
                             "(default 0.04)")


def recipe_of(args, defaults: dict[str, Any] | None = None) -> dict[str, Any]:
    """``Plan``'s recipe fields from the options ``add_recipe_arguments`` added, each option
    left out taken from ``defaults`` (``GENERIC`` unless given; ``RECIPES[obs]`` for a
    table), its ``--set`` items after those of the defaults' that set other fields."""
    base = GENERIC if defaults is None else defaults
    given = {"demos": args.demos, "steps": args.steps, "batch": args.batch,
             "episodes": args.episodes, "noise": args.noise, "noise_kind": args.noise_kind,
             "rendered_copies": args.rendered_copies, "rendered_reach": args.rendered_reach}
    recipe = {k: base[k] if v is None else v for k, v in given.items()}
    # a recipe item whose field an option sets again gives way to it, so that a command that
    # spells the whole recipe out names the folders it always named
    everywhere = {target_of(item) for item in args.set}
    per_task = task_items(args.task_set)
    task_sets = {}
    for task in dict.fromkeys([*base.get("task_sets", {}), *per_task]):
        own = per_task.get(task, ())
        task_sets[task] = overridden(base.get("task_sets", {}).get(task, ()), own, everywhere)
    return {**recipe, "sets": overridden(base["sets"], tuple(args.set)),
            "task_sets": {task: items for task, items in task_sets.items() if items}}


def overridden(recipe: tuple[str, ...], given: tuple[str, ...],
               also: set = frozenset()) -> tuple[str, ...]:
    """``recipe``'s items without those whose field ``given`` (or ``also``) sets, then
    ``given``."""
    replaced = set(also) | {target_of(item) for item in given}
    return tuple(item for item in recipe if target_of(item) not in replaced) + given


def task_items(given: list[str]) -> dict[str, tuple[str, ...]]:
    """``--task-set`` items (``TASK:ITEM``, TASK a name or gym id) grouped by the task's
    registered name: a one-line ValueError for an item without a task, UnknownTaskError for a
    task that does not exist."""
    out: dict[str, tuple[str, ...]] = {}
    for text in given:
        task, sep, item = text.partition(":")
        if not sep or not item:
            raise ValueError(f"--task-set wants TASK:[POLICY.]FIELD=VALUE, got {text!r}")
        name = get_task(task.strip()).name
        out[name] = out.get(name, ()) + (item.strip(),)
    return out
