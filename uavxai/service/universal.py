"""One D3QN for every layout: a per-user set network, trained across random problems.

The paper's agent (dueling heads, double-DQN targets, a 7-way movement branch and an L-way
power branch per user) with the structure of the problem built in, so that one network serves
any K up to ``K_MAX``, both access modes and all four environments without retraining:

- **Observation** (``observe``) at the UAV position, fading-free. Per user (``USER_FEATURES``):
  the offset user - UAV, horizontal distance, elevation angle, LoS probability, large-scale
  gain (dB relative to free space at 100 m), the change of that gain in dB for each of the six
  moves, and the user's rate at equal power against the QoS rate. Global
  (``GLOBAL_FEATURES``): the UAV position in the box, the access mode and the environment
  (one-hot), K / K_MAX, for each move the log2 change of the equal-power objective and
  whether the move stays in the box, and the equal-power objective against the naive
  placement. Everything is a ratio or an angle, so it does not depend on the bandwidth or
  the transmit power.
- **Network** (``SetQNetwork``): a shared encoder maps every user's features (with the global
  ones) to an embedding; mean and max pooling over the users give a summary of the layout;
  a context MLP on [mean, max, global] feeds the state value V and the movement advantages;
  the power branch of user k is one shared head on [its embedding, the context], so every
  branch sees its user and a summary of the others, and padding to K_MAX is masked out.
  Dueling: ``Q_d = V + A_d - mean A_d`` per branch.
- **Targets**: as ``d3qn.py`` (Tavakoli et al. 2018): all branches regress on
  ``r + gamma * mean_d Q_d^target(s', argmax Q_d^online(s'))``, the mean over the move branch
  and the K real power branches. DQN (the ablation) is the same network without V and with
  ``max_a Q_d^target`` (no double).
- **Training** (``train``): every episode a new problem from ``layouts.random_problem``
  (K uniform in 2..K_MAX, uniform or clustered users, random access mode and environment),
  fading-free, rewards divided by the naive placement's objective. Every ``eval_every``
  episodes the greedy policy is flown on a fixed validation set; the checkpoint keeps the
  best validation score.
- **Planning** (``plan``): the greedy flight of ``steps`` moves from the region centre at
  100 m with the power branch's levels at every step, stopped when it hovers or revisits a
  point (the walk is deterministic); the best visited point (with the levels the network
  chose there) is "D3QN alone". ``refine`` then polishes it on the same lattice and levels:
  the best single improving change (a move to one of the 6 neighbours, one user's level, or
  one level moved from one user to another) until none improves, from the network's levels
  and from equal power; for K <= 12 the exact power DP of ``grid`` at the final point.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn

from uavxai.comms.channel import ENVIRONMENTS, Channel, free_space_loss_db
from uavxai.errors import CheckpointError
from uavxai.outputs import write_output, write_torch
from uavxai.service.layouts import random_problem
from uavxai.service.service_env import (
    GAIN_REFERENCE_DISTANCE_M,
    MOVES,
    SearchSpace,
    ServiceEnv,
    levels_to_power,
)

if TYPE_CHECKING:
    from uavxai.service.orbit import OrbitObjective

CHECKPOINT_FORMAT = "uavxai.service.universal-q/1"
K_MAX = 20
USER_FEATURES = 13
GLOBAL_FEATURES = 23
OFFSET_SCALE_M = 250.0  # half the default region: offsets of about -2..2
OBJECTIVE_DELTA_SCALE = 10.0  # log2 change of the objective per move is ~0.01-0.1
CLIP = 5.0
ACCESS_MODES = ("shared", "ofdma")


# ------------------------------------------------------------------------------ observation
@dataclass
class Observation:
    glob: np.ndarray  # (G,) float32
    users: np.ndarray  # (K, F) float32


def observe(env: ServiceEnv, position: np.ndarray | None = None) -> Observation:
    """The features at ``position`` (default: the env's current position), fading-free."""
    ch, space = env.channel, env.space
    pos = env.position if position is None else np.asarray(position, float)
    around = pos + np.vstack([np.zeros((1, 3)), MOVES[:6] * space.step_m])  # (7, 3)
    gain_db = -ch.path_loss_db(around)  # (7, K)
    ref_db = -free_space_loss_db(np.array(GAIN_REFERENCE_DISTANCE_M), ch.carrier_hz)
    rate = ch.rate(10.0 ** (gain_db / 10.0), ch.equal_power())  # (7, K)
    objective = ch.objective(rate)  # (7,)
    distance, elevation = ch.geometry(pos)
    offset = (ch.users[:, :2] - pos[:2]) / OFFSET_SCALE_M
    qos = max(ch.qos_rate_bps, 1.0)
    users = np.column_stack(
        [
            offset,
            np.hypot(offset[:, 0], offset[:, 1]),
            elevation / 90.0,
            ch.p_los(pos),  # the channel model's (comms.channel)
            (gain_db[0] - ref_db) / 10.0,
            gain_db[1:].T - gain_db[0][:, None],  # (K, 6): dB per move
            np.log2(np.maximum(rate[0], 1e-9) / qos) / 4.0,
        ]
    )
    access = np.array([ch.access == m for m in ACCESS_MODES], float)
    environment = np.array([ch.environment == e for e in ENVIRONMENTS], float)
    inside = space.contains(around[1:]).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.log2(np.maximum(objective[1:], 1e-30) / max(objective[0], 1e-30))
        level = np.log2(max(objective[0], 1e-30) / max(env.naive_objective, 1e-30))
    glob = np.concatenate(
        [
            np.clip(space.normalise(pos), -1.0, 1.0),
            access,
            environment,
            [ch.k / K_MAX],
            delta * OBJECTIVE_DELTA_SCALE * inside,
            inside,
            [level],
        ]
    )
    return Observation(
        np.clip(glob, -CLIP, CLIP).astype(np.float32),
        np.clip(users, -CLIP, CLIP).astype(np.float32),
    )


# ---------------------------------------------------------------------------------- network
def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers)


