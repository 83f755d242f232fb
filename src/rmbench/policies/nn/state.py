"""The state observation's encoder, in place of the CNNs when a policy reads
``observation.environment_state`` (``observation="state"`` in its config).

    [environment_state; agent_pos; (grasp poses); (reach joints)] (normalised)
        -> MLP -> tokens (B, n, dim)

Both parts are normalised to zero mean and unit variance with the training dataset's
statistics, stored here as buffers so that a checkpoint carries them. An entry that is constant
over the dataset (a colour one-hot that three demonstrations happen not to vary, a flag that
never flips) keeps a unit scale instead of dividing by its zero spread, so an unseen value at
evaluation arrives as a unit change rather than a thousandfold one; other spreads are floored at
STD_FLOOR (a button cap's depth varies by millimetres).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from rmbench.policies.action_space import EE_DIM, EEActions
from rmbench.sim import robot
from rmbench.sim.kinematics import reach_grid
from rmbench.sim.simulator import ACTION_DIM

STD_FLOOR = 1e-2
CONSTANT = 1e-6  # a spread below this is an entry the dataset never varies
REACH_ARM = 6  # joints per arm of a reach input


def reach_indices(state_names, names) -> np.ndarray:
    """Positions of ``{name}_x`` and ``{name}_y`` in ``state_names`` for each of ``names``
    (n, 2); a one-line error naming what is missing."""
    index = {n: i for i, n in enumerate(state_names)}
    missing = [n for n in names if f"{n}_x" not in index or f"{n}_y" not in index]
    if missing:
        have = sorted({n[:-2] for n in state_names if n.endswith("_x")})
        raise ValueError(f"reach_input {missing} has no _x/_y entries in the environment "
                         f"state; positions there: {', '.join(have)}")
    return np.array([[index[f"{n}_x"], index[f"{n}_y"]] for n in names], np.int64)


def reach_joints(xy: np.ndarray) -> np.ndarray:
    """Positions (..., n, 2) -> both arms' top-down reach joints (..., n * 12), float32."""
    grid = reach_grid()
    joints = np.concatenate([grid.joints(side, xy) for side in robot.SIDES], -1)
    return joints.reshape(*xy.shape[:-2], -1).astype(np.float32)


def safe_std(std) -> np.ndarray:
    std = np.asarray(std, np.float64)
    return np.where(std < CONSTANT, 1.0, np.maximum(std, STD_FLOOR))


class StateEncoder(nn.Module):
    """A list ``[environment_state (B, D), agent_pos (B, 14)]`` -> ``tokens`` d-dim tokens
    (B, tokens, dim): the same shape as ``CameraEncoders``' pooled output, so a model reads
    either. Two hidden GELU layers of width ``hidden``, a LayerNorm per token."""

    def __init__(self, state_dim: int, dim: int, tokens: int = 1, hidden: int = 256,
                 agent_dim: int = ACTION_DIM, grasp_pose: bool = False, reach: int = 0):
        super().__init__()
        if state_dim < 1:
            raise ValueError("a state encoder needs the environment state's length (>= 1)")
        self.tokens, self.dim = tokens, dim
        self.register_buffer("state_mean", torch.zeros(state_dim))
        self.register_buffer("state_std", torch.ones(state_dim))
        self.register_buffer("agent_mean", torch.zeros(agent_dim))
        self.register_buffer("agent_std", torch.ones(agent_dim))
        # the grasp sites' poses, by forward kinematics of the joints (no gradient flows there)
        self.poses = EEActions() if grasp_pose else None
        pose_dim = EE_DIM if grasp_pose else 0
        if grasp_pose:  # (only then: checkpoints from before the option load as they are)
            self.register_buffer("pose_mean", torch.zeros(pose_dim))
            self.register_buffer("pose_std", torch.ones(pose_dim))
        # ``reach`` named positions of the environment state, each as both arms' joints for a
        # top-down grasp there (sim.kinematics.ReachGrid; set_reach says which entries)
        reach_dim = 2 * REACH_ARM * reach
        if reach:
            self.register_buffer("reach_index", torch.zeros(reach, 2, dtype=torch.long))
            self.register_buffer("reach_mean", torch.zeros(reach_dim))
            self.register_buffer("reach_std", torch.ones(reach_dim))
        self.reach = reach
        self.mlp = nn.Sequential(nn.Linear(state_dim + agent_dim + pose_dim + reach_dim, hidden),
                                 nn.GELU(),
                                 nn.Linear(hidden, hidden), nn.GELU(),
                                 nn.Linear(hidden, tokens * dim))
        self.norm = nn.LayerNorm(dim)

    @property
    def state_dim(self) -> int:
        return self.state_mean.shape[0]

    def set_stats(self, stats: dict[str, dict[str, np.ndarray]], state_key: str,
                  agent_key: str) -> None:
        """Mean and spread from a dataset's statistics (meta/stats.json, as ``from_json``
        reads it)."""
        with torch.no_grad():
            for prefix, key in (("state", state_key), ("agent", agent_key)):
                getattr(self, f"{prefix}_mean").copy_(
                    torch.as_tensor(np.asarray(stats[key]["mean"]), dtype=torch.float32))
                getattr(self, f"{prefix}_std").copy_(
                    torch.as_tensor(safe_std(stats[key]["std"]), dtype=torch.float32))

    def set_pose_stats(self, poses: np.ndarray) -> None:
        """With ``grasp_pose``: mean and spread of the grasp poses (``EEActions.from_joints``)
        of a dataset's joint states."""
        with torch.no_grad():
            self.pose_mean.copy_(torch.as_tensor(poses.mean(0), dtype=torch.float32))
            self.pose_std.copy_(torch.as_tensor(safe_std(poses.std(0)), dtype=torch.float32))

    def set_reach(self, state_names, names, env_states: np.ndarray) -> None:
        """With ``reach``: which entries are the named positions (``{name}_x``, ``{name}_y``),
        and the mean and spread of their reach joints over a dataset's environment states."""
        if len(names) != self.reach:
            raise ValueError(f"the encoder reads {self.reach} reach positions, got {len(names)}")
        index = reach_indices(state_names, names)
        joints = reach_joints(np.asarray(env_states)[:, index])
        with torch.no_grad():
            self.reach_index.copy_(torch.from_numpy(index))
            self.reach_mean.copy_(torch.as_tensor(joints.mean(0), dtype=torch.float32))
            self.reach_std.copy_(torch.as_tensor(safe_std(joints.std(0)), dtype=torch.float32))

    def forward(self, inputs: list[torch.Tensor]) -> torch.Tensor:
        env_state, agent_pos = inputs
        parts = [(env_state.float() - self.state_mean) / self.state_std,
                 (agent_pos.float() - self.agent_mean) / self.agent_std]
        if self.poses is not None:
            flat = agent_pos.detach().reshape(-1, agent_pos.shape[-1]).cpu().numpy()
            pose = torch.from_numpy(self.poses.from_joints(flat)).to(agent_pos.device)
            parts.append((pose.reshape(*agent_pos.shape[:-1], -1) - self.pose_mean) / self.pose_std)
        if self.reach:
            xy = env_state.detach()[..., self.reach_index].cpu().numpy()
            joints = torch.from_numpy(reach_joints(xy)).to(env_state.device)
            parts.append((joints - self.reach_mean) / self.reach_std)
        x = torch.cat(parts, -1)
        return self.norm(self.mlp(x).unflatten(-1, (self.tokens, self.dim)))
