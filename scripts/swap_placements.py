"""How a policy's swaps on blocks_ranking_try go: replays episodes (deterministic, as the
evaluation ran them) and prints each cube's lifts and set-downs with its distance to the
parking spot of the sequence's first swap and to the three slots. The slots are unmarked,
so where a set-down lands against them is what the episode record's ``row`` event cannot
say once a cube misses by more than the slot tolerance.

    .venv/bin/python scripts/swap_placements.py POLICY_SPEC [--seeds 100000 100001 ...]
        [--steps 1500]

POLICY_SPEC as for ``rmbench eval --policy`` (``act:CKPT``, ``mem0:CKPT?execute=10``).
"""

from __future__ import annotations

import argparse

import numpy as np

from rmbench.envs.registration import make
from rmbench.eval.episode import as_chunk
from rmbench.policies.registry import env_options, make_policy
from rmbench.tasks.blocks_ranking_try import PARK_OFFSET, SWAPS

LIFTED = 0.02  # m above its resting height: the cube is carried


def placements(env, policy, seed: int, steps: int) -> list[str]:
    obs, info = env.reset(seed=seed)
    u = env.unwrapped
    policy.reset(info["instruction"], {**u.spec_info, "seed": seed,
                                       "instruction": info["instruction"]})
    task = u.task
    park = task.slots[SWAPS[0][0]] + np.array([0.0, -PARK_OFFSET])
    rest = [cube.pos(task.data)[2] for cube in task.cubes]
    up = [False] * len(task.cubes)
    lines = [f"seed {seed}: slots hold colours {task.initial}; the first swap is slots "
             f"{SWAPS[0]}"]
    queue: list[np.ndarray] = []
    for step in range(1, steps + 1):
        if not queue:
            queue = list(as_chunk(policy.act(obs)))
        obs, _, terminated, truncated, info = env.step(queue.pop(0))
        for colour, cube in enumerate(task.cubes):
            xy, z = cube.pos(task.data)[:2], cube.pos(task.data)[2]
            to_slots = np.linalg.norm(task.slots - xy, axis=1) * 100
            if not up[colour] and z > rest[colour] + LIFTED:
                up[colour] = True
                lines.append(f"  {step}: colour {colour} lifted near slot "
                             f"{int(np.argmin(to_slots))}")
            elif up[colour] and task.released(cube):
                up[colour] = False
                near = int(np.argmin(to_slots))
                dx, dy = (xy - task.slots[near]) * 100
                lines.append(f"  {step}: colour {colour} set down "
                             f"{np.linalg.norm(xy - park) * 100:.1f} cm from the parking spot, "
                             f"{', '.join(f'{d:.1f}' for d in to_slots)} cm from the slots "
                             f"(slot {near} + ({dx:+.1f}, {dy:+.1f}) cm)")
        if terminated or truncated:
            lines.append(f"  {step}: episode over, success {info['is_success']}")
            break
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy")
    parser.add_argument("--seeds", type=int, nargs="+", default=list(range(100000, 100006)))
    parser.add_argument("--steps", type=int, default=1500)
    args = parser.parse_args()
    env = make("blocks_ranking_try", instructions="seen", **env_options(args.policy))
    policy = make_policy(args.policy, env)
    for seed in args.seeds:
        print("\n".join(placements(env, policy, seed, args.steps)), flush=True)


if __name__ == "__main__":
    main()
