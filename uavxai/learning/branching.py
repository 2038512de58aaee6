"""Training the service point's branching Q-networks on one user layout: D3QN (dueling,
double-DQN targets) and DQN, the ablation without either (`uavxai train --stage service`).
The network and its greedy policy are :mod:`uavxai.service.d3qn` (inference only).

One file, top to bottom, CleanRL style; every hyper-parameter is in :class:`D3QNConfig`.

All branches regress on one target, the mean over branches of the next state's branch values;
with double DQN the online network picks each branch's next action and the target network
values it:

    y = r + gamma * mean_d Q_d^target(s', argmax_a Q_d^online(s', a))

without it (DQN) the target network both picks and values it (``max_a Q_d^target``).
Exploration is epsilon-greedy per branch, epsilon falling linearly from 0.9 to 0.1 over the
first ``exploration_fraction`` of the steps. Rewards are divided by the environment's
``reward_scale`` (the naive placement's objective), so values are about 1 whatever the
bandwidth, access mode or environment.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from uavxai.learning import checkpoint
from uavxai.learning.replay import ReplayBuffer
from uavxai.service.d3qn import (
    BranchingQNetwork,
    Episode,
    episode_of,
    fading_free,
    greedy_action,
    rollout,
)
from uavxai.service.service_env import ServiceEnv


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


@dataclass
class DQNConfig(D3QNConfig):
    """DQN: the same network and loop without dueling heads or double-DQN targets, so the
    learning curves isolate what the two add."""

    dueling: bool = False
    double: bool = False


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
    rb = _replay(cfg.buffer_size, obs_dim, k)
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
            rb.add(
                obs=obs,
                action=action,
                reward=reward / env_e.reward_scale,
                next_obs=next_obs,
                done=float(terminated),
            )
            obs, ret, done = next_obs, ret + reward, terminated or truncated
            global_step += 1

            if global_step > cfg.learning_starts and global_step % cfg.train_frequency == 0:
                _update(q, target, optimizer, rb.sample(rng, cfg.batch_size), cfg)
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


def _new_network(obs_dim: int, k: int, L: int, cfg: D3QNConfig) -> BranchingQNetwork:
    return BranchingQNetwork(obs_dim, k, L, cfg.hidden, cfg.layers, cfg.dueling)


def _replay(size: int, obs_dim: int, k: int) -> ReplayBuffer:
    """Transitions of one layout: the action is the move and the K users' power levels."""
    return ReplayBuffer(
        size,
        {
            "obs": ((obs_dim,), np.float32),
            "action": ((1 + k,), np.int64),
            "reward": ((), np.float32),
            "next_obs": ((obs_dim,), np.float32),
            "done": ((), np.float32),
        },
    )


def _update(q, target, optimizer, batch: dict[str, torch.Tensor], cfg: D3QNConfig) -> float:
    obs, actions, rewards = batch["obs"], batch["action"], batch["reward"]
    next_obs, dones = batch["next_obs"], batch["done"]
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


def save_checkpoint(
    path: Path, net: BranchingQNetwork, algo: str, cfg: D3QNConfig, meta: dict[str, Any]
) -> None:
    """``path``: the network's weights and sizes (:mod:`uavxai.learning.checkpoint`), read
    back by :func:`uavxai.service.d3qn.load_checkpoint`."""
    checkpoint.save(
        path,
        "branching",
        {
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


def config_dict(cfg: D3QNConfig) -> dict[str, Any]:
    return asdict(cfg)
