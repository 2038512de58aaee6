"""Training the universal placement network (:mod:`uavxai.service.universal`, inference only):
one D3QN (or its DQN ablation) across random problems, so that it serves any K up to
``K_MAX``, both access modes and all four environments without retraining
(`uavxai train --stage universal`), and its fine-tuning on one layout (`uavxai train
--stage service --finetune`).

Every episode a new problem from ``layouts.random_problem`` (K uniform in 2..K_MAX, uniform or
clustered users, random access mode and environment), fading-free, rewards divided by the
naive placement's refined objective. Targets as :mod:`uavxai.learning.branching` (Tavakoli et
al. 2018): all branches regress on ``r + gamma * mean_d Q_d^target(s', argmax Q_d^online(s'))``,
the mean over the move branch and the K real power branches. Every ``eval_every`` episodes the
greedy policy is flown on a fixed validation set; the checkpoint keeps the best validation
score.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from uavxai.comms.channel import ENVIRONMENTS
from uavxai.learning import checkpoint
from uavxai.learning.replay import ReplayBuffer
from uavxai.outputs import write_output
from uavxai.scenario import Scenario
from uavxai.service.layouts import random_problem
from uavxai.service.service_env import ServiceEnv
from uavxai.service.universal import (
    ACCESS_MODES,
    GLOBAL_FEATURES,
    K_MAX,
    USER_FEATURES,
    NumpyPolicy,
    Observation,
    SetQNetwork,
    fly,
    objective_at,
    observe,
    reference_objective,
    shipped_path,
    step,
)


@dataclass
class UniversalConfig:
    episodes: int = 2000
    minutes: float = 30.0  # wall-clock cap: training stops at whichever comes first
    train_steps: int = 60  # moves per training episode (half start at a random point)
    hidden: int = 64
    learning_rate: float = 5e-4
    gamma: float = 0.95
    buffer_size: int = 100_000
    batch_size: int = 64
    learning_starts: int = 1000
    train_frequency: int = 4
    target_network_frequency: int = 500
    start_e: float = 0.9
    end_e: float = 0.05
    exploration_fraction: float = 0.4
    max_grad_norm: float = 10.0
    # Huber loss with lr 2.5e-4 and target updates every 1000 steps validated worse (-0.33 /
    # -0.37 against -0.18 / -0.16 for D3QN / DQN): the shipped models use squared errors.
    huber: bool = False
    k_range: tuple[int, int] = (2, K_MAX)
    eval_every: int = 100
    eval_problems: int = 24
    dueling: bool = True
    double: bool = True
    seed: int = 0


def _replay(size: int) -> ReplayBuffer:
    """Transitions of problems of any K, padded to ``K_MAX`` users (``mask`` says which are
    real; a padded action is 0)."""
    return ReplayBuffer(
        size,
        {
            "glob": ((GLOBAL_FEATURES,), np.float32),
            "users": ((K_MAX, USER_FEATURES), np.float32),
            "mask": ((K_MAX,), bool),
            "action": ((1 + K_MAX,), np.int64),
            "reward": ((), np.float32),
            "next_glob": ((GLOBAL_FEATURES,), np.float32),
            "next_users": ((K_MAX, USER_FEATURES), np.float32),
        },
    )


def _padded(users: np.ndarray) -> np.ndarray:
    out = np.zeros((K_MAX, USER_FEATURES), np.float32)
    out[: len(users)] = users
    return out


def _store(
    rb: ReplayBuffer, obs: Observation, nxt: Observation, action: np.ndarray, reward: float
) -> None:
    k = len(obs.users)
    mask = np.arange(K_MAX) < k
    padded_action = np.zeros(1 + K_MAX, np.int64)
    padded_action[: 1 + k] = action
    rb.add(glob=obs.glob, users=_padded(obs.users), mask=mask, action=padded_action,
           reward=reward, next_glob=nxt.glob, next_users=_padded(nxt.users))  # fmt: skip


def _update(
    q: SetQNetwork, target: SetQNetwork, opt, batch: dict[str, torch.Tensor], cfg: UniversalConfig
) -> float:
    g, u, mask, a, r = (batch[k] for k in ("glob", "users", "mask", "action", "reward"))
    g2, u2 = batch["next_glob"], batch["next_users"]
    m = mask.to(torch.float32)
    branches = 1.0 + m.sum(1)
    with torch.no_grad():
        move_t, power_t = target(g2, u2, mask)
        if cfg.double:
            move_o, power_o = q(g2, u2, mask)
            nm = move_t.gather(1, move_o.argmax(1, keepdim=True))[:, 0]
            npw = power_t.gather(2, power_o.argmax(2, keepdim=True))[..., 0]
        else:
            nm, npw = move_t.max(1).values, power_t.max(2).values
        y = r + cfg.gamma * (nm + (npw * m).sum(1)) / branches  # truncation only: no done
    move, power = q(g, u, mask)
    qm = move.gather(1, a[:, :1])[:, 0]
    qp = power.gather(2, a[:, 1:, None])[..., 0]

    def err(x: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        if cfg.huber:
            return nn.functional.smooth_l1_loss(x, t, reduction="none")
        return (x - t) ** 2

    loss = ((err(qm, y) + (err(qp, y[:, None].expand_as(qp)) * m).sum(1)) / branches).mean()
    opt.zero_grad()
    loss.backward()
    nn.utils.clip_grad_norm_(q.parameters(), cfg.max_grad_norm)
    opt.step()
    return float(loss.detach())


@dataclass
class TrainLog:
    net: SetQNetwork
    config: UniversalConfig
    rows: list[dict[str, float]] = field(default_factory=list)
    best_score: float = -np.inf
    best_episode: int = 0
    episodes: int = 0
    wall_s: float = 0.0


def validation_envs(n: int, k_range: tuple[int, int]) -> list[ServiceEnv]:
    """A fixed validation set (seeds disjoint from training and from the benchmark), each
    with ``reward_scale`` set to ``reference_objective``."""
    envs = [random_problem(np.random.default_rng([7_777, i]), k_range) for i in range(n)]
    for env in envs:
        env.reward_scale = reference_objective(env)
    return envs


def score(net: SetQNetwork | NumpyPolicy, envs: list[ServiceEnv]) -> float:
    """Mean log2 of (best visited objective / reference objective) of greedy flights."""
    vals = [np.log2(max(fly(net, e).objective, 1e-30) / e.reward_scale) for e in envs]
    return float(np.mean(vals))


def train(
    cfg: UniversalConfig,
    log_path: Path | None = None,
    *,
    init: SetQNetwork | None = None,
    problems: list[ServiceEnv] | None = None,
) -> TrainLog:
    """Train across random problems; the returned net holds the best validated weights.

    Half the episodes start at a random lattice point instead of the region centre, so that
    the replay covers the whole box (the greedy flight starts at the centre). Fine-tuning
    (:func:`finetune`): ``init`` is the network to start from and ``problems`` the layouts
    to train and validate on (each with ``reward_scale`` set); the starting weights are
    scored first, so a fine-tuned net is never worse on them than the one it started from.
    """
    t0 = time.perf_counter()
    torch.set_num_threads(1)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    q = SetQNetwork(6, cfg.hidden, cfg.dueling) if init is None else copy.deepcopy(init)
    q.train()
    policy = NumpyPolicy(q)
    target = copy.deepcopy(q)
    opt = torch.optim.Adam(q.parameters(), lr=cfg.learning_rate)
    rb = _replay(cfg.buffer_size)
    val = validation_envs(cfg.eval_problems, cfg.k_range) if problems is None else problems
    log = TrainLog(net=q, config=cfg)
    best_state = copy.deepcopy(q.state_dict())
    if init is not None:
        log.best_score, log.best_episode = score(policy, val), 0
    total = cfg.episodes * cfg.train_steps
    global_step, eps = 0, cfg.start_e
    for episode in range(cfg.episodes):
        env, scale, pos = _problem(cfg, problems, episode, rng)
        obs = observe(env, pos)
        nvec = env.action_space.nvec
        ret = 0.0
        for _ in range(cfg.train_steps):
            frac = global_step / max(1, int(cfg.exploration_fraction * total))
            eps = max(cfg.end_e, cfg.start_e + (cfg.end_e - cfg.start_e) * frac)
            action = policy(obs)
            explore = rng.random(len(nvec)) < eps
            action[explore] = rng.integers(0, nvec[explore])
            pos, refused = step(env, pos, int(action[0]))
            reward = objective_at(env, pos, action[1:]) / scale / (2.0 if refused else 1.0)
            nxt = observe(env, pos)
            _store(rb, obs, nxt, action, reward)
            obs, ret = nxt, ret + reward
            global_step += 1
            if global_step > cfg.learning_starts and global_step % cfg.train_frequency == 0:
                _update(q, target, opt, rb.sample(rng, cfg.batch_size), cfg)
            if global_step % cfg.target_network_frequency == 0:
                target.load_state_dict(q.state_dict())
        log.episodes = episode + 1
        last = (episode + 1 == cfg.episodes) or (time.perf_counter() - t0 > 60 * cfg.minutes)
        if (episode + 1) % cfg.eval_every == 0 or last:
            s = score(policy, val)
            row = {
                "episode": episode + 1,
                "epsilon": eps,
                "return": ret / cfg.train_steps,
                "val_log2_over_reference": s,
                "wall_s": time.perf_counter() - t0,
            }
            log.rows.append(row)
            if s > log.best_score:
                log.best_score, log.best_episode = s, episode + 1
                best_state = copy.deepcopy(q.state_dict())
            if log_path is not None:
                with log_path.open("a") as f:
                    f.write(json.dumps(row) + "\n")
        if last:
            break
    q.load_state_dict(best_state)
    log.wall_s = time.perf_counter() - t0
    return log


def _problem(
    cfg: UniversalConfig, problems: list[ServiceEnv] | None, episode: int, rng: np.random.Generator
) -> tuple[ServiceEnv, float, np.ndarray]:
    """The episode's problem (a fresh random one, or the next of ``problems``), its reward
    scale and the start: the region centre, or for half the episodes a random lattice point."""
    if problems is None:
        env = random_problem(np.random.default_rng([cfg.seed, episode]), cfg.k_range)
        scale = reference_objective(env)
    else:
        env = problems[episode % len(problems)]
        scale = env.reward_scale
    pos = env.space.start.copy()
    if rng.random() < 0.5:
        pos = np.array([rng.choice(axis) for axis in env.space.axes()])
    return env, scale, pos


def finetune(net: SetQNetwork, env: ServiceEnv, cfg: UniversalConfig | None = None) -> TrainLog:
    """Fine-tune a universal model on one layout (``env``, fading-free): training goes on
    from ``net``'s weights on that layout alone, with little exploration, and the returned
    net is the best greedy flight's weights, the starting ones included."""
    env.reward_scale = reference_objective(env)
    cfg = cfg or FINETUNE
    cfg = replace(cfg, dueling=net.dueling, double=net.dueling, hidden=net.hidden)
    return train(cfg, init=net, problems=[env])


