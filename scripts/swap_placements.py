"""How a policy's swaps on blocks_ranking_try go: replays episodes through the evaluation's
own episode loop (deterministic, so the very episodes of the records) and prints each cube's
lifts and set-downs with its distance to the parking spot of the sequence's first swap and
to the three slots. The slots are unmarked, so where a set-down lands against them is what
the episode record's ``row`` event cannot say once a cube misses by more than the slot
tolerance.

    .venv/bin/python scripts/swap_placements.py POLICY_SPEC [--seeds 100000 100001 ...]

POLICY_SPEC as for ``rmbench eval --policy`` (``act:CKPT``, ``mem0:CKPT?execute=10``).
"""

from __future__ import annotations

import argparse

import numpy as np

from rmbench.envs.registration import make
from rmbench.eval.episode import run_policy_episode
from rmbench.policies.registry import env_options, make_policy
from rmbench.sim.station import TABLE_TOP
from rmbench.tasks.blocks_ranking_try import PARK_OFFSET, SWAPS

LIFTED = 0.02  # m above its resting height: the cube is carried


def placements(env, policy, seed: int) -> list[str]:
    task = env.unwrapped.task
    lines: list[str] = []
    up = [False] * len(task.cubes)

    def watch(step: int, info: dict) -> None:
        park = task.slots[SWAPS[0][0]] + np.array([0.0, -PARK_OFFSET])
        for colour, cube in enumerate(task.cubes):
            carried = cube.pos(task.data)[2] > TABLE_TOP + cube.rest_height + LIFTED
            lifted, set_down = not up[colour] and carried, up[colour] and task.released(cube)
            if not (lifted or set_down):
                continue
            up[colour] = lifted
            xy = cube.pos(task.data)[:2]
            to_slots = np.linalg.norm(task.slots - xy, axis=1) * 100
            near = int(np.argmin(to_slots))
            if lifted:
                lines.append(f"  {step}: colour {colour} lifted near slot {near}")
            else:
                dx, dy = (xy - task.slots[near]) * 100
                lines.append(f"  {step}: colour {colour} set down "
                             f"{np.linalg.norm(xy - park) * 100:.1f} cm from the parking spot, "
                             f"{', '.join(f'{d:.1f}' for d in to_slots)} cm from the slots "
                             f"(slot {near} + ({dx:+.1f}, {dy:+.1f}) cm)")

    record = run_policy_episode(env, policy, seed, on_step=watch)
    return [f"seed {seed}: slots hold colours {task.initial}; the first swap is slots "
            f"{SWAPS[0]}", *lines, f"  {record['steps']}: {record['reason']}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(100000, 100006)))
    args = parser.parse_args()
    env = make("blocks_ranking_try", instructions="seen", **env_options(args.policy))
    policy = make_policy(args.policy, env)
    for seed in args.seeds:
        print("\n".join(placements(env, policy, seed)), flush=True)


if __name__ == "__main__":
    main()
