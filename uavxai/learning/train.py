"""Training of the learned avoidance baselines, DQN and Safe-DQN, on the episode engine's
kinematic world (:class:`uavxai.learning.env.EncounterEnv`; `uavxai train SCENARIO --stage
avoidance --algo dqn|safe_dqn`).

One file, top to bottom, CleanRL style: hyper-parameters in :class:`Hyperparameters`, the
rewards in :func:`rewards`, the envs as Gymnasium wrappers, then the loop in :func:`train`.

The env's observation is what the networks see and its reward the paper's eq 14; training
wraps it twice (:func:`training_env`): :class:`RandomEncounters` draws each episode through
``reset(options=...)`` and :class:`ShapedReward` pays the shaped reward below. ``n_envs`` of
them fly side by side in a ``gymnasium.vector.SyncVectorEnv`` (one batched forward pass for
all), which resets an env in the step that ends its episode.

Episodes are the scenario's (its start, goal, intruder behaviour, speeds and altitudes) with a
fresh intruder count drawn from ``intruders`` each time, so that one network serves 5 or 40
intruders. A share of episodes (``random_start_share``) starts and ends elsewhere in the
flight area, so that the policy has seen walls and goals from every side and does not just
memorise the scenario's one route.

Rewards. The paper's eq 14 pays only at the end (goal 1, time-out 0.1, collision 0), which a
DQN cannot learn from in a few thousand episodes; both baselines are given the same, denser
signal split in two parts, as Safe-DQN needs:

- goal: progress towards the goal per step (metres closed over ``progress_scale_m``), less
  ``step_cost`` per decision (so that circling is never free), plus ``arrival_reward`` at the
  goal, plus a potential-based term on the heading error to the goal (it credits turning
  towards the goal at once without changing the optimal policy);
- safety: a penalty growing as the separation falls below ``warn_separation_m`` (quadratic in
  the shortfall, up to ``separation_weight`` per step), a cost per step on the worst
  *predicted* conflict (closest approach at current velocities, see :func:`situation`), which
  tells a turn that resolves a conflict from one that does not at once rather than seconds
  later, and ``-failure_penalty`` for a collision or leaving the flight area.

Targets are n-step returns (``n_step``), so that a collision's penalty reaches the decisions
that could still have avoided it sooner than one step per update. DQN learns one Q-network
on the sum of the parts (double-DQN targets). Safe-DQN learns two, one per
part; both are bootstrapped on the action Safe-DQN itself would take next (the best
``Q_goal + Q_safety`` among actions with ``Q_safety`` at least the median), so their sum is
the value of the policy that acts. A time-out is a truncation: it is bootstrapped, since the
observation holds no clock.
"""

from __future__ import annotations

import copy
import csv
import io
import json
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from uavxai.avoidance.learned import (
    ALGOS,
    QNetwork,
    head_names,
    load_checkpoint,
    obs_dim,
    safe_action,
    save_checkpoint,
)
from uavxai.avoidance.types import N_ACTIONS, PlannerConfig
from uavxai.errors import UserError
from uavxai.geometry import bearing, closest_point_of_approach, wrap_angle
from uavxai.learning.env import EncounterEnv
from uavxai.learning.replay import ReplayBuffer, n_step_return
from uavxai.outputs import write_figure, write_output
from uavxai.scenario import Scenario, Start
from uavxai.sim.spec import episode_goal


