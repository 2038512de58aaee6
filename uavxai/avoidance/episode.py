"""The kinematic encounter as a Gymnasium environment, for training learned planners.

:class:`EncounterEnv` flies the ownship and the intruders on the encounter model
(:mod:`uavxai.avoidance.model`) one decision period per step, over the 9 actions: the
training ground of the learned planners (Gymnasium API). Episodes of a scenario with any
planner are flown by the episode engine (:func:`uavxai.sim.build.run_kinematic`,
:func:`uavxai.sim.build.fly`), on :class:`uavxai.sim.kinematic.KinematicWorld`.

Intruders are flown by the same pilots as in the JSBSim world
(:func:`uavxai.dynamics.behaviours.make_pilots`): each decision period a pilot gives a bank
command, which its aircraft follows at the roll-rate limit in a coordinated turn at constant
speed and altitude. ``straight`` intruders therefore fly at constant velocity; an intruder
that reaches the edge of the flight area flies on out of it, as in the JSBSim world (it is
then no threat, so traffic thins out over a long episode).

Outcomes are the paper's: ``goal`` (within ``goal_radius_m``), ``collision`` (3-D separation
below ``d_min_m`` at any instant), ``out_of_bounds`` (the ownship leaves the area) and
``timeout`` (``max_steps`` decisions without any of these).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from uavxai.avoidance.model import (
    NONE,
    OUTCOME_NAMES,
    PHI_CMD,
    PSI,
    STATE_DIM,
    TERMINAL_VALUE,
    TIMEOUT,
    EncounterModel,
    Track,
    V,
    ownship_state,
)
from uavxai.avoidance.observation import observation_size, observe
from uavxai.avoidance.types import (
    N_ACTIONS,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
)
from uavxai.errors import UserError
from uavxai.scenario import IntruderSpec, Scenario, Start

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
    from uavxai.dynamics.traffic import draw_intruders

    return draw_intruders(scenario, np.random.default_rng(seed), n_intruders)


def start_state(start: Start | Ownship) -> np.ndarray:
    """An encounter-model state row for a scenario start (wings level) or an Ownship."""
    if isinstance(start, Ownship):
        return ownship_state(start)
    return ownship_state(
        Ownship(start.x, start.y, start.h, start.speed_mps, math.radians(start.heading_deg))
    )


class EncounterEnv(gym.Env):
    """One ownship among intruders; an action (0..8) per decision period (Gymnasium API).

    ``intruder_specs`` is a list, or a function of the episode's random generator that draws
    one (see :meth:`from_scenario`). Intruders with behaviours other than ``straight`` need
    the ``scenario`` their pilots come from. Rewards are the paper's eq 14, paid at the end:
    1 at the goal, 0 for a collision or leaving the area, 0.1 at the time-out (which is
    reported as ``truncated``: the observation holds no clock); 0 on every other step. The
    ``info`` dict carries ``outcome``, ``min_separation_m`` over the step, ``distance_m`` to
    the goal and ``t``, so that a learner can shape its own reward.
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        config: PlannerConfig,
        intruder_specs: IntruderSource,
        goal: Goal,
        start: Start | Ownship,
        *,
        scenario: Scenario | None = None,
        n_nearest: int = 5,
    ) -> None:
        self.config = config
        self.model = EncounterModel(config)
        self.goal = np.asarray(goal, dtype=float)
        self.start = start
        self.scenario = scenario
        self.n_nearest = n_nearest
        self._source = intruder_specs
        self.action_space = spaces.Discrete(N_ACTIONS)
        size = observation_size(n_nearest)
        self.observation_space = spaces.Box(-np.inf, np.inf, (size,), dtype=np.float32)
        self.own = start_state(start)
        self.traffic = np.zeros((0, STATE_DIM))
        self.pilots: list | None = None
        self.t = 0.0
        self.steps = 0
        self.outcome = ""

    @classmethod
    def from_scenario(
        cls, scenario: Scenario, n_intruders: int | None = None, **kwargs: Any
    ) -> EncounterEnv:
        """Episodes of ``scenario``: intruders drawn afresh at every reset, from its seed."""
        from uavxai.dynamics.traffic import draw_intruders

        return cls(
            PlannerConfig.from_scenario(scenario),
            lambda rng: draw_intruders(scenario, rng, n_intruders),
            default_goal(scenario),
            scenario.ownship.start,
            scenario=scenario,
            **kwargs,
        )

    # --------------------------------------------------------------------- gymnasium API
    def reset(
        self, *, seed: int | None = None, options: dict | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        specs = list(self._source(self.np_random) if callable(self._source) else self._source)
        self.own = start_state(self.start)
        self.traffic = np.array(
            [[s.x, s.y, s.h, s.speed_mps, math.radians(s.heading_deg), 0, 0, 0] for s in specs],
            dtype=float,
        ).reshape(len(specs), STATE_DIM)
        self.pilots = self._make_pilots(specs, seed)
        self.t, self.steps, self.outcome = 0.0, 0, ""
        return self.observation(), self._info(math.inf)

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.outcome:
            raise RuntimeError(f"the episode is over ({self.outcome}); call reset()")
        if not 0 <= int(action) < N_ACTIONS:
            raise ValueError(f"action must be 0..{N_ACTIONS - 1}, got {action}")
        cfg = self.config
        period = cfg.decision_period_s
        pos, traffic_end = self._fly_traffic(period)
        seg = self.model.fly(
            self.own[None],
            np.array([int(action)]),
            self.goal,
            period,
            Track.of(pos),
            cull=False,
            exact=True,
        )
        event = int(seg.event[0])
        self.own, self.traffic = seg.end[0], traffic_end
        self.steps += 1
        if event != NONE:
            self.t += float(seg.t_event[0])  # the start of the sub-step where it happened
        else:
            self.t += period
        truncated = event == NONE and self.steps >= cfg.max_steps
        if event != NONE or truncated:
            self.outcome = OUTCOME_NAMES[TIMEOUT if truncated else event]
        reward = TERMINAL_VALUE[TIMEOUT if truncated else event] if self.outcome else 0.0
        info = self._info(float(seg.min_sep[0]))
        return self.observation(), float(reward), event != NONE, truncated, info

    # ------------------------------------------------------------------------- the state
    @property
    def ownship(self) -> Ownship:
        x, y, h, v, psi, phi, cmd, vertical = self.own.tolist()
        return Ownship(
            x=x, y=y, h=h, speed=v, heading=psi, bank=cmd, phi=phi, vertical=int(vertical)
        )

    @property
    def intruders(self) -> list[Intruder]:
        """What the planner sees: every intruder's position and velocity; ids 1..N."""
        v, psi = self.traffic[:, V], self.traffic[:, PSI]
        return [
            Intruder(i + 1, float(r[0]), float(r[1]), float(r[2]), float(vx), float(vy), 0.0)
            for i, (r, vx, vy) in enumerate(
                zip(self.traffic, v * np.sin(psi), v * np.cos(psi), strict=True)
            )
        ]

    def intruder_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(N, 3) positions and velocities of the intruders."""
        v, psi = self.traffic[:, V], self.traffic[:, PSI]
        vel = np.stack([v * np.sin(psi), v * np.cos(psi), np.zeros_like(v)], axis=1)
        return self.traffic[:, :3].copy(), vel

    def observation(self) -> np.ndarray:
        pos, vel = self.intruder_arrays()
        return observe(self.own, pos, vel, self.goal, self.config, self.n_nearest)

    def distance_to_goal(self) -> float:
        return float(np.linalg.norm(self.own[:3] - self.goal))

    # ---------------------------------------------------------------------- internals
    def _info(self, step_min_sep: float) -> dict:
        return {
            "outcome": self.outcome,
            "min_separation_m": step_min_sep,
            "distance_m": self.distance_to_goal(),
            "t": self.t,
            "steps": self.steps,
        }

    def _make_pilots(self, specs: Sequence[IntruderSpec], seed: int | None) -> list | None:
        if all((s.behaviour or "straight") == "straight" for s in specs):
            return None  # constant velocity: no pilot needed
        if self.scenario is None:
            raise UserError(
                "intruders with behaviour random_turns or goal_seeking need the scenario "
                "they come from: EncounterEnv(..., scenario=...) or EncounterEnv.from_scenario"
            )
        from uavxai.dynamics.behaviours import make_pilots

        pilot_seed = seed if seed is not None else int(self.np_random.integers(2**31))
        return make_pilots(self.scenario, specs, pilot_seed)

    def _fly_traffic(self, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """Intruder positions at the step's sub-step instants (n+1, N, 3), and end states."""
        cmd = self.traffic[:, PHI_CMD].copy()
        if self.pilots is not None:
            pos, vel = self.intruder_arrays()
            for i, pilot in enumerate(self.pilots):
                bank, speed = pilot.command(self.t, pos[i], vel[i], float(self.traffic[i, PSI]))
                cmd[i] = bank
                self.traffic[i, V] = speed  # the pilot's speed target, held
        if len(self.traffic) == 0:
            return np.zeros((self.model.substeps(duration) + 1, 0, 3)), self.traffic
        return self.model.fly_commanded(self.traffic, cmd, duration)
