"""D3QN for the service point: a dueling, branching Q-network with double-DQN targets.

One file, top to bottom, CleanRL style; every hyper-parameter is in :class:`D3QNConfig`.

The action is a move (7 options) and a power level (L options) for each of K users: 7 L^K joint
actions (4.2e8 for K = 10, L = 6), too many for one Q-value each. As in Action Branching
Architectures (Tavakoli et al., 2018) the network has a shared trunk (3 hidden layers of 40,
ReLU), a state-value head V(s) and one advantage head per branch — one 7-way movement branch
and K power branches of L each, the paper's K x 6 output. Branch d has
``Q_d(s, a_d) = V(s) + A_d(s, a_d) - mean_a A_d(s, a)``. All branches regress on one target,
the mean over branches of the next state's branch values; with double DQN the online network
picks each branch's next action and the target network values it:

    y = r + gamma * mean_d Q_d^target(s', argmax_a Q_d^online(s', a))

Exploration is epsilon-greedy per branch, epsilon falling linearly from 0.9 to 0.1 over the
first ``exploration_fraction`` of the steps. Rewards are divided by the environment's
``reward_scale`` (the naive placement's objective), so values are about 1 whatever the
bandwidth, access mode or environment.

DQN (``dqn.py``) is this file with ``dueling=False, double=False``.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from uavxai.errors import CheckpointError
from uavxai.outputs import write_torch
from uavxai.service.service_env import MOVES, ServiceEnv

CHECKPOINT_FORMAT = "uavxai.service.branching-q/1"


@dataclass
class D3QNConfig:
    episodes: int = 300
    hidden: int = 40
    layers: int = 3
    learning_rate: float = 1e-3
    gamma: float = 0.95  # horizon ~20 moves: the climb to the best altitude is 5-15 of them
    buffer_size: int = 50_000
    batch_size: int = 64
    learning_starts: int = 500  # environment steps before the first update
    train_frequency: int = 2  # environment steps per gradient step
    target_network_frequency: int = 200  # steps between hard target updates
    start_e: float = 0.9
    end_e: float = 0.1
    exploration_fraction: float = 0.5  # share of all steps over which epsilon falls
    max_grad_norm: float = 10.0
    dueling: bool = True
    double: bool = True
    seed: int = 0


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


# --------------------------------------------------------------------------------- replay
class ReplayBuffer:
    def __init__(self, size: int, obs_dim: int, action_dim: int):
        self.obs = np.zeros((size, obs_dim), np.float32)
        self.next_obs = np.zeros((size, obs_dim), np.float32)
        self.actions = np.zeros((size, action_dim), np.int64)
        self.rewards = np.zeros(size, np.float32)
        self.dones = np.zeros(size, np.float32)
        self.size, self.pos, self.full = size, 0, False

    def add(self, obs, next_obs, action, reward, done) -> None:
        i = self.pos
        self.obs[i], self.next_obs[i], self.actions[i] = obs, next_obs, action
        self.rewards[i], self.dones[i] = reward, done
        self.pos = (i + 1) % self.size
        self.full = self.full or self.pos == 0

    def sample(self, batch: int, rng: np.random.Generator) -> tuple[torch.Tensor, ...]:
        idx = rng.integers(0, self.size if self.full else self.pos, size=batch)
        return tuple(
            torch.as_tensor(a[idx])
            for a in (self.obs, self.actions, self.rewards, self.next_obs, self.dones)
        )


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


# --------------------------------------------------------------------------------- training
@dataclass
class TrainResult:
    net: BranchingQNetwork
    config: D3QNConfig
    curve: list[dict[str, float]] = field(default_factory=list)
    wall_s: float = 0.0
    best: Episode | None = None  # the best position visited while training (one layout)
    best_greedy: float = -np.inf  # the best greedy objective of an evaluated policy ...
    best_state: dict[str, torch.Tensor] | None = None  # ... and that policy's weights


def linear_schedule(start: float, end: float, duration: int, t: int) -> float:
    return max(end, start + (end - start) * t / max(duration, 1))


def train(
    env: ServiceEnv | Callable[[int], ServiceEnv],
    cfg: D3QNConfig,
    init: BranchingQNetwork | None = None,
    on_episode: Callable[[int, dict[str, float]], None] | None = None,
) -> TrainResult:
    """Train on ``env``, or on ``env(episode)`` — a fresh environment per episode (random user
    layouts for the shipped models; they must share K and L). After every episode the greedy
    policy is evaluated on a fading-free copy of the episode's environment:
    ``greedy_objective`` is the objective of the service point it would pick."""
    t0 = time.perf_counter()
    torch.set_num_threads(1)  # a 3 x 40 MLP: a second thread only adds contention
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    make_env = env if callable(env) and not isinstance(env, ServiceEnv) else (lambda _: env)
    first = make_env(0)
    k, L, steps = first.channel.k, first.power_levels, first.steps
    obs_dim = first.observation_space.shape[0]
    q = init if init is not None else _new_network(obs_dim, k, L, cfg)
    target = copy.deepcopy(q)
    optimizer = torch.optim.Adam(q.parameters(), lr=cfg.learning_rate)
    rb = ReplayBuffer(cfg.buffer_size, obs_dim, 1 + k)
    nvec = first.action_space.nvec
    total_steps = cfg.episodes * steps
    result = TrainResult(net=q, config=cfg)

    global_step = 0
    for episode in range(cfg.episodes):
        env_e = first if episode == 0 else make_env(episode)
        obs, _ = env_e.reset(seed=cfg.seed + episode)
        ret, done = 0.0, False
        while not done:
            epsilon = linear_schedule(
                cfg.start_e, cfg.end_e, int(cfg.exploration_fraction * total_steps), global_step
            )
            action = greedy_action(q, obs)
            explore = rng.random(len(nvec)) < epsilon
            action[explore] = rng.integers(0, nvec[explore])
            next_obs, reward, terminated, truncated, _ = env_e.step(action)
            # Truncation is the search budget, not an end of the world: keep bootstrapping.
            rb.add(obs, next_obs, action, reward / env_e.reward_scale, float(terminated))
            obs, ret, done = next_obs, ret + reward, terminated or truncated
            global_step += 1

            if global_step > cfg.learning_starts and global_step % cfg.train_frequency == 0:
                _update(q, target, optimizer, rb.sample(cfg.batch_size, rng), cfg)
            if global_step % cfg.target_network_frequency == 0:
                target.load_state_dict(q.state_dict())

        if result.best is None or env_e.best["objective"] > result.best.objective:
            result.best = episode_of(env_e, ret)
        greedy = rollout(q, fading_free(env_e))
        if greedy.objective > result.best_greedy:
            result.best_greedy = greedy.objective
            result.best_state = copy.deepcopy(q.state_dict())
        row = {
            "episode": episode + 1,
            "epsilon": epsilon,
            "return": ret / steps,
            "train_objective": env_e.best["objective"],
            "greedy_objective": greedy.objective,
            "reward_scale": env_e.reward_scale,
        }
        result.curve.append(row)
        if on_episode is not None:
            on_episode(episode, row)
    result.wall_s = time.perf_counter() - t0
    return result


def fading_free(env: ServiceEnv) -> ServiceEnv:
    """A copy of ``env`` with ``fading: none``: deterministic, for evaluation."""
    channel = replace(env.channel, fading="none")
    return ServiceEnv(channel, env.space, env.steps, env.power_levels)


def _new_network(obs_dim: int, k: int, L: int, cfg: D3QNConfig) -> BranchingQNetwork:
    return BranchingQNetwork(obs_dim, k, L, cfg.hidden, cfg.layers, cfg.dueling)


def _update(q, target, optimizer, batch, cfg: D3QNConfig) -> float:
    obs, actions, rewards, next_obs, dones = batch
    with torch.no_grad():
        move_t, power_t = target(next_obs)
        if cfg.double:
            move_o, power_o = q(next_obs)
            next_move = move_t.gather(1, move_o.argmax(1, keepdim=True))[:, 0]
            next_power = power_t.gather(2, power_o.argmax(2, keepdim=True))[..., 0]
        else:
            next_move = move_t.max(1).values
            next_power = power_t.max(2).values
        branches = 1 + next_power.shape[1]
        next_value = (next_move + next_power.sum(1)) / branches
        y = rewards + cfg.gamma * (1.0 - dones) * next_value
    move, power = q(obs)
    q_move = move.gather(1, actions[:, :1])[:, 0]
    q_power = power.gather(2, actions[:, 1:, None])[..., 0]
    # The mean over branches of each branch's squared TD error.
    loss = (((q_move - y) ** 2).mean() + ((q_power - y[:, None]) ** 2).mean(0).sum()) / branches
    optimizer.zero_grad()
    loss.backward()
    nn.utils.clip_grad_norm_(q.parameters(), cfg.max_grad_norm)
    optimizer.step()
    return float(loss.detach())


# --------------------------------------------------------------------------------- checkpoints
def save_checkpoint(
    path: Path, net: BranchingQNetwork, algo: str, cfg: D3QNConfig, meta: dict[str, Any]
) -> None:
    write_torch(  # whole or not at all
        path,
        {
            "format": CHECKPOINT_FORMAT,
            "algo": algo,
            "obs_dim": net.trunk[0].in_features,
            "k": net.k,
            "power_levels": net.power_levels,
            "hidden": cfg.hidden,
            "layers": cfg.layers,
            "dueling": net.dueling,
            "meta": meta,
            "state_dict": net.state_dict(),
        },
    )


def load_checkpoint(path: str | Path) -> tuple[BranchingQNetwork, dict[str, Any]]:
    """Load a model written by :func:`save_checkpoint`; any problem is a CheckpointError.

    The declared sizes are bounded and compared with the stored tensors, and the weights must
    be finite, before a network is allocated (:mod:`uavxai.service.guard`)."""
    from uavxai.service import guard

    p = Path(path)
    where = "service.checkpoint"
    remedy = "Give a model.pt written by `uavxai train SCENARIO --stage service --algo d3qn`."
    if not p.is_file():
        raise CheckpointError(f"{where} {p}: no such file. {remedy[:-1]}, or null for the "
                              "shipped model.")  # fmt: skip
    data = guard.read_checkpoint(p, where, remedy)
    if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(
            f"service.checkpoint {p}: not a uavxai service-point model (expected format "
            f"{CHECKPOINT_FORMAT}). Train one with `uavxai train SCENARIO --stage service "
            "--algo d3qn`."
        )
    obs_dim = guard.declared_int(data, "obs_dim", 1, guard.MAX_OBS_DIM, p, where, remedy)
    k = guard.declared_int(data, "k", 1, guard.MAX_USERS, p, where, remedy)
    levels = guard.declared_int(data, "power_levels", 1, guard.MAX_POWER_LEVELS, p, where, remedy)
    hidden = guard.declared_int(data, "hidden", 1, guard.MAX_HIDDEN_WIDTH, p, where, remedy)
    layers = guard.declared_int(data, "layers", 1, guard.MAX_LAYERS, p, where, remedy)
    dueling = guard.declared_bool(data, "dueling", p, where, remedy)
    try:
        net = guard.build_checked(
            lambda: BranchingQNetwork(obs_dim, k, levels, hidden, layers, dueling),
            data.get("state_dict"), p, where, remedy,
        )  # fmt: skip
        info = {key: data[key] for key in ("algo", "k", "power_levels", "dueling", "meta")}
    except (KeyError, RuntimeError, TypeError) as exc:
        raise CheckpointError(f"service.checkpoint {p}: damaged model file ({exc}).") from None
    return net, info


def config_dict(cfg: D3QNConfig) -> dict[str, Any]:
    return asdict(cfg)
