"""D3QN for the service point: a dueling, branching Q-network with double-DQN targets.

The action is a move (7 options) and a power level (L options) for each of K users: 7 L^K joint
actions (4.2e8 for K = 10, L = 6), too many for one Q-value each. As in Action Branching
Architectures (Tavakoli et al., 2018) the network has a shared trunk (3 hidden layers of 40,
ReLU), a state-value head V(s) and one advantage head per branch — one 7-way movement branch
and K power branches of L each, the paper's K x 6 output. Branch d has
``Q_d(s, a_d) = V(s) + A_d(s, a_d) - mean_a A_d(s, a)``. All branches regress on one target,
the mean over branches of the next state's branch values; with double DQN the online network
picks each branch's next action and the target network values it:

    y = r + gamma * mean_d Q_d^target(s', argmax_a Q_d^online(s', a))

Training (D3QN and the DQN ablation) is :mod:`uavxai.learning.branching`; this module is the
network, its greedy policy and the loading of its checkpoints.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from uavxai.learning import checkpoint
from uavxai.service.service_env import MOVES, ServiceEnv


# --------------------------------------------------------------------------------- network
class BranchingQNetwork(nn.Module):
    """Shared trunk; a move branch (7) and K power branches (L); dueling or plain heads."""

    def __init__(
        self, obs_dim: int, k: int, power_levels: int, hidden: int, layers: int, dueling: bool
    ):
        super().__init__()
        self.k, self.power_levels, self.dueling = k, power_levels, dueling
        sizes = [obs_dim] + [hidden] * layers
        pairs = zip(sizes[:-1], sizes[1:], strict=True)
        self.trunk = nn.Sequential(*(m for a, b in pairs for m in (nn.Linear(a, b), nn.ReLU())))
        self.move = nn.Linear(hidden, len(MOVES))
        self.power = nn.Linear(hidden, k * power_levels)
        self.value = nn.Linear(hidden, 1) if dueling else None

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Q-values ``(B, 7)`` of the moves and ``(B, K, L)`` of the power levels."""
        z = self.trunk(obs)
        move = self.move(z)
        power = self.power(z).view(-1, self.k, self.power_levels)
        if self.value is not None:
            v = self.value(z)
            move = v + move - move.mean(dim=-1, keepdim=True)
            power = v[:, :, None] + power - power.mean(dim=-1, keepdim=True)
        return move, power


def greedy_action(net: BranchingQNetwork, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        move, power = net(torch.as_tensor(obs, dtype=torch.float32)[None])
    return np.concatenate([move.argmax(-1).numpy(), power.argmax(-1)[0].numpy()])


# --------------------------------------------------------------------------------- rollouts
@dataclass
class Episode:
    """One search: the best position visited (fading-free objective) and the path flown."""

    objective: float
    position: np.ndarray
    levels: np.ndarray
    path: np.ndarray  # (T + 1, 3)
    ret: float = 0.0  # sum of the rewards, bit/s per step summed (throughput of eq 7 / dt)


def rollout(net: BranchingQNetwork, env: ServiceEnv) -> Episode:
    """The greedy policy from the start: deterministic for a fading-free environment."""
    obs, _ = env.reset()
    ret, done = 0.0, False
    while not done:
        obs, reward, terminated, truncated, _ = env.step(greedy_action(net, obs))
        ret += reward
        done = terminated or truncated
    return episode_of(env, ret)


def episode_of(env: ServiceEnv, ret: float) -> Episode:
    best = env.best
    return Episode(
        objective=best["objective"],
        position=best["position"],
        levels=best["levels"],
        path=np.array(env.path),
        ret=ret,
    )


def fading_free(env: ServiceEnv) -> ServiceEnv:
    """A copy of ``env`` with ``fading: none``: deterministic, for evaluation."""
    channel = replace(env.channel, fading="none")
    return ServiceEnv(channel, env.space, env.steps, env.power_levels)




def load_checkpoint(path: str | Path) -> tuple[BranchingQNetwork, dict[str, Any]]:
    """A model written by :func:`uavxai.learning.branching.save_checkpoint`, read without
    trusting it (:mod:`uavxai.learning.checkpoint`); any problem is a CheckpointError."""
    src = checkpoint.Source(
        Path(path),
        "service.checkpoint",
        "Give a model.pt written by `uavxai train SCENARIO --stage service --algo d3qn`, or "
        "null for the shipped model.",
    )
    data = checkpoint.read(src, "branching")
    obs_dim = checkpoint.declared_int(data, "obs_dim", 1, checkpoint.MAX_OBS_DIM, src)
    k = checkpoint.declared_int(data, "k", 1, checkpoint.MAX_USERS, src)
    levels = checkpoint.declared_int(data, "power_levels", 1, checkpoint.MAX_POWER_LEVELS, src)
    hidden = checkpoint.declared_int(data, "hidden", 1, checkpoint.MAX_HIDDEN_WIDTH, src)
    layers = checkpoint.declared_int(data, "layers", 1, checkpoint.MAX_LAYERS, src)
    dueling = checkpoint.declared_bool(data, "dueling", src)
    net = checkpoint.build_checked(
        lambda: BranchingQNetwork(obs_dim, k, levels, hidden, layers, dueling),
        data.get("state_dict"),
        src,
    )
    info = {
        "algo": data.get("algo"),
        "k": k,
        "power_levels": levels,
        "dueling": dueling,
        "meta": checkpoint.declared_meta(data, src),
    }
    return net, info
