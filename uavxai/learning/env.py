"""The episode engine as a Gymnasium environment, for training learned planners.

:class:`EncounterEnv` is an episode of the engine (:mod:`uavxai.sim`) with the planner's seat
taken by the Gymnasium agent: every ``step`` the agent's action (0..8) becomes the decision
the engine sends through the direct command path, as any planner's does (bank command one
``bank_step`` along, acceleration), the kinematic world
(:class:`uavxai.sim.kinematic.KinematicWorld`) flies one decision period, and the engine's
:class:`uavxai.sim.judge.Judge` says how it ended: the same aircraft, intruder pilots,
persistent traffic (``intruders.flow``) and outcome rules as ``uavxai evaluate --dynamics
kinematic``. The agent sees every intruder's exact state (the ``truth`` picture), as the
observation the learned planners' networks see (:mod:`uavxai.avoidance.observation`: the
ownship, the ``n_nearest`` intruders and their closest approach), and is paid the paper's
eq 14 reward. Training's shaped reward is a wrapper
(:class:`uavxai.learning.train.ShapedReward`), its random routes another
(:class:`uavxai.learning.train.RandomEncounters`, through ``reset(options=...)``).

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
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from uavxai.avoidance.model import accel_command, bank_command, ownship_state, terminal_value
from uavxai.avoidance.observation import N_NEAREST, observation_size, observe
from uavxai.avoidance.types import (
    N_ACTIONS,
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
)
from uavxai.scenario import Scenario, Start
from uavxai.sim.build import open_world, start_episode
from uavxai.sim.command import DirectPath
from uavxai.sim.episode import TRUTH, Episode, Observer
from uavxai.sim.spec import EpisodeSpec, episode_spec
from uavxai.surveillance.tracker import truth_beliefs
from uavxai.vocabulary import HOLD, Outcome

# What reset(options=...) may set for the episode, passed on to episode_spec.
RESET_OPTIONS = ("start", "goal", "intruders", "n_intruders")


def _start(start: Start | Ownship | None) -> Start | None:
    """A scenario start; an Ownship's position, speed and heading (it starts wings level)."""
    if start is None or isinstance(start, Start):
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

    Each ``reset(seed=...)`` flies :func:`uavxai.sim.spec.episode_spec` of the scenario at that
    seed (kept as :attr:`episode_spec`): the start, goal, intruders and step budget that
    `uavxai run` and `uavxai evaluate` fly for it. ``options`` may change it for one episode:
    ``start`` (a scenario ``Start`` or an ``Ownship``), ``goal`` (x, y, h), ``intruders`` (a
    list of ``IntruderSpec``) or ``n_intruders`` (how many to draw; the constructor's
    ``n_intruders`` otherwise, None: the scenario's). Rewards are the paper's eq 14,
    paid at the end: 1 at the goal, 0 for a collision or leaving the area, 0.1 at the
    time-out (which is reported as ``truncated``: the observation holds no clock); 0 on every
    other step. The ``info`` dict carries ``outcome`` ("" until the episode ends),
    ``min_separation_m`` over the step, ``distance_m`` to the goal, ``t``, ``steps`` and
    ``intruders`` (how many the episode has), so that a wrapper can shape the reward.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        scenario: Scenario,
        *,
        n_intruders: int | None = None,
        n_nearest: int = N_NEAREST,
        sample_hz: float | None = None,
    ) -> None:
        self.scenario = scenario
        self.config = PlannerConfig.from_scenario(scenario)
        self.n_intruders = n_intruders
        self.n_nearest = n_nearest
        self.sample_hz = sample_hz
        self.action_space = spaces.Discrete(N_ACTIONS)
        size = observation_size(n_nearest)
        self.observation_space = spaces.Box(-np.inf, np.inf, (size,), dtype=np.float32)
        self._seat = _Seat(self.config)
        self._period = _Period()
        self._episode: Episode | None = None
        self._spec: EpisodeSpec | None = None
        self.outcome = ""

    # --------------------------------------------------------------------- gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - set(RESET_OPTIONS)
        if unknown:
            raise ValueError(
                f"reset options {sorted(unknown)} unknown; allowed: {', '.join(RESET_OPTIONS)}"
            )
        world_seed = seed if seed is not None else int(self.np_random.integers(2**31))
        self.close()
        spec = episode_spec(
            self._sampled(self.scenario),
            world_seed,
            n_intruders=options.get("n_intruders", self.n_intruders),
            dynamics="kinematic",
            goal=options.get("goal"),
            start=_start(options.get("start")),
            intruders=options.get("intruders"),
        )
        world = open_world(spec)
        self._spec = spec
        self._episode = start_episode(
            spec.scenario,
            world,
            self._seat,
            DirectPath(world),
            spec.goal,
            max_steps=spec.max_steps,
            observers=[self._period],
            picture=TRUTH,  # the agent sees every intruder exactly
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
        truncated = ended is None and ep.steps >= self.episode_spec.max_steps
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
    def episode_spec(self) -> EpisodeSpec:
        """The episode flown since the last reset (:func:`uavxai.sim.spec.episode_spec`)."""
        if self._spec is None:
            raise RuntimeError("no episode yet; call reset()")
        return self._spec

    @property
    def goal(self) -> np.ndarray:
        """The episode's goal (x, y, h)."""
        return np.asarray(self.episode_spec.goal, dtype=float)

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

    def _sampled(self, sc: Scenario) -> Scenario:
        """The scenario at this env's sample rate (training judges fewer samples)."""
        if self.sample_hz is None:
            return sc
        update: dict[str, Any] = {
            "dynamics": sc.dynamics.model_copy(update={"trajectory_hz": self.sample_hz})
        }
        return sc.model_copy(update=update)

    def _info(self) -> dict:
        return {
            "outcome": self.outcome,
            "min_separation_m": self._period.min_separation_m,
            "distance_m": self.distance_to_goal(),
            "t": self.t,
            "steps": self.steps,
            "intruders": len(self.episode_spec.intruders),
        }
