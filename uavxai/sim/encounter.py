"""Flying statistical encounters (docs/scenario.md "encounters"; docs/daa-metrics.md).

Episode i of an encounter scenario is encounter i: :func:`draw_encounter` samples it with seed
(campaign seed + i) from the scenario's encounter model against the ownship's planned straight
path (from ``ownship.start`` toward ``ownship.goal`` at the start speed and height), so that
the closest approach falls at the sampled TCA; :func:`fly_encounter` flies it, the one
intruder following the encounter's track (the `track` pilot) on
``encounters.intruder_aircraft``, for ``encounters.duration_s``, and returns the episode
result with the per-encounter detect-and-avoid record (:class:`EncounterRecord`).

The record's columns are every campaign episode's (:mod:`uavxai.sim.daa_record`), with the
encounter's importance weight and the geometry it was drawn with.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from uavxai.avoidance.types import Planner, PlannerConfig
from uavxai.encounters import (
    Encounter,
    EncounterConfig,
    EncounterModel,
    Trajectory,
    default_model,
    load_model,
    sample_encounter,
    straight_ownship,
)
from uavxai.encounters.tracks import MIN_FIXED_WING_SPEED
from uavxai.errors import UserError
from uavxai.geometry import bearing
from uavxai.scenario import (
    IntruderSpec,
    Scenario,
    aircraft_height_loop,
    aircraft_speed_range,
    flown_bank_limit_rad,
)
from uavxai.sim.daa_record import DaaObserver, DaaRecord
from uavxai.sim.episode import EpisodeResult
from uavxai.sim.flight_quality import FlightQuality

# A track's turns need at most this share of the intruder's bank limit, leaving the track
# pilot the rest to correct its errors.
TRACK_BANK_SHARE = 0.8


@lru_cache(maxsize=4)
def encounter_model(parameters: str | None) -> EncounterModel:
    """The encounter model of a scenario (``encounters.parameters``; None: the shipped one),
    read once per process."""
    return default_model() if parameters is None else load_model(parameters)


def encounter_config(scenario: Scenario) -> EncounterConfig:
    """The pairing settings of ``scenario``'s ``encounters`` section, with the intruder
    aircraft's dynamic limits: tracks slower than its minimum speed redrawn, faster ones flown
    at its maximum, vertical rates within its climb-rate limit, turns within
    TRACK_BANK_SHARE of the bank limit."""
    e = scenario.encounters
    if e is None:
        raise UserError(f"scenario '{scenario.name}' has no encounters section")
    lo, hi = aircraft_speed_range(e.aircraft)
    _, climb = aircraft_height_loop(e.aircraft)
    return EncounterConfig(
        duration=e.duration_s,
        tca_window=tuple(e.tca_window_s),
        hmd_max=e.hmd_max_m,
        vmd_max=e.vmd_max_m,
        hmd_nominal=e.hmd_nominal,
        min_speed=max(MIN_FIXED_WING_SPEED, lo),
        max_speed=hi,
        max_vertical_rate=climb,
        max_bank=TRACK_BANK_SHARE
        * flown_bank_limit_rad(e.aircraft, scenario.avoidance.bank_limit_deg),
    )


def route(scenario: Scenario) -> tuple[np.ndarray, float]:
    """The ownship's planned straight route: its start (x, y, h) and heading (rad) to the goal."""
    s, goal = scenario.ownship.start, scenario.ownship.goal
    if goal is None:
        raise UserError(f"scenario '{scenario.name}': an encounter scenario needs ownship.goal")
    return np.array([s.x, s.y, s.h]), bearing(goal[0] - s.x, goal[1] - s.y)


def draw_encounter(scenario: Scenario, seed: int) -> Encounter:
    """Encounter ``seed`` of ``scenario``: the intruder track placed against the ownship's
    straight route, flown from t = 0, at TCA; held ``intruder_floor_m`` above the ground."""
    e = scenario.encounters
    start, heading = route(scenario)
    speed = scenario.ownship.start.speed_mps

    def own_at(tca: float):
        return straight_ownship(speed, heading, float(start[2]), tca, start=(start[0], start[1]))

    enc = sample_encounter(encounter_model(e.parameters), own_at, int(seed), e.importance,
                           encounter_config(scenario))
    tr = enc.intruder
    low = tr.h < e.intruder_floor_m
    if low.any():
        tr = Trajectory(t=tr.t, x=tr.x, y=tr.y, h=np.maximum(tr.h, e.intruder_floor_m),
                        vx=tr.vx, vy=tr.vy, vh=np.where(low, 0.0, tr.vh))
        enc = replace(enc, intruder=tr)
    return enc


def intruder_spec(enc: Encounter) -> IntruderSpec:
    """The intruder's start: its track's first sample."""
    tr = enc.intruder
    return IntruderSpec(x=float(tr.x[0]), y=float(tr.y[0]), h=float(tr.h[0]),
                        heading_deg=math.degrees(float(tr.heading[0])),
                        speed_mps=float(tr.speed[0]))


def flight_scenario(scenario: Scenario) -> Scenario:
    """``scenario`` as an encounter flies it: the intruder aircraft the encounter's, as many
    decisions as ``duration_s`` lasts."""
    e = scenario.encounters
    steps = math.ceil(e.duration_s / scenario.avoidance.decision_period_s - 1e-9)
    return scenario.model_copy(update={
        "intruders": scenario.intruders.model_copy(update={"aircraft": e.aircraft}),
        "avoidance": scenario.avoidance.model_copy(update={"max_steps": steps}),
    })


@dataclass
@dataclass
class EncounterRecord(DaaRecord):
    """One flown encounter's detect-and-avoid columns (:class:`DaaRecord`) and the geometry the
    encounter was drawn with."""

    sampled_hmd_m: float = math.nan  # the encounter's, at TCA
    sampled_vmd_m: float = math.nan
    tca_s: float = math.nan


def fly_encounter(
    scenario: Scenario,
    planner: Planner,
    seed: int,
    dynamics: str = "kinematic",
    quality: FlightQuality | None = None,
    observers=(),
) -> tuple[EpisodeResult, EncounterRecord, Encounter]:
    """Fly encounter ``seed`` of ``scenario`` (with ``seed`` as the episode's seed); ``quality``
    (a new one when None) records the ownship's flight along the straight route."""
    from uavxai.sim.build import fly
    from uavxai.sim.spec import episode_spec

    sc = flight_scenario(scenario.with_seed(seed))
    enc = draw_encounter(scenario, seed)
    rec = DaaObserver(PlannerConfig.from_scenario(sc))
    spec = episode_spec(sc, dynamics=dynamics, intruders=[intruder_spec(enc)],
                        tracks={0: enc.intruder})  # fmt: skip
    if quality is None:
        quality = FlightQuality(((spec.start.x, spec.start.y, spec.start.h), spec.goal))
    r = fly(spec, planner, observers=[quality, rec, *observers])
    record = EncounterRecord(
        **vars(rec.record(quality, sc.avoidance.well_clear, enc.weight)),
        sampled_hmd_m=float(enc.hmd),
        sampled_vmd_m=float(enc.vmd),
        tca_s=float(enc.tca),
    )
    return r, record, enc


__all__ = [
    "EncounterRecord", "draw_encounter", "encounter_config",
    "encounter_model", "fly_encounter", "flight_scenario", "intruder_spec", "route",
]