@dataclass(frozen=True)
class Hyperparameters:
    episodes: int = 3500
    seed: int = 0
    intruders: tuple[int, int] = (5, 40)  # count drawn uniformly per episode, inclusive
    random_start_share: float = 0.5
    n_envs: int = 8  # episodes flown side by side (one batched forward pass for all)
    n_nearest: int = 8
    # Samples per second the engine judges: 2 (0.5 s pieces) flies about 4x faster than the
    # scenario's 10 and still finds every collision between samples (see uavxai.learning.env).
    sample_hz: float = 2.0
    hidden: tuple[int, ...] = (128, 128)
    learning_rate: float = 5e-4
    buffer_size: int = 200_000
    batch_size: int = 128
    gamma: float = 0.99
    n_step: int = 3  # returns over n steps: a collision's penalty reaches back faster
    tau: float = 0.01  # soft target update per gradient step
    start_e: float = 1.0
    end_e: float = 0.03
    exploration_fraction: float = 0.4  # of the episodes
    learning_starts: int = 5_000  # transitions before the first gradient step
    train_frequency: int = 2  # transitions per gradient step
    max_grad_norm: float = 10.0
    # rewards (see the module docstring)
    progress_scale_m: float = 500.0
    arrival_reward: float = 1.0
    warn_separation_m: float = 150.0
    separation_weight: float = 0.2
    failure_penalty: float = 2.0
    step_cost: float = 0.01  # per decision, in the goal part: circling is never free
    heading_weight: float = 0.1  # potential on the cosine of the heading error to the goal
    conflict_weight: float = 0.1  # per decision at the worst predicted conflict
    conflict_horizon_s: float = 20.0
    log_window: int = 100  # episodes in the rolling rates
    # Model selection: DQN's greedy policy swings from one snapshot to the next, so every
    # `validate_every` episodes it flies the scenario's route on held-out seeds and the
    # snapshot with the best goal rate minus collision rate is the one kept.
    validate_every: int = 250
    validation_intruders: tuple[int, ...] = (5, 20, 40)
    validation_episodes: int = 8  # per intruder count
    validation_seed: int = 1_000_000  # campaigns use scenario.seed + 0, 1, ...


DEFAULT_EPISODES = Hyperparameters.episodes


@dataclass(frozen=True)
class Situation:
    """What the rewards look at in a state."""

    distance_m: float  # to the goal
    heading_error_rad: float  # between the heading and the bearing to the goal
    conflict: float  # 0..1, the worst predicted loss of separation (see :func:`situation`)


def situation(
    hp: Hyperparameters, own: np.ndarray, pos: np.ndarray, vel: np.ndarray, goal: np.ndarray
) -> Situation:
    """The rewards' view of an encounter-model state row among intruders at ``pos``, ``vel``.

    ``conflict`` is the largest, over intruders, of ``(1 - dcpa / warn) (1 - tcpa / horizon)``
    for a closest approach within ``warn_separation_m`` and ``conflict_horizon_s`` at the
    current velocities: 1 for a collision course now, 0 when nothing converges soon.
    """
    x, y, h, v, psi = (float(c) for c in own[:5])
    dx, dy = float(goal[0]) - x, float(goal[1]) - y
    error = wrap_angle(bearing(dx, dy) - psi)
    conflict = 0.0
    if len(pos):
        rel = pos - own[:3]
        rv = vel - (v * math.sin(psi), v * math.cos(psi), 0.0)
        tcpa, dcpa = closest_point_of_approach(rel, rv, hp.conflict_horizon_s)
        worst = (1.0 - dcpa / hp.warn_separation_m) * (1.0 - tcpa / hp.conflict_horizon_s)
        conflict = float(np.clip(worst.max(), 0.0, 1.0))
    return Situation(math.dist((x, y, h), goal), error, conflict)


def rewards(
    hp: Hyperparameters, outcome: str, before: Situation, after: Situation, min_sep: float
) -> tuple[float, float]:
    """(goal reward, safety reward) of one step from ``before`` to ``after``; ``min_sep`` is
    the smallest separation flown during the step."""
    goal = (before.distance_m - after.distance_m) / hp.progress_scale_m - hp.step_cost
    # Potential-based shaping (Ng et al. 1999): credit for turning towards the goal at once,
    # with the optimal policy unchanged; a terminal state's potential is 0.
    potential_after = 0.0 if outcome else hp.heading_weight * math.cos(after.heading_error_rad)
    goal += hp.gamma * potential_after - hp.heading_weight * math.cos(before.heading_error_rad)
    if outcome == "goal":
        goal += hp.arrival_reward
    shortfall = max(0.0, 1.0 - min_sep / hp.warn_separation_m) if math.isfinite(min_sep) else 0.0
    safety = -hp.separation_weight * shortfall**2 - hp.conflict_weight * after.conflict
    if outcome in ("collision", "out_of_bounds"):
        safety -= hp.failure_penalty
    return goal, safety


