"""One campaign episode: the episode a campaign flies at a seed, flown on the episode engine,
and its ``episodes.csv`` row; any row flown again alone (:func:`rerun_row`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from uavxai.campaign.files import GOAL_COLUMNS
from uavxai.errors import UserError
from uavxai.scenario import Scenario
from uavxai.vocabulary import Outcome, avoidance_planners

if TYPE_CHECKING:
    from uavxai.avoidance.types import Planner

# One planner per (method, scenario) per process: loading a network or building a model once.
_PLANNERS: dict[tuple[str, str], object] = {}


def planner_for(scenario: Scenario, method: str) -> Planner:
    """The planner ``method`` of ``scenario``, made once per process (a campaign loads every
    method's planner before flying, so that a missing checkpoint fails at once)."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig

    key = (method, scenario.model_dump_json())
    planner = _PLANNERS.get(key)
    if planner is None:
        config = PlannerConfig.from_scenario(scenario)
        planner = make_planner(method, config, checkpoint=scenario.avoidance.checkpoint)
        _PLANNERS[key] = planner
    return planner


def campaign_spec(
    scenario: Scenario,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
):
    """The episode a campaign of ``scenario`` flies at ``seed`` with ``n_intruders``: to the
    campaign's goal (None: the scenario's, :func:`uavxai.sim.spec.episode_goal` at the seed
    its file names, whatever the episode's seed: the same goal for every episode), no
    mission. An encounter campaign's one intruder is its encounter's (``fly_encounter``)."""
    from uavxai.sim.spec import episode_spec

    encounter = [] if scenario.encounters is not None else None
    return episode_spec(
        scenario, seed, n_intruders=n_intruders, dynamics=dynamics, goal=goal, intruders=encounter
    )


def run_campaign_episode(
    scenario: Scenario,
    method: str,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
) -> dict:
    """Fly one campaign episode on the episode engine (the commands go straight to the
    autopilot, no recording) and return its ``episodes.csv`` row (without ``episode``: with
    its detect-and-avoid record, uavxai.sim.daa_record, weighted 1 for random traffic), plus
    ``decision_ms`` (every decision's planner time, for the pooled median). ``goal``: the
    campaign's goal (None: the scenario's, see :func:`campaign_spec`)."""
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.build import fly
    from uavxai.sim.daa_record import DaaObserver
    from uavxai.sim.flight_quality import FlightQuality

    if scenario.fleet.size > 1:  # it would fly member 0 alone, the others uncommanded traffic
        raise UserError(
            f"scenario '{scenario.name}' flies a fleet (fleet.size = {scenario.fleet.size}): "
            "run_campaign_episode and rerun_row fly one ownship; a fleet's episode is "
            "uavxai.campaign.run_fleet_episode (uavxai evaluate --dynamics jsbsim)."
        )
    if method not in avoidance_planners():
        raise UserError(f"method '{method}' is not one of {', '.join(avoidance_planners())}.")
    spec = campaign_spec(scenario, n_intruders, seed, dynamics, goal)
    start = (spec.start.x, spec.start.y, spec.start.h)
    quality = FlightQuality(None if spec.mission else (start, spec.goal))
    if scenario.encounters is not None:  # episode i is encounter i, with its one intruder
        from uavxai.sim.encounter import fly_encounter

        r, rec, _ = fly_encounter(scenario, planner_for(scenario, method), seed, dynamics, quality)
        n_intruders = 1
    else:
        daa = DaaObserver(PlannerConfig.from_scenario(scenario))
        r = fly(spec, planner_for(scenario, method), observers=[quality, daa])
        rec = daa.record(quality, scenario.avoidance.well_clear)
    if r.outcome is Outcome.INTERRUPTED:
        # a signal to this process: the campaign stops here (its caller keeps the finished
        # episodes), and a flight cut short is no episode of its results
        raise KeyboardInterrupt("episode interrupted")
    ms = r.decision_ms
    return {
        "method": method,
        "intruders": int(n_intruders),
        "seed": int(seed),
        "outcome": r.outcome.value,
        "steps": int(r.steps),
        "min_separation_m": round(float(r.min_separation_m), 3)
        if math.isfinite(r.min_separation_m)
        else math.inf,
        "flight_time_s": round(float(r.flight_time_s), 3),
        "nmac": int(r.nmac),
        "decision_ms_p50": round(float(np.median(ms)), 4) if ms else math.nan,
        **{k: round(float(v), 3) for k, v in zip(GOAL_COLUMNS, spec.goal, strict=True)},
        **quality.result().row(),
        **rec.columns(),
        "decision_ms": ms,
    }


def rerun_row(
    scenario_path: str | Path,
    method: str,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
) -> dict:
    """Fly one row of an ``episodes.csv`` again: its scenario file, method, intruders, seed and
    (for a scenario without ``ownship.goal`` flown with another ``--seed``) the row's goal."""
    from uavxai.scenario import load_scenario

    scenario = load_scenario(scenario_path)
    row = run_campaign_episode(scenario, method, n_intruders, seed, dynamics, goal)
    row.pop("decision_ms")
    return row
