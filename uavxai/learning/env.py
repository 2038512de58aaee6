"""The episode engine as a Gymnasium environment, for training learned planners.

:class:`EncounterEnv` is an episode of the engine (:mod:`uavxai.sim`) with the planner's seat
taken by the Gymnasium agent: every ``step`` the agent's action (0..8) becomes the decision
the engine sends through the direct command path, as any planner's does (bank command one
``bank_step`` along, acceleration), the kinematic world
(:class:`uavxai.sim.kinematic.KinematicWorld`) flies one decision period, and the engine's
:class:`uavxai.sim.judge.Judge` says how it ended: the same aircraft, intruder pilots,
persistent traffic (``intruders.flow``) and outcome rules as ``uavxai evaluate --dynamics
kinematic``. The agent sees every intruder's exact state (the ``truth`` picture).

Outcomes are the engine's: ``goal`` (within ``goal_radius_m``), ``collision`` (3-D separation
below ``d_min_m`` at any instant, a pass between two samples included), ``out_of_bounds``
(the ownship leaves the area), and ``timeout`` after ``max_steps`` decisions without any of
these.

Samples: by default the scenario's (``dynamics.trajectory_hz``), as every episode. Training
passes a coarser ``sample_hz``: the world flies each sample in one closed-form piece, so 2
samples per decision cost about a quarter of 10, and the judge still finds every collision
between samples (its closest approach is exact for two straight pieces, and a 0.5 s piece of a
30 deg banked turn strays 0.18 m from its chord at any speed), while the goal and the walls
are seen up to one sample late.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from uavxai.avoidance.model import accel_command, bank_command, ownship_state, terminal_value
from uavxai.avoidance.observation import observation_size, observe
from uavxai.avoidance.types import (
    N_ACTIONS,
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
)
from uavxai.dynamics.traffic import draw_intruders
from uavxai.scenario import IntruderSpec, Scenario, Start
from uavxai.sim.build import start_episode
from uavxai.sim.command import DirectPath
from uavxai.sim.episode import Episode, Observer
from uavxai.sim.kinematic import KinematicWorld
from uavxai.surveillance.tracker import truth_beliefs
from uavxai.vocabulary import HOLD, Outcome

IntruderSource = Sequence[IntruderSpec] | Callable[[np.random.Generator], Sequence[IntruderSpec]]


def default_goal(scenario: Scenario) -> tuple[float, float, float]:
    """The ownship's goal: ``ownship.goal``, else the centre of the users' region at 100 m
    (clamped to the world's altitude band), where the service-point search starts."""
    if scenario.ownship.goal is not None:
        x, y, h = scenario.ownship.goal
        return float(x), float(y), float(h)
    r, (h_lo, h_hi) = scenario.comms.users.region, scenario.world.h
    return 0.5 * (r.x[0] + r.x[1]), 0.5 * (r.y[0] + r.y[1]), min(max(100.0, h_lo), h_hi)


def episode_intruders(
    scenario: Scenario, seed: int, n_intruders: int | None = None
) -> list[IntruderSpec]:
    """The intruders of episode ``seed``: the scenario's list, or ``n_intruders`` drawn."""
    return draw_intruders(scenario, np.random.default_rng(seed), n_intruders)


def _start(start: Start | Ownship) -> Start:
    """A scenario start; an Ownship's position, speed and heading (it starts wings level)."""
    if isinstance(start, Start):
        return start
    heading = math.degrees(start.heading) % 360.0
    return Start(x=start.x, y=start.y, h=start.h, heading_deg=heading, speed_mps=start.speed)


class _Seat:
    """The planner's seat in the engine, taken by the agent: the action it was given becomes
    the decision the engine sends, as a planner's chosen action does."""

    name = "agent"

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config
        self.action = HOLD

    def reset(self, seed: int) -> None:
        """Nothing to seed: the agent decides outside."""

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        a, cfg = self.action, self.config
        return Decision(
            bank_cmd_rad=float(bank_command(own.bank, a, cfg)),
            accel_mps2=float(accel_command(a, cfg)),
            action=a,
            children=[],
            planner=self.name,
            d_min_m=cfg.d_min_m,
        )


class _Period(Observer):
    """The closest approach the engine judged over the last decision period."""

    min_separation_m = math.inf

    def on_period(self, ep: Episode, event, flown_min_m: float) -> None:
        self.min_separation_m = flown_min_m


class EncounterEnv(gym.Env):
    """Episodes of ``scenario`` on the engine; an action (0..8) per decision period.

    ``intruders`` is a list, or a function of the episode's random generator that draws one;
    None draws ``n_intruders`` (None: the scenario's count) afresh at every reset, from the
    reset's seed. ``goal`` None: :func:`default_goal`; ``start`` None: the scenario's
    (``start`` and ``goal`` may be changed between episodes). Rewards are the paper's eq 14,
    paid at the end: 1 at the goal, 0 for a collision or leaving the area, 0.1 at the
    time-out (which is reported as ``truncated``: the observation holds no clock); 0 on every
    other step. The ``info`` dict carries ``outcome``, ``min_separation_m`` over the step,
    ``distance_m`` to the goal, ``t`` and ``steps``, so that a learner can shape its own
    reward.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        scenario: Scenario,
        *,
        intruders: IntruderSource | None = None,
        n_intruders: int | None = None,
        goal: Goal | None = None,
        start: Start | Ownship | None = None,
        n_nearest: int = 5,
        sample_hz: float | None = None,
    ) -> None:
        self.scenario = scenario
        self.config = PlannerConfig.from_scenario(scenario)
        self.goal = np.asarray(default_goal(scenario) if goal is None else goal, dtype=float)
        self.start: Start | Ownship = scenario.ownship.start if start is None else start
        self.n_nearest = n_nearest
        self.sample_hz = sample_hz
        if intruders is None:
            intruders = partial(draw_intruders, scenario, count=n_intruders)
        self._source = intruders
        self.action_space = spaces.Discrete(N_ACTIONS)
        size = observation_size(n_nearest)
        self.observation_space = spaces.Box(-np.inf, np.inf, (size,), dtype=np.float32)
        self._seat = _Seat(self.config)
        self._period = _Period()
        self._episode: Episode | None = None
        self.outcome = ""

    # --------------------------------------------------------------------- gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        specs = list(self._source(self.np_random) if callable(self._source) else self._source)
        world_seed = seed if seed is not None else int(self.np_random.integers(2**31))
        self.close()
        sc = self._flown_scenario(world_seed)
        world = KinematicWorld(sc, intruders=specs, seed=world_seed)
        self._episode = start_episode(
            sc,
            world,
            self._seat,
            DirectPath(world),
            tuple(float(g) for g in self.goal),
            max_steps=self.config.max_steps,
            observers=[self._period],
            picture=truth_beliefs,
        )
        self.outcome = ""
        self._period.min_separation_m = math.inf
        return self.observation(), self._info()

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.outcome:
            raise RuntimeError(f"the episode is over ({self.outcome}); call reset()")
        if not 0 <= int(action) < N_ACTIONS:
            raise ValueError(f"action must be 0..{N_ACTIONS - 1}, got {action}")
        ep = self._live()
        self._seat.action = int(action)
        ended = ep.advance(ep.decide())
        truncated = ended is None and ep.steps >= self.config.max_steps
        if truncated:
            ended = Outcome.TIMEOUT
        reward = 0.0
        if ended is not None:
            self.outcome = ended.value
            reward = terminal_value(self.outcome)
        terminated = ended is not None and not truncated
        return self.observation(), float(reward), terminated, truncated, self._info()

    def close(self) -> None:
        if self._episode is not None:
            self._episode.world.close()

    # ------------------------------------------------------------------------- the state
    @property
    def t(self) -> float:
        return self._live().state.t

    @property
    def steps(self) -> int:
        return self._live().steps

    @property
    def ownship(self) -> Ownship:
        """The ownship as a planner sees it."""
        return self._live().ownship()

    @property
    def own(self) -> np.ndarray:
        """The ownship as an encounter-model state row."""
        return ownship_state(self.ownship)

    @property
    def intruders(self) -> list[Intruder]:
        """What a planner with the ``truth`` picture sees: every intruder's position,
        velocity and turn rate."""
        return truth_beliefs(self._live().state)

    def intruder_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) positions and velocities (over the ground) of the intruders."""
        s = self._live().state
        return s.pos[1:].copy(), s.vel[1:].copy()

    def observation(self) -> np.ndarray:
        pos, vel = self.intruder_arrays()
        return observe(self.own, pos, vel, self.goal, self.config, self.n_nearest)

    def distance_to_goal(self) -> float:
        return float(np.linalg.norm(self._live().state.pos[0] - self.goal))

    # ---------------------------------------------------------------------- internals
    def _live(self) -> Episode:
        if self._episode is None:
            raise RuntimeError("no episode yet; call reset()")
        return self._episode

    def _flown_scenario(self, seed: int) -> Scenario:
        """The scenario with this episode's start, seed and sample rate."""
        sc = self.scenario
        update: dict[str, Any] = {
            "seed": int(seed),
            "ownship": sc.ownship.model_copy(update={"start": _start(self.start)}),
        }
        if self.sample_hz is not None:
            update["dynamics"] = sc.dynamics.model_copy(update={"trajectory_hz": self.sample_hz})
        return sc.model_copy(update=update)

    def _info(self) -> dict:
        return {
            "outcome": self.outcome,
            "min_separation_m": self._period.min_separation_m,
            "distance_m": self.distance_to_goal(),
            "t": self.t,
            "steps": self.steps,
        }