# ------------------------------------------------------------------------------ environments
class ShapedReward(gym.Wrapper):
    """The shaped reward of the module docstring in place of the env's eq 14: ``reward`` is
    goal + safety, and ``info`` carries the two parts (``reward_goal``, ``reward_safety``:
    Safe-DQN learns one network per part) beside the env's own ``eq14_reward``."""

    def __init__(self, env: gym.Env, hp: Hyperparameters) -> None:
        super().__init__(env)
        self.hp = hp
        self._before: Situation | None = None

    def _situation(self) -> Situation:
        e = self.env.unwrapped
        pos, vel = e.intruder_arrays()
        return situation(self.hp, e.own, pos, vel, e.goal)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._before = self._situation()
        return obs, info

    def step(self, action):
        obs, eq14, terminated, truncated, info = self.env.step(action)
        after = self._situation()
        assert self._before is not None  # reset() came first: the env checks that
        goal, safety = rewards(
            self.hp, info["outcome"], self._before, after, info["min_separation_m"]
        )
        self._before = after
        info = {**info, "eq14_reward": eq14, "reward_goal": goal, "reward_safety": safety}
        return obs, goal + safety, terminated, truncated, info


class RandomEncounters(gym.Wrapper):
    """Training's episodes: every reset draws a fresh intruder count from ``hp.intruders``
    and, for ``random_start_share`` of them, a random route (start and goal anywhere in the
    area), passed to the env through ``reset(options=...)``. Its draws come from a generator
    seeded by the first ``reset(seed=...)``, so a vector env's auto-resets repeat with it."""

    def __init__(self, env: gym.Env, hp: Hyperparameters) -> None:
        super().__init__(env)
        self.hp = hp
        self.rng = np.random.default_rng(hp.seed)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        rng, hp = self.rng, self.hp
        drawn: dict = {"n_intruders": int(rng.integers(hp.intruders[0], hp.intruders[1] + 1))}
        if rng.random() < hp.random_start_share:
            drawn["start"], drawn["goal"] = self._random_route()
        return self.env.reset(seed=int(rng.integers(2**31)), options={**drawn, **(options or {})})

    def _random_route(self) -> tuple[Start, tuple[float, float, float]]:
        """A start and goal anywhere in the area, at least 600 m apart, 150 m off the walls."""
        sc = self.env.unwrapped.scenario
        w = sc.world
        margin = 150.0
        lo = np.array([w.x[0] + margin, w.y[0] + margin])
        hi = np.array([w.x[1] - margin, w.y[1] - margin])
        while True:
            a, b = self.rng.uniform(lo, hi), self.rng.uniform(lo, hi)
            if np.linalg.norm(a - b) >= 600.0:
                break
        h = float(np.clip(sc.ownship.start.h, *w.h))
        start = Start(
            x=float(a[0]),
            y=float(a[1]),
            h=h,
            heading_deg=float(self.rng.uniform(0.0, 360.0)),
            speed_mps=float(self.rng.uniform(*sc.avoidance.speed_mps)),
        )
        goal_h = episode_goal(sc)[2]  # the height the scenario's own goal is at
        return start, (float(b[0]), float(b[1]), goal_h)


def training_env(scenario: Scenario, hp: Hyperparameters) -> gym.Env:
    """One of training's envs: the scenario's encounters (:class:`RandomEncounters`) with the
    shaped reward (:class:`ShapedReward`)."""
    env = EncounterEnv(scenario, n_nearest=hp.n_nearest, sample_hz=hp.sample_hz)
    return ShapedReward(RandomEncounters(env, hp), hp)