class SetQNetwork(nn.Module):
    """Shared per-user encoder, mean/max pooling, a move branch and one shared power head."""

    def __init__(self, power_levels: int, hidden: int = 64, dueling: bool = True):
        super().__init__()
        self.power_levels, self.hidden, self.dueling = power_levels, hidden, dueling
        self.encoder = _mlp([USER_FEATURES + GLOBAL_FEATURES, hidden, hidden])
        self.context = _mlp([2 * hidden + GLOBAL_FEATURES, hidden, hidden])
        self.move = nn.Linear(hidden, len(MOVES))
        self.power = nn.Sequential(_mlp([2 * hidden, hidden]), nn.Linear(hidden, power_levels))
        self.value = nn.Linear(hidden, 1) if dueling else None

    def forward(
        self, glob: torch.Tensor, users: torch.Tensor, mask: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``glob (B, G)``, ``users (B, K, F)``, ``mask (B, K)`` bool -> Q ``(B, 7)``,
        ``(B, K, L)`` (rows of padded users are meaningless)."""
        b, k, _ = users.shape
        e = self.encoder(torch.cat([users, glob[:, None].expand(b, k, -1)], dim=-1))
        m = mask[..., None].to(e.dtype)
        mean = (e * m).sum(1) / m.sum(1).clamp(min=1.0)
        top = e.masked_fill(~mask[..., None], -1e9).max(1).values
        z = self.context(torch.cat([mean, top, glob], dim=-1))
        move = self.move(z)
        power = self.power(torch.cat([e, z[:, None].expand(b, k, -1)], dim=-1))
        if self.value is not None:
            v = self.value(z)
            move = v + move - move.mean(-1, keepdim=True)
            power = v[:, :, None] + power - power.mean(-1, keepdim=True)
        return move, power


def greedy_action(net: SetQNetwork, obs: Observation) -> np.ndarray:
    with torch.inference_mode():
        users = torch.as_tensor(obs.users)[None]
        mask = torch.ones(users.shape[:2], dtype=torch.bool)
        move, power = net(torch.as_tensor(obs.glob)[None], users, mask)
    return np.concatenate([move.argmax(-1).numpy(), power[0].argmax(-1).numpy()])


class NumpyPolicy:
    """The greedy policy of a ``SetQNetwork`` in numpy, for one state at a time.

    A batch-of-one torch forward costs ~1 ms of framework overhead; these few matrix products
    cost ~0.1 ms. The arrays are views of the parameters, so in-place optimiser steps show
    through. V and the mean advantage do not change an argmax: only advantages are computed.
    """

    def __init__(self, net: SetQNetwork):
        def wb(layer: nn.Linear) -> tuple[np.ndarray, np.ndarray]:
            return layer.weight.detach().numpy(), layer.bias.detach().numpy()

        self.enc = [wb(net.encoder[0]), wb(net.encoder[2])]
        self.ctx = [wb(net.context[0]), wb(net.context[2])]
        self.move = wb(net.move)
        self.pow = [wb(net.power[0][0]), wb(net.power[1])]

    @staticmethod
    def _relu_layers(x: np.ndarray, layers: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        for w, b in layers:
            x = np.maximum(x @ w.T + b, 0.0)
        return x

    def __call__(self, obs: Observation) -> np.ndarray:
        k = len(obs.users)
        x = np.concatenate([obs.users, np.broadcast_to(obs.glob, (k, len(obs.glob)))], axis=1)
        e = self._relu_layers(x, self.enc)
        z = self._relu_layers(np.concatenate([e.mean(0), e.max(0), obs.glob]), self.ctx)
        move = z @ self.move[0].T + self.move[1]
        h = self._relu_layers(np.concatenate([e, np.broadcast_to(z, (k, len(z)))], 1), self.pow[:1])
        power = h @ self.pow[1][0].T + self.pow[1][1]
        return np.concatenate([[int(np.argmax(move))], power.argmax(1)])


# ---------------------------------------------------------------------------------- rollouts
@dataclass
class Flight:
    objective: float  # best visited, with the network's levels there
    position: np.ndarray
    levels: np.ndarray
    path: np.ndarray  # (T + 1, 3)


def objective_at(env: ServiceEnv, position: np.ndarray, levels: np.ndarray) -> float:
    """Fading-free objective R / 2^lambda at one position with integer levels."""
    power = levels_to_power(levels, env.channel.p_max_w, env.power_levels)
    return float(env.channel.evaluate(position, power).objective)


def step(env: ServiceEnv, position: np.ndarray, move: int) -> tuple[np.ndarray, bool]:
    """The env's move rule (a move out of the box is refused) without the gym checks."""
    target = position + MOVES[move] * env.space.step_m
    if bool(env.space.contains(target)):
        return target, False
    return position, True


def fly(
    net: SetQNetwork | NumpyPolicy, env: ServiceEnv, start: np.ndarray | None = None
) -> Flight:
    """The greedy flight of at most ``env.steps`` moves: the best point visited, with the
    levels the power branch chose there. The observation depends on the position only, so
    the greedy flight is a deterministic walk: once it hovers or comes back to a point it
    will loop for ever, and the flight stops there (the rest would visit nothing new)."""
    policy = net if isinstance(net, NumpyPolicy) else NumpyPolicy(net)
    pos = env.space.start.copy() if start is None else np.asarray(start, float).copy()
    path, seen = [pos.copy()], {tuple(np.round(pos, 6))}
    best = (-np.inf, pos.copy(), np.zeros(env.channel.k, np.int64))
    for _ in range(env.steps):
        action = policy(observe(env, pos))
        pos, _ = step(env, pos, int(action[0]))
        value = objective_at(env, pos, action[1:])
        if value > best[0]:
            best = (value, pos.copy(), action[1:].copy())
        path.append(pos.copy())
        key = tuple(np.round(pos, 6))
        if key in seen:
            break
        seen.add(key)
    return Flight(best[0], best[1], best[2], np.array(path))


def reference_objective(env: ServiceEnv) -> float:
    """The scale rewards are divided by: the naive point (users' centroid, 100 m) with its
    levels polished by ``refine`` from equal power, position fixed. In the shared band with
    many users, equal power leaves every user below the QoS rate and the naive objective is
    ~2^-K of what good levels give; this scale stays about 1 near the optimum everywhere."""
    from uavxai.service.service_env import naive_placement

    naive = naive_placement(env.space, env.channel.users)
    full = np.full(env.channel.k, env.power_levels - 1, np.int64)
    _, _, value, _ = refine(env.channel, env.space, env.power_levels, naive, full, move=False)
    return max(value, 1e-30)


def refine(
    channel: Channel,
    space: SearchSpace,
    power_levels: int,
    position: np.ndarray,
    levels: np.ndarray,
    max_rounds: int = 300,
    move: bool = True,
    scorer: OrbitObjective | None = None,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Best-improvement local search on the lattice and the levels (see the module doc).

    Returns position, levels, objective and the number of rounds. Stays on the planner's
    lattice and discrete levels, so the result is never above the grid optimum. With a
    ``scorer`` (``service.platform: orbit``) candidates are ranked by ``scorer.value``, the
    orbit objective, instead of the hover objective.
    """
    L, k = power_levels, channel.k
    pos, lev = np.asarray(position, float).copy(), np.asarray(levels, np.int64).copy()
    eye = np.eye(k, dtype=np.int64)
    pairs = np.array([(i, j) for i in range(k) for j in range(k) if i != j]).reshape(-1, 2)

    gains: dict[tuple[float, ...], np.ndarray] = {}  # large-scale gains per lattice point

    def gain(p: np.ndarray) -> np.ndarray:
        keys = [tuple(np.round(row, 6)) for row in np.atleast_2d(p)]
        missing = [n for n, key in enumerate(keys) if key not in gains]
        if missing:
            for n, g in zip(missing, channel.mean_gain(np.atleast_2d(p)[missing]), strict=True):
                gains[keys[n]] = g
        return np.array([gains[key] for key in keys])

    def value(p: np.ndarray, lv: np.ndarray) -> np.ndarray:
        if scorer is not None:
            return scorer.value(p, lv)
        power = levels_to_power(lv, channel.p_max_w, L)
        return channel.objective(channel.rate(gain(p), power))

    best = float(value(pos, lev)[0])
    rounds = 0
    while rounds < max_rounds:
        rounds += 1
        # candidate levels: one user's level set to any value, one level moved i -> j
        single = np.repeat(lev[None], k * L, axis=0)
        single[np.arange(k * L), np.repeat(np.arange(k), L)] = np.tile(np.arange(L), k)
        moved = lev[None] - eye[pairs[:, 0]] + eye[pairs[:, 1]]
        cand = np.vstack([single, moved])
        cand = cand[(cand >= 0).all(1) & (cand < L).all(1) & (cand.sum(1) > 0)]
        lv_values = value(pos, cand)
        neighbours = pos + MOVES[:6] * space.step_m
        neighbours = neighbours[space.contains(neighbours)] if move else neighbours[:0]
        nb_values = value(neighbours, lev[None]) if len(neighbours) else np.zeros(0)
        i, j = int(np.argmax(lv_values)), int(np.argmax(nb_values)) if len(nb_values) else -1
        top_lv = float(lv_values[i])
        top_nb = float(nb_values[j]) if j >= 0 else -np.inf
        if max(top_lv, top_nb) <= best * (1.0 + 1e-12):
            break
        if top_lv >= top_nb:
            lev, best = cand[i].copy(), top_lv
        else:
            pos, best = neighbours[j].copy(), top_nb
    return pos, lev, best, rounds


@dataclass
class Plan:
    flight: Flight  # "D3QN alone": the greedy flight and its best visited point
    position: np.ndarray  # what the planner returns, after the refinement
    levels: np.ndarray
    objective: float
    refine_rounds: int


EXACT_POWER_MAX_COST = 2.1  # grid.dp_cost: K <= 12 users at L = 6, 5-25 ms on one core


def plan(
    policy: SetQNetwork | NumpyPolicy, env: ServiceEnv, scorer: OrbitObjective | None = None
) -> Plan:
    """The ``service.planner: d3qn|dqn`` search on a fading-free env: the greedy flight, then
    ``refine`` from its best point twice — with the network's levels and with all levels full
    (equal power) — keeping the better. Two starts because a local search over levels cannot
    leave a QoS trap (many users below the QoS rate, where one level changes nothing): in the
    shared band with many users the network's levels can start it inside one. Last, where the
    exact power DP of ``grid`` is cheap (K <= 12 at L = 6), the levels at the final point are
    replaced by the exact optimum for that point: single-level and pair moves stop short of
    the shared band's optimum (all users but one exactly at the QoS rate), 0.96 for K = 10.
    On the hover objective the refinement also starts from the two best points of a coarse
    screen at equal power, is kicked out of QoS plateaus (an iterated local search), and the
    exact power step is followed by an exact climb (``uavxai.service.starts``: needles and
    steps a local search from the flight cannot reach).

    With a ``scorer`` (``service.platform: orbit``) the network still flies as trained (on the
    hover objective) and its best visited point is the start, but the refinement and the exact
    power step score the orbit objective (``uavxai.service.orbit``)."""
    from uavxai.service.grid import dp_cost, optimal_levels
    from uavxai.service.starts import climb_exact, kicked, screened_starts

    flight = fly(policy, env)
    best: tuple[np.ndarray, np.ndarray, float] | None = None
    rounds = 0
    full = np.full(env.channel.k, env.power_levels - 1, np.int64)
    starts = [(flight.position, flight.levels), (flight.position, full)]
    if scorer is None:  # hover: also the screen's best points (uavxai.service.starts)
        starts += [(p, full) for p in screened_starts(env.channel, env.space, flight.position)]
    for start, levels in starts:
        pos, lev, value, r = refine(
            env.channel, env.space, env.power_levels, start, levels, scorer=scorer
        )
        rounds += r
        if best is None or value > best[2]:
            best = (pos, lev, value)
    assert best is not None
    if scorer is None:  # hover: kicks out of a QoS plateau (uavxai.service.starts)
        best, r = kicked(
            env.space,
            best,
            lambda p, lv: refine(env.channel, env.space, env.power_levels, p, lv),
        )
        rounds += r
    if dp_cost(env.channel.k, env.power_levels) <= EXACT_POWER_MAX_COST:
        if scorer is not None:
            lev, value = scorer.optimal_levels(best[0])
        else:
            gain = env.channel.mean_gain(best[0])
            lev, value = optimal_levels(env.channel, gain, env.power_levels)
        if value > best[2]:
            best = (best[0], lev, value)
        if scorer is None:  # hover: the exact climb (uavxai.service.starts)
            best = climb_exact(env.channel, env.space, env.power_levels, best)
    return Plan(flight, best[0], best[1], best[2], rounds)


# ---------------------------------------------------------------------------------- training
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


class _Replay:
    def __init__(self, size: int):
        self.g = np.zeros((size, GLOBAL_FEATURES), np.float32)
        self.u = np.zeros((size, K_MAX, USER_FEATURES), np.float32)
        self.g2 = np.zeros_like(self.g)
        self.u2 = np.zeros_like(self.u)
        self.mask = np.zeros((size, K_MAX), bool)
        self.a = np.zeros((size, 1 + K_MAX), np.int64)
        self.r = np.zeros(size, np.float32)
        self.size, self.pos, self.full = size, 0, False

    def add(self, obs: Observation, nxt: Observation, action: np.ndarray, reward: float) -> None:
        i, k = self.pos, len(obs.users)
        self.g[i], self.g2[i] = obs.glob, nxt.glob
        self.u[i] = 0.0
        self.u2[i] = 0.0
        self.u[i, :k], self.u2[i, :k] = obs.users, nxt.users
        self.mask[i] = False
        self.mask[i, :k] = True
        self.a[i] = 0
        self.a[i, : 1 + k] = action
        self.r[i] = reward
        self.pos = (i + 1) % self.size
        self.full = self.full or self.pos == 0

    def sample(self, n: int, rng: np.random.Generator) -> tuple[torch.Tensor, ...]:
        idx = rng.integers(0, self.size if self.full else self.pos, size=n)
        return tuple(
            torch.as_tensor(x[idx]) for x in (self.g, self.u, self.mask, self.a, self.r, self.g2,
                                               self.u2)
        )


def _update(q: SetQNetwork, target: SetQNetwork, opt, batch, cfg: UniversalConfig) -> float:
    g, u, mask, a, r, g2, u2 = batch
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
    rb = _Replay(cfg.buffer_size)
    val = validation_envs(cfg.eval_problems, cfg.k_range) if problems is None else problems
    log = TrainLog(net=q, config=cfg)
    best_state = copy.deepcopy(q.state_dict())
    if init is not None:
        log.best_score, log.best_episode = score(policy, val), 0
    total = cfg.episodes * cfg.train_steps
    global_step, eps = 0, cfg.start_e
    for episode in range(cfg.episodes):
        if problems is None:
            env = random_problem(np.random.default_rng([cfg.seed, episode]), cfg.k_range)
            scale = reference_objective(env)
        else:
            env = problems[episode % len(problems)]
            scale = env.reward_scale
        pos = env.space.start.copy()
        if rng.random() < 0.5:
            pos = np.array([rng.choice(axis) for axis in env.space.axes()])
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
            rb.add(obs, nxt, action, reward)
            obs, ret = nxt, ret + reward
            global_step += 1
            if global_step > cfg.learning_starts and global_step % cfg.train_frequency == 0:
                _update(q, target, opt, rb.sample(cfg.batch_size, rng), cfg)
            if global_step % cfg.target_network_frequency == 0:
                target.load_state_dict(q.state_dict())
        log.episodes = episode + 1
        last = (episode + 1 == cfg.episodes) or (time.perf_counter() - t0 > 60 * cfg.minutes)
        if (episode + 1) % cfg.eval_every == 0 or last:
            s = score(policy, val)
            row = {"episode": episode + 1, "epsilon": eps, "return": ret / cfg.train_steps,
                   "val_log2_over_reference": s, "wall_s": time.perf_counter() - t0}
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


def finetune(
    net: SetQNetwork, env: ServiceEnv, cfg: UniversalConfig | None = None
) -> TrainLog:
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


# ------------------------------------------------------------------------------- checkpoints
def save(path: Path, net: SetQNetwork, algo: str, meta: dict[str, Any]) -> None:
    """``path`` (state dict and sizes, loadable with ``weights_only=True``) and a JSON beside."""
    write_torch(  # whole or not at all
        path,
        {
            "format": CHECKPOINT_FORMAT,
            "algo": algo,
            "k_max": K_MAX,
            "power_levels": net.power_levels,
            "hidden": net.hidden,
            "dueling": net.dueling,
            "state_dict": net.state_dict(),
        },
    )
    write_output(path.with_suffix(".json"), json.dumps(meta, indent=2, default=str) + "\n")


def load(path: str | Path) -> tuple[SetQNetwork, dict[str, Any]]:
    """A model written by :func:`save`; any problem is a CheckpointError. The declared sizes
    are bounded and compared with the stored tensors, and the weights must be finite, before
    a network is allocated (:mod:`uavxai.service.guard`)."""
    from uavxai.service import guard

    p = Path(path)
    where = "service model"
    remedy = "Use a model written by `uavxai train SCENARIO --stage service`, or the shipped one."
    data = guard.read_checkpoint(p, where, remedy)
    if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"service model {p}: not a {CHECKPOINT_FORMAT} model.")
    levels = guard.declared_int(data, "power_levels", 1, guard.MAX_POWER_LEVELS, p, where, remedy)
    hidden = guard.declared_int(data, "hidden", 1, guard.MAX_HIDDEN_WIDTH, p, where, remedy)
    dueling = guard.declared_bool(data, "dueling", p, where, remedy)
    try:
        net = guard.build_checked(
            lambda: SetQNetwork(levels, hidden, dueling), data.get("state_dict"), p, where, remedy
        )
        info = {key: data[key] for key in ("algo", "k_max", "power_levels", "dueling")}
    except (KeyError, RuntimeError, TypeError) as exc:
        raise CheckpointError(f"service model {p}: damaged ({exc}).") from None
    return net, info


def config_dict(cfg: UniversalConfig) -> dict[str, Any]:
    return asdict(cfg)


def shipped_path(algo: str, power_levels: int = 6) -> Path:
    from uavxai.paths import service_checkpoints_dir

    return service_checkpoints_dir() / f"universal_{algo}_l{power_levels}.pt"


def main(argv: list[str] | None = None) -> None:
    """``python -m uavxai.service.universal --algo d3qn|dqn [--minutes 30] [--out DIR]``:
    train the universal model and write ``universal_{algo}_l6.pt`` with its JSON."""
    import argparse

    from uavxai import __version__

    parser = argparse.ArgumentParser(prog="python -m uavxai.service.universal")
    parser.add_argument("--algo", choices=("d3qn", "dqn"), default="d3qn")
    parser.add_argument("--minutes", type=float, default=UniversalConfig.minutes)
    parser.add_argument("--episodes", type=int, default=UniversalConfig.episodes)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    dueling = args.algo == "d3qn"
    cfg = UniversalConfig(
        episodes=args.episodes, minutes=args.minutes, seed=args.seed, dueling=dueling,
        double=dueling,
    )
    path = (args.out / f"universal_{args.algo}_l6.pt") if args.out else shipped_path(args.algo)
    path.parent.mkdir(parents=True, exist_ok=True)
    log_path = path.with_suffix(".log.jsonl")
    log_path.unlink(missing_ok=True)
    log = train(cfg, log_path)
    meta = {
        "algo": args.algo,
        "format": CHECKPOINT_FORMAT,
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
        "command": f"python -m uavxai.service.universal --algo {args.algo} --minutes "
        f"{args.minutes} --episodes {args.episodes} --seed {args.seed}",
    }
    save(path, log.net, args.algo, meta)
    print(path, json.dumps(log.rows[-1] if log.rows else {}))


if __name__ == "__main__":
    main()
