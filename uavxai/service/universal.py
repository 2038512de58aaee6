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
- **Training** (:mod:`uavxai.learning.universal`): every episode a new problem from
  ``layouts.random_problem`` (K uniform in 2..K_MAX, uniform or clustered users, random
  access mode and environment), fading-free, rewards divided by the naive placement's
  objective. Every ``eval_every`` episodes the greedy policy is flown on a fixed validation
  set; the checkpoint keeps the best validation score.
- **Planning** (``plan``): the greedy flight of ``steps`` moves from the region centre at
  100 m with the power branch's levels at every step, stopped when it hovers or revisits a
  point (the walk is deterministic); the best visited point (with the levels the network
  chose there) is "D3QN alone". ``refine`` then polishes it on the same lattice and levels:
  the best single improving change (a move to one of the 6 neighbours, one user's level, or
  one level moved from one user to another) until none improves, from the network's levels
  and from equal power; for K <= 12 the exact power DP of ``grid`` at the final point.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from torch import nn

from uavxai.comms.channel import ENVIRONMENTS, Channel, free_space_loss_db
from uavxai.learning import checkpoint
from uavxai.service.service_env import (
    GAIN_REFERENCE_DISTANCE_M,
    MOVES,
    SearchSpace,
    ServiceEnv,
    levels_to_power,
)

if TYPE_CHECKING:
    from uavxai.service.orbit import OrbitObjective

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


# ------------------------------------------------------------------------------- checkpoints
def load(path: str | Path) -> tuple[SetQNetwork, dict[str, Any]]:
    """A model written by :func:`uavxai.learning.universal.save`, read without trusting it
    (:mod:`uavxai.learning.checkpoint`); any problem is a CheckpointError."""
    src = checkpoint.Source(
        Path(path),
        "service model",
        "Use a model written by `uavxai train SCENARIO --stage service`, or the shipped one.",
    )
    data = checkpoint.read(src, "universal")
    levels = checkpoint.declared_int(data, "power_levels", 1, checkpoint.MAX_POWER_LEVELS, src)
    hidden = checkpoint.declared_int(data, "hidden", 1, checkpoint.MAX_HIDDEN_WIDTH, src)
    dueling = checkpoint.declared_bool(data, "dueling", src)
    net = checkpoint.build_checked(
        lambda: SetQNetwork(levels, hidden, dueling), data.get("state_dict"), src
    )
    info = {"algo": data.get("algo"), "k_max": data.get("k_max"), "power_levels": levels,
            "dueling": dueling}  # fmt: skip
    return net, info


def shipped_path(algo: str, power_levels: int = 6) -> Path:
    from uavxai.paths import service_checkpoints_dir

    return service_checkpoints_dir() / f"universal_{algo}_l{power_levels}.pt"