def training_envs(scenario: Scenario, hp: Hyperparameters) -> gym.vector.SyncVectorEnv:
    """``hp.n_envs`` training envs side by side (one batched forward pass for all), reset in
    the step that ends an episode (``final_obs`` and ``final_info`` keep its end)."""
    return gym.vector.SyncVectorEnv(
        [lambda: training_env(scenario, hp)] * hp.n_envs,
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )


# ---------------------------------------------------------------------------------- training
@dataclass
class TrainResult:
    nets: dict[str, QNetwork]  # the snapshot that validated best
    curve: list[dict] = field(default_factory=list)
    td_losses: list[float] = field(default_factory=list)
    validation: list[dict] = field(default_factory=list)
    best_episode: int = 0  # the episode count at the kept snapshot
    wall_s: float = 0.0


def validate(
    scenario: Scenario, hp: Hyperparameters, policy, config: PlannerConfig | None = None
) -> dict[str, float]:
    """Greedy episodes of the scenario's own route at each of ``validation_intruders``, on
    seeds (``validation_seed`` + i) apart from any campaign's: goal and collision rates."""
    outcomes = []
    env = EncounterEnv(scenario, n_nearest=hp.n_nearest, sample_hz=hp.sample_hz)
    for n in hp.validation_intruders:
        for i in range(hp.validation_episodes):
            obs, info = env.reset(seed=hp.validation_seed + i, options={"n_intruders": n})
            while not info["outcome"]:
                obs, _, _, _, info = env.step(int(policy(obs[None])[0]))
            outcomes.append(info["outcome"])
    env.close()
    k = len(outcomes)
    goal_rate, collision_rate = outcomes.count("goal") / k, outcomes.count("collision") / k
    return {
        "goal_rate": goal_rate,
        "collision_rate": collision_rate,
        "score": goal_rate - collision_rate,
    }


def train(
    scenario: Scenario,
    algo: str,
    hp: Hyperparameters,
    *,
    init: dict[str, QNetwork] | None = None,
    on_episode=None,
) -> TrainResult:
    """Train ``algo`` ('dqn' or 'safe_dqn') on ``scenario``'s encounters; ``init`` warm-starts
    from trained networks. ``on_episode(row)`` sees every finished episode."""
    if algo not in ALGOS:
        raise UserError(f"--algo {algo}: the avoidance stage trains {', '.join(ALGOS)}.")
    # Setup: seeded networks, optimiser and replay buffer, the vector of training envs.
    wall0 = time.perf_counter()
    torch.manual_seed(hp.seed)
    rng = np.random.default_rng(hp.seed)
    learner = _QLearner.create(algo, hp, init)
    buffer = _replay(hp)
    envs = training_envs(scenario, hp)
    obs, _ = envs.reset(seed=hp.seed)
    run = _Run(hp, [[] for _ in range(hp.n_envs)], np.zeros((hp.n_envs, 2)),
               np.full(hp.n_envs, math.inf))  # fmt: skip
    result = TrainResult(nets=learner.q)
    best = (-math.inf, learner.snapshot())
    explore_episodes = max(1, int(hp.exploration_fraction * hp.episodes))
    while (finished := len(result.curve)) < hp.episodes:
        # Collect: epsilon-greedy actions for every env from one batched forward pass.
        run.epsilon = hp.start_e + (hp.end_e - hp.start_e) * min(1.0, finished / explore_episodes)
        explore = rng.random(hp.n_envs) < run.epsilon
        actions = np.where(explore, rng.integers(0, N_ACTIONS, hp.n_envs), learner.act(obs))
        nxt, _, terminated, truncated, infos = envs.step(actions)
        for i in range(hp.n_envs):
            ended = bool(terminated[i] or truncated[i])
            info = _info_at(infos, i, ended)
            last = infos["final_obs"][i] if ended else nxt[i]
            _store(run, i, obs[i], int(actions[i]), info, last, bool(terminated[i]), buffer)
            run.transitions += 1
            # Update: one gradient step every train_frequency transitions once warmed up.
            if run.transitions >= hp.learning_starts and run.transitions % hp.train_frequency == 0:
                batch = Batch(**buffer.sample(rng, hp.batch_size))
                run.losses.append(learner.gradient_step(batch))
            if ended and len(result.curve) < hp.episodes:
                row = run.episode_row(len(result.curve), i, info)
                result.curve.append(row)
                # Evaluate: validate now and then, keeping the best snapshot.
                best = _evaluate(scenario, hp, learner, result, row, best)
                if on_episode:
                    on_episode(row)
        obs = nxt
    envs.close()
    result.td_losses = run.losses
    result.wall_s = time.perf_counter() - wall0
    for k, net in learner.q.items():
        net.load_state_dict(best[1][k])
        net.eval()
    return result


