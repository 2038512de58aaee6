"""What one episode is, decided in one place: :class:`EpisodeSpec` and :func:`episode_spec`.

`uavxai run`, `uavxai evaluate` (kinematic and JSBSim), the kinematic runner
(:func:`uavxai.sim.build.run_kinematic`) and the training env
(:class:`uavxai.learning.env.EncounterEnv`) all build their episode here, so that a scenario
and a seed mean the same start, goal, intruders and step budget wherever they are flown. The
one goal rule is :func:`episode_goal`; the one intruder draw is
:func:`uavxai.dynamics.traffic.draw_intruders` on ``numpy.random.default_rng(seed)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from uavxai.dynamics.track_pilot import TrackLike
from uavxai.dynamics.traffic import draw_intruders
from uavxai.errors import UserError
from uavxai.scenario import IntruderSpec, Scenario, Start
from uavxai.sim.mission import MissionConfig, mission_of
from uavxai.vocabulary import DYNAMICS_MODELS

Point = tuple[float, float, float]


@dataclass(frozen=True)
class EpisodeSpec:
    """One seeded episode, before anything flies it.

    ``scenario`` is the scenario as flown (``seed`` and ``start`` applied); ``intruders`` their
    initial conditions (row i + 1 of the traffic); ``tracks`` the intruders (by index) that
    follow a trajectory; ``mission`` the mission flown (None: a transit to ``goal``);
    ``max_steps`` the decisions before the episode times out.
    """

    scenario: Scenario
    seed: int
    start: Start
    goal: Point
    intruders: tuple[IntruderSpec, ...]
    dynamics: str = "kinematic"
    tracks: Mapping[int, TrackLike] | None = None
    mission: MissionConfig | None = None
    max_steps: int = 0


def episode_goal(scenario: Scenario, service_point: Sequence[float] | None = None) -> Point:
    """THE goal rule: ``ownship.goal`` if the scenario names one, else the service point
    (``service_point``, or planned here for ``scenario`` as given, its own seed)."""
    if scenario.ownship.goal is not None:
        return _point(scenario.ownship.goal)
    if service_point is None:
        return _service_point(scenario.model_dump_json())
    return _point(service_point)


@lru_cache(maxsize=32)
def _service_point(scenario_json: str) -> Point:
    """The planned service point of a scenario, once per process (campaign episodes, training
    episodes and tests fly the same scenario many times; the plan is deterministic).

    Planned on a fork of torch's random state: a learned service planner draws from it, and
    the caller's stream (a training run's network initialisation) must not depend on whether
    this process had planned the point before."""
    import torch

    from uavxai.service.stage import plan_service  # the service layer only when needed

    with torch.random.fork_rng(devices=[]):
        plan = plan_service(Scenario.model_validate_json(scenario_json))
    return _point(plan.service_point)


def _point(v: Sequence[float]) -> Point:
    x, y, h = (float(c) for c in np.asarray(v, dtype=float))
    return x, y, h


def episode_spec(
    scenario: Scenario,
    seed: int | None = None,
    *,
    n_intruders: int | None = None,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
    service_point: Sequence[float] | None = None,
    start: Start | None = None,
    intruders: Sequence[IntruderSpec] | None = None,
    tracks: Mapping[int, TrackLike] | None = None,
    mission: bool | MissionConfig = False,
) -> EpisodeSpec:
    """The episode ``seed`` (None: the scenario's) of ``scenario``.

    ``goal`` None: :func:`episode_goal` of ``scenario`` (``service_point`` the one already
    planned, if any); a campaign passes its one goal for every episode. ``intruders`` None:
    drawn from the seed (``n_intruders`` of them, None: the scenario's list or count).
    ``start`` None: the scenario's. ``mission`` True: the scenario's mission to the goal (none
    for a scenario that names its goal, or without time on station); a ``MissionConfig``: that
    one; False: a transit to the goal.
    """
    if dynamics not in DYNAMICS_MODELS:
        raise UserError(f"dynamics '{dynamics}' is not one of {', '.join(DYNAMICS_MODELS)}.")
    seed = scenario.seed if seed is None else int(seed)
    where = episode_goal(scenario, service_point) if goal is None else _point(goal)
    sc = scenario.with_seed(seed)
    if start is not None:
        sc = sc.model_copy(update={"ownship": sc.ownship.model_copy(update={"start": start})})
    if intruders is None:
        intruders = draw_intruders(sc, np.random.default_rng(seed), n_intruders)
    flown = mission_of(sc, where) if mission is True else (mission or None)
    return EpisodeSpec(
        scenario=sc,
        seed=seed,
        start=sc.ownship.start,
        goal=where,
        intruders=tuple(intruders),
        dynamics=dynamics,
        tracks=tracks,
        mission=flown,
        max_steps=episode_steps(sc, flown),
    )


def episode_steps(scenario: Scenario, mission: MissionConfig | None) -> int:
    """Decisions before the episode times out: ``avoidance.max_steps``, or for a mission
    there and back plus the time on station."""
    av = scenario.avoidance
    if mission is None:
        return av.max_steps
    return 2 * av.max_steps + math.ceil(mission.service_s / av.decision_period_s)
