"""Open-loop action error: a policy walked through recorded demonstrations, each step fed the
recorded observation, its action compared with the recorded one.

It separates "has not fitted the demonstrations" from "fitted them but drifts in closed loop"
when a success rate is zero. The policy runs its own closed-loop code (observation window,
memory, chunk queue), so the error covers what ``rmbench eval`` runs. The reference is holding
the current joint positions (the noop policy), which a fitted policy should beat by far.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rmbench.data import layout as L
from rmbench.data.reader import Dataset
from rmbench.data.torch_dataset import DemoDataset
from rmbench.envs.registration import make
from rmbench.policies.registry import env_options, make_policy, policy_cameras, reads_simulator


def open_loop_error(spec: str, dataset: str, episodes: list[int]) -> dict[str, Any]:
    """Mean absolute difference (joints in rad, grippers in the action space's units) between
    the policy's action and the recorded one at every frame of ``episodes``, and the same for holding still.
    The policy is built for an env of the dataset's task that renders nothing (the recorded
    frames are what it reads), so one that reads the simulator is refused."""
    ds = Dataset(dataset)
    bad = [e for e in episodes if not 0 <= e < ds.num_episodes]
    if bad:
        raise ValueError(f"episode {bad[0]} is not in {dataset} ({ds.num_episodes} episodes)")
    if reads_simulator(spec):
        raise ValueError(f"{spec} reads the simulator, which open-loop does not run: it feeds "
                         f"a policy recorded observations alone")
    env = make(ds.task, **{**env_options(spec), "render": False})
    try:
        policy = make_policy(spec, env)
    finally:
        env.close()
    # built without an env, a learned policy cannot check its task against one: against the
    # demonstrations' here (its checkpoint's description names the task it learned)
    trained = (getattr(policy, "describe", None) or {}).get("task")
    cameras = policy_cameras(spec)
    missing = sorted(set(cameras) - set(ds.cameras))
    if (trained is not None and trained != ds.task) or missing:
        policy.close()
        raise ValueError(f"{spec} reads camera {missing[0]!r}, which {dataset} does not hold"
                         if missing else f"{spec} was trained on {trained}; {dataset} holds "
                         f"{ds.task} demonstrations")
    # frames at the size the learned policies were trained on; others get the dataset's own
    cfg = getattr(policy, "cfg", None)
    size = tuple(cfg.image_size) if cameras and hasattr(cfg, "image_size") else None
    with_state = ds.state_names is not None  # what a state policy reads (else: its ValueError)
    seeds = [int(row["rmbench/seed"]) for row in ds.episodes]
    per_episode = []
    for e in episodes:
        frames = DemoDataset(ds, chunk=1, cameras=list(cameras), image_size=size, episodes=[e],
                             environment_state=with_state)
        policy.reset("", {"seed": seeds[e]})
        err, hold = [], []
        for t in range(len(frames)):
            item = frames[t]
            state = item[L.STATE].numpy().astype(np.float64)
            obs = {"agent_pos": state,
                   "pixels": {c: item[L.image_key(c)].permute(1, 2, 0).numpy() for c in cameras}}
            if with_state:
                obs["environment_state"] = item[L.ENV_STATE].numpy().astype(np.float64)
            recorded = item[L.ACTION][0].numpy().astype(np.float64)
            err.append(np.abs(np.asarray(policy.act(obs), np.float64) - recorded).mean())
            hold.append(np.abs(state - recorded).mean())
        per_episode.append({"episode": e, "seed": seeds[e], "frames": len(frames),
                            "error": float(np.mean(err)), "hold_error": float(np.mean(hold))})
    policy.close()
    frames_total = sum(r["frames"] for r in per_episode)
    return {"policy": spec, "dataset": str(dataset), "episodes": per_episode,
            "error": sum(r["error"] * r["frames"] for r in per_episode) / frames_total,
            "hold_error": sum(r["hold_error"] * r["frames"] for r in per_episode) / frames_total}