def _replay(hp: Hyperparameters) -> ReplayBuffer:
    """n-step transitions; rewards kept in two parts (goal, safety), DQN learns their sum;
    ``discount`` is gamma^k, 0 after a terminal state (no bootstrap)."""
    n_obs = obs_dim(hp.n_nearest)
    return ReplayBuffer(
        hp.buffer_size,
        {
            "obs": ((n_obs,), np.float32),
            "action": ((), np.int64),
            "reward": ((2,), np.float32),
            "next_obs": ((n_obs,), np.float32),
            "discount": ((), np.float32),
        },
    )


def _info_at(infos: dict, i: int, ended: bool) -> dict:
    """Env ``i``'s info of the step from the vector env's batched infos (of the episode's end
    when it ended: the vector env has already reset it)."""
    source = infos["final_info"] if ended else infos
    skip = ("final_info", "final_obs")
    return {k: v[i] for k, v in source.items() if not k.startswith("_") and k not in skip}


@dataclass
class _Run:
    """The state of a training run between steps: each env's last n steps, returns and
    closest approach of its episode; the exploration rate, transitions, losses and recent
    outcomes."""

    hp: Hyperparameters
    windows: list[list[tuple]]  # per env, the last n (obs, action, (goal, safety) reward)
    returns: np.ndarray  # (n_envs, 2)
    min_sep: np.ndarray  # (n_envs,)
    epsilon: float = 1.0
    transitions: int = 0
    losses: list[float] = field(default_factory=list)
    recent: list[str] = field(default_factory=list)

    def episode_row(self, episode: int, i: int, info: dict) -> dict:
        """The learning-curve row of the episode env ``i`` just finished (CURVE_COLUMNS); the
        env's returns and closest approach start again."""
        self.recent = (self.recent + [str(info["outcome"])])[-self.hp.log_window :]
        recent, losses = self.recent, self.losses
        row = {
            "episode": episode,
            "intruders": int(info["intruders"]),
            "outcome": str(info["outcome"]),
            "steps": int(info["steps"]),
            "return_goal": round(float(self.returns[i, 0]), 4),
            "return_safety": round(float(self.returns[i, 1]), 4),
            "min_separation_m": round(float(self.min_sep[i]), 2),
            "epsilon": round(self.epsilon, 4),
            "td_loss": round(float(np.mean(losses[-200:])), 6) if losses else math.nan,
            "goal_rate": recent.count("goal") / len(recent),
            "collision_rate": recent.count("collision") / len(recent),
            "transitions": self.transitions,
            "val_goal_rate": math.nan,
            "val_collision_rate": math.nan,
        }
        self.returns[i] = 0.0
        self.min_sep[i] = math.inf
        return row