# A layout, not the world: a short, calm continuation of training (about 10 s on one core).
FINETUNE = UniversalConfig(
    episodes=100, minutes=5.0, learning_rate=2e-4, learning_starts=300,
    target_network_frequency=200, start_e=0.3, end_e=0.05, exploration_fraction=0.5,
    eval_every=5,
)  # fmt: skip


def save(path: Path, net: SetQNetwork, algo: str, meta: dict[str, Any]) -> None:
    """``path`` (:mod:`uavxai.learning.checkpoint`, read back by
    :func:`uavxai.service.universal.load`) and a JSON beside it saying what it was trained on."""
    checkpoint.save(
        path,
        "universal",
        {
            "algo": algo,
            "k_max": K_MAX,
            "power_levels": net.power_levels,
            "hidden": net.hidden,
            "dueling": net.dueling,
            "state_dict": net.state_dict(),
        },
    )
    write_output(path.with_suffix(".json"), json.dumps(meta, indent=2, default=str) + "\n")


def config_dict(cfg: UniversalConfig) -> dict[str, Any]:
    return asdict(cfg)


def train_command(
    scenario: Scenario, algo: str, episodes: int | None, out: Path, *, minutes: float | None = None
) -> dict[str, Any]:
    """`uavxai train --stage universal --algo d3qn|dqn`: train the universal model across
    random problems (seeded by the scenario's seed: nothing else of it is used) and write
    ``out/model.pt`` with ``out/model.json`` (and the validation
    log ``out/model.log.jsonl``). The shipped models are these files copied to
    ``uavxai/service/checkpoints/universal_{algo}_l6.pt`` (and ``.json``)."""
    from uavxai import __version__

    dueling = algo == "d3qn"
    cfg = UniversalConfig(
        episodes=episodes or UniversalConfig.episodes, seed=scenario.seed, dueling=dueling,
        double=dueling, minutes=UniversalConfig.minutes if minutes is None else minutes,
    )  # fmt: skip
    out.mkdir(parents=True, exist_ok=True)
    path = out / "model.pt"
    log_path = path.with_suffix(".log.jsonl")
    log_path.unlink(missing_ok=True)
    log = train(cfg, log_path)
    meta = {
        "algo": algo,
        "format": checkpoint.FORMATS["universal"][0],
        "k_range": [2, K_MAX],
        "power_levels": 6,
        "access": list(ACCESS_MODES),
        "environments": list(ENVIRONMENTS),
        "layouts": "uavxai.service.layouts.random_problem: K uniform in 2..20, uniform or "
        "clustered users in the default region, random access and environment, fading-free",
        "other_parameters": "scenario defaults (2 GHz, 1 MHz, -100 dBm, 1 W, QoS 100 kbit/s, "
        "10 m steps, world.h [50, 300] m)",
        "config": config_dict(cfg),
        "episodes_trained": log.episodes,
        "best_episode": log.best_episode,
        "best_val_log2_over_reference": log.best_score,
        "wall_s": round(log.wall_s, 1),
        "uavxai_version": __version__,
        "torch_version": str(torch.__version__),
        "command": f"uavxai train SCENARIO --stage universal --algo {algo} --episodes "
        f"{cfg.episodes} (seed {scenario.seed})",
    }
    save(path, log.net, algo, meta)
    return {"algo": algo, "model": str(path), "episodes": log.episodes,
            "best_episode": log.best_episode, "best_val_log2_over_reference": log.best_score,
            "wall_s": round(log.wall_s, 1), "shipped_as": str(shipped_path(algo))}  # fmt: skip
