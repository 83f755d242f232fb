"""The state observation's encoder, in place of the CNNs when a policy reads
``observation.environment_state`` (``observation="state"`` in its config).

    [environment_state; agent_pos; (grasp poses)] (normalised) -> MLP -> tokens (B, n, dim)

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

STD_FLOOR = 1e-2
CONSTANT = 1e-6  # a spread below this is an entry the dataset never varies


def safe_std(std) -> np.ndarray:
    std = np.asarray(std, np.float64)
    return np.where(std < CONSTANT, 1.0, np.maximum(std, STD_FLOOR))


class StateEncoder(nn.Module):
    """A list ``[environment_state (B, D), agent_pos (B, 14)]`` -> ``tokens`` d-dim tokens
    (B, tokens, dim): the same shape as ``CameraEncoders``' pooled output, so a model reads
    either. Two hidden GELU layers of width ``hidden``, a LayerNorm per token."""

    def __init__(self, state_dim: int, dim: int, tokens: int = 1, hidden: int = 256,
                 agent_dim: int = 14, grasp_pose: bool = False):
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
        self.mlp = nn.Sequential(nn.Linear(state_dim + agent_dim + pose_dim, hidden), nn.GELU(),
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

    def forward(self, inputs: list[torch.Tensor]) -> torch.Tensor:
        env_state, agent_pos = inputs
        parts = [(env_state.float() - self.state_mean) / self.state_std,
                 (agent_pos.float() - self.agent_mean) / self.agent_std]
        if self.poses is not None:
            flat = agent_pos.detach().reshape(-1, agent_pos.shape[-1]).cpu().numpy()
            pose = torch.from_numpy(self.poses.from_joints(flat)).to(agent_pos.device)
            parts.append((pose.reshape(*agent_pos.shape[:-1], -1) - self.pose_mean) / self.pose_std)
        x = torch.cat(parts, -1)
        return self.norm(self.mlp(x).unflatten(-1, (self.tokens, self.dim)))