def _store(
    run: _Run,
    i: int,
    obs: np.ndarray,
    action: int,
    info: dict,
    next_obs: np.ndarray,
    terminated: bool,
    buffer: ReplayBuffer,
) -> None:
    """Account env ``i``'s step and store the n-step transitions it completes (all that are
    left when its episode ended)."""
    r = (float(info["reward_goal"]), float(info["reward_safety"]))
    run.returns[i] += r
    run.min_sep[i] = min(run.min_sep[i], float(info["min_separation_m"]))
    window = run.windows[i]
    window.append((obs.copy(), action, r))
    ended = bool(info["outcome"])
    while len(window) == run.hp.n_step or (ended and window):
        buffer.add(
            obs=window[0][0],
            action=window[0][1],
            reward=n_step_return([w[2] for w in window], run.hp.gamma),
            next_obs=next_obs,
            discount=0.0 if terminated else run.hp.gamma ** len(window),
        )
        window.pop(0)


@dataclass
class _QLearner:
    """The algorithm's online and target Q-networks and their optimiser."""

    algo: str
    hp: Hyperparameters
    q: dict[str, QNetwork]
    target: dict[str, QNetwork]
    params: list[torch.nn.Parameter]
    optimizer: torch.optim.Optimizer

    @classmethod
    def create(cls, algo: str, hp: Hyperparameters, init: dict[str, QNetwork] | None) -> _QLearner:
        """Fresh networks (or copies of ``init``); the targets start equal to them. The order
        of construction fixes the draws from torch's seeded generator."""
        heads = head_names(algo)
        n_obs = obs_dim(hp.n_nearest)
        q = {k: QNetwork(n_obs, hp.hidden) for k in heads}
        if init is not None:
            for k in heads:
                q[k].load_state_dict(init[k].state_dict())
        target = {k: QNetwork(n_obs, hp.hidden) for k in heads}
        for k in heads:
            target[k].load_state_dict(q[k].state_dict())
        params = [p for k in heads for p in q[k].parameters()]
        optimizer = torch.optim.Adam(params, lr=hp.learning_rate)
        return cls(algo, hp, q, target, params, optimizer)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """Greedy actions for a batch of observations (Safe-DQN: its safe argmax)."""
        with torch.no_grad():
            x = torch.as_tensor(obs)
            if self.algo == "dqn":
                return self.q["q"](x).argmax(dim=1).numpy()
            return safe_action(self.q["goal"](x), self.q["safety"](x)).numpy()

    def gradient_step(self, batch: Batch) -> float:
        """One clipped Adam step on the TD loss, then a soft (Polyak) target update."""
        loss = td_loss(self.algo, self.q, self.target, batch)
        self.optimizer.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(self.params, self.hp.max_grad_norm)
        self.optimizer.step()
        with torch.no_grad():
            for k, net in self.q.items():
                for p_t, p in zip(self.target[k].parameters(), net.parameters(), strict=True):
                    p_t.lerp_(p, self.hp.tau)
        return loss.item()

    def snapshot(self) -> dict[str, dict]:
        """Deep copies of the online networks' weights, to restore the best one at the end."""
        return {k: copy.deepcopy(net.state_dict()) for k, net in self.q.items()}


def _evaluate(
    scenario: Scenario,
    hp: Hyperparameters,
    learner: _QLearner,
    result: TrainResult,
    row: dict,
    best: tuple[float, dict[str, dict]],
) -> tuple[float, dict[str, dict]]:
    """Every ``validate_every`` episodes (and after the last) validate the greedy policy,
    record it in ``result`` and ``row``; return the best (score, snapshot) so far."""
    done = len(result.curve)
    if done % hp.validate_every == 0 or done == hp.episodes:
        val = {"episode": done, **validate(scenario, hp, learner.act)}
        result.validation.append(val)
        row["val_goal_rate"] = val["goal_rate"]
        row["val_collision_rate"] = val["collision_rate"]
        if val["score"] > best[0]:
            best = (val["score"], learner.snapshot())
            result.best_episode = done
    return best


@dataclass
class Batch:
    obs: torch.Tensor  # (B, n_obs)
    action: torch.Tensor  # (B,) int64
    reward: torch.Tensor  # (B, 2): goal, safety
    next_obs: torch.Tensor  # (B, n_obs): the state n steps later
    discount: torch.Tensor  # (B,) gamma^n, or 0 where the episode terminated (no bootstrap)


def td_loss(
    algo: str, q: dict[str, QNetwork], target: dict[str, QNetwork], batch: Batch
) -> torch.Tensor:
    """The Huber TD loss of one batch of n-step transitions, summed over the algorithm's
    Q-networks."""
    discount = batch.discount
    a = batch.action[:, None]
    with torch.no_grad():
        nxt = batch.next_obs
        if algo == "dqn":
            a_next = q["q"](nxt).argmax(dim=1, keepdim=True)  # double DQN
            y = {"q": batch.reward.sum(dim=1) + discount * _at(target["q"](nxt), a_next)}
        else:
            a_next = safe_action(q["goal"](nxt), q["safety"](nxt))[:, None]
            y = {
                name: batch.reward[:, col] + discount * _at(target[name](nxt), a_next)
                for col, name in enumerate(("goal", "safety"))
            }
    return sum(
        torch.nn.functional.smooth_l1_loss(_at(q[k](batch.obs), a), y[k]) for k in head_names(algo)
    )


def _at(values: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    return values.gather(1, actions).squeeze(1)


# ------------------------------------------------------------------------------ the command
CURVE_COLUMNS = (
    "episode",
    "intruders",
    "outcome",
    "steps",
    "return_goal",
    "return_safety",
    "min_separation_m",
    "epsilon",
    "td_loss",
    "goal_rate",
    "collision_rate",
    "transitions",
    "val_goal_rate",
    "val_collision_rate",
)


def train_command(
    scenario: Scenario,
    algo: str,
    episodes: int | None,
    out: Path,
    *,
    hp: Hyperparameters | None = None,
) -> dict:
    """`uavxai train --stage avoidance`: train with a progress bar and write ``out/model.pt``
    (with ``out/model.json`` saying what it was trained on), ``out/learning_curve.csv`` and
    ``out/learning_curve.png``; return a short report.

    A checkpoint named in the scenario (``avoidance.checkpoint``) is the starting point
    (it must be a model of ``algo``); without one the networks start from scratch.
    """
    from uavxai.progress import progress_bar

    if algo not in ALGOS:
        raise UserError(f"--algo {algo}: the avoidance stage trains {', '.join(ALGOS)}.")
    hp, init = _command_setup(scenario, algo, episodes, hp)
    torch.set_num_threads(1)
    out.mkdir(parents=True, exist_ok=True)
    with progress_bar() as progress:
        bar = progress.add_task(f"{algo} on {scenario.name}", total=hp.episodes)

        def on_episode(row: dict) -> None:
            progress.update(
                bar,
                advance=1,
                description=(
                    f"{algo}: goal {row['goal_rate']:.2f} collision {row['collision_rate']:.2f} "
                    f"eps {row['epsilon']:.2f}"
                ),
            )

        result = train(scenario, algo, hp, init=init, on_episode=on_episode)

    last = result.curve[-hp.log_window :]
    report = {
        "algo": algo,
        "scenario": scenario.name,
        "episodes": len(result.curve),
        "transitions": result.curve[-1]["transitions"] if result.curve else 0,
        "final_goal_rate": sum(r["outcome"] == "goal" for r in last) / max(1, len(last)),
        "final_collision_rate": sum(r["outcome"] == "collision" for r in last) / max(1, len(last)),
        "final_window_episodes": len(last),
        "kept_snapshot_episode": result.best_episode,
        "validation": result.validation,
        "wall_s": round(result.wall_s, 1),
        "model": str(out / "model.pt"),
    }
    _write_outputs(scenario, algo, hp, result, report, out)
    return report


def _command_setup(
    scenario: Scenario, algo: str, episodes: int | None, hp: Hyperparameters | None
) -> tuple[Hyperparameters, dict[str, QNetwork] | None]:
    """The hyper-parameters to train with (``--episodes`` applied) and the warm-start networks
    of ``avoidance.checkpoint``, if any. A warm start keeps its own network sizes, so they
    override ``hp``'s."""
    hp = hp or Hyperparameters(seed=scenario.seed)
    if episodes is not None:
        if episodes < 1:
            raise UserError(f"--episodes {episodes}: must be >= 1.")
        hp = Hyperparameters(**{**asdict(hp), "episodes": int(episodes)})
    init = None
    if scenario.avoidance.checkpoint is not None:
        init, info = load_checkpoint(scenario.avoidance.checkpoint, algo)
        if info["n_nearest"] != hp.n_nearest or list(info["hidden"]) != list(hp.hidden):
            hp = Hyperparameters(
                **{**asdict(hp), "n_nearest": info["n_nearest"], "hidden": tuple(info["hidden"])}
            )
    return hp, init


def _write_outputs(
    scenario: Scenario,
    algo: str,
    hp: Hyperparameters,
    result: TrainResult,
    report: dict,
    out: Path,
) -> None:
    """``out/model.pt`` with ``out/model.json`` saying what it was trained on (the same meta
    travels inside the checkpoint), ``out/learning_curve.csv`` and its plot."""
    meta = {
        "trained_on": {
            "scenario": scenario.name,
            "seed": scenario.seed,
            "intruders": list(hp.intruders),
            "behaviour": scenario.intruders.behaviour,
            "episodes": len(result.curve),
            "warm_start": scenario.avoidance.checkpoint,
        },
        "hyperparameters": asdict(hp),
        "report": {k: v for k, v in report.items() if k != "model"},
        "versions": {"torch": str(torch.__version__)},
    }
    save_checkpoint(
        out / "model.pt", algo, result.nets, hidden=hp.hidden, n_nearest=hp.n_nearest, meta=meta
    )
    write_output(out / "model.json", json.dumps({"algo": algo, **meta}, indent=2) + "\n")
    curve = io.StringIO()
    w = csv.DictWriter(curve, fieldnames=CURVE_COLUMNS)
    w.writeheader()
    w.writerows(result.curve)
    write_output(out / "learning_curve.csv", curve.getvalue())
    plot_learning_curve(result.curve, out / "learning_curve.png", f"{algo} on {scenario.name}")


def plot_learning_curve(curve: list[dict], path: Path, title: str) -> None:
    """Rolling goal and collision rates, and the TD loss, against the episode."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ep = [r["episode"] for r in curve]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 5.5), dpi=110, sharex=True)
    top.plot(ep, [r["goal_rate"] for r in curve], label="goal rate")
    top.plot(ep, [r["collision_rate"] for r in curve], label="collision rate")
    top.plot(ep, [r["epsilon"] for r in curve], label="epsilon", linestyle=":", color="grey")
    val = [r for r in curve if not math.isnan(r["val_goal_rate"])]
    top.plot([r["episode"] for r in val], [r["val_goal_rate"] for r in val], "o", color="tab:blue",
             label="validation goal rate (greedy)")  # fmt: skip
    top.plot([r["episode"] for r in val], [r["val_collision_rate"] for r in val], "o",
             color="tab:orange", label="validation collision rate (greedy)")  # fmt: skip
    top.set_ylim(-0.02, 1.02)
    top.set_ylabel("rolling rate")
    top.legend(fontsize=8)
    top.grid(alpha=0.3)
    top.set_title(title, fontsize=10)
    bottom.plot(ep, [r["td_loss"] for r in curve], color="tab:red")
    bottom.set_yscale("log")
    bottom.set_ylabel("TD loss")
    bottom.set_xlabel("episode")
    bottom.grid(alpha=0.3)
    fig.tight_layout()
    write_figure(path, fig)
    plt.close(fig)
