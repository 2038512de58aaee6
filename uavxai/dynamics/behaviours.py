"""How intruders fly: `straight`, `random_turns`, `goal_seeking` (and a given track:
:mod:`uavxai.dynamics.track_pilot`, attached with ``make_pilots(..., tracks=)``).

A pilot turns the intruder's situation into autopilot commands (bank angle, airspeed); the
altitude drawn for it is held by the autopilot. Nothing here depends on the dynamics, so
the JSBSim world and the kinematic encounter model of the campaigns fly the same pilots, and
a scenario + seed gives the same traffic in both (see :func:`make_pilots`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from uavxai.dynamics.track_pilot import TrackLike, TrackPilot
from uavxai.geometry import bearing, wrap_angle
from uavxai.scenario import (
    IntruderSpec,
    Scenario,
    aircraft_height_loop,
    aircraft_speed_range,
    flown_bank_limit_rad,
)

BEHAVIOURS = ("straight", "random_turns", "goal_seeking")
PILOT_PERIOD_S = 1.0  # how often intruder pilots decide, in every world

# random_turns: hold each bank command this long, s
TURN_HOLD_S = (5.0, 20.0)
# random_turns: share of the segments flown wings level
LEVEL_SHARE = 0.3
# goal_seeking: bank per radian of heading error, and the distance at which a goal counts as
# reached and the next one is drawn
HEADING_GAIN = 1.0
GOAL_REACHED_M = 100.0


class IntruderPilot:
    """The pilot of one intruder. ``command`` is meant to be called about once a second."""

    def __init__(self, spec: IntruderSpec, rng: np.random.Generator, scenario: Scenario) -> None:
        behaviour = spec.behaviour or scenario.intruders.behaviour
        if behaviour not in BEHAVIOURS:
            raise ValueError(f"unknown intruder behaviour '{behaviour}'; known: {BEHAVIOURS}")
        self.behaviour = behaviour
        self.speed_mps = spec.speed_mps
        self.bank_limit_rad = intruder_bank_limit_rad(scenario)
        self._rng = rng
        self._world = scenario.world
        self._bank = 0.0
        self._next_change_t = 0.0
        self.goal: tuple[float, float] | None = None
        if behaviour == "goal_seeking":
            self.goal = self._draw_goal()

    def command(
        self, t: float, pos: Sequence[float], vel: Sequence[float], psi: float
    ) -> tuple[float, float]:
        """(bank_cmd_rad, speed_target_mps) at time t for an intruder at ``pos`` (x, y, h),
        moving with ``vel`` (vx, vy, vh), heading ``psi`` (rad, clockwise from north)."""
        if self.behaviour == "random_turns":
            return self._random_turns(t), self.speed_mps
        if self.behaviour == "goal_seeking":
            return self._goal_seeking(pos, psi), self.speed_mps
        return 0.0, self.speed_mps

    def alt_target(self, t: float) -> float | None:
        """The height target at time t, or None: these behaviours hold the height drawn."""
        return None

    def _random_turns(self, t: float) -> float:
        if t >= self._next_change_t:
            if self._rng.random() < LEVEL_SHARE:
                self._bank = 0.0
            else:
                self._bank = float(self._rng.uniform(-1.0, 1.0)) * self.bank_limit_rad
            self._next_change_t = t + float(self._rng.uniform(*TURN_HOLD_S))
        return self._bank

    def _goal_seeking(self, pos: Sequence[float], psi: float) -> float:
        assert self.goal is not None
        dx, dy = self.goal[0] - pos[0], self.goal[1] - pos[1]
        if math.hypot(dx, dy) < GOAL_REACHED_M:
            self.goal = self._draw_goal()
            dx, dy = self.goal[0] - pos[0], self.goal[1] - pos[1]
        bank = HEADING_GAIN * wrap_angle(bearing(dx, dy) - psi)
        return max(-self.bank_limit_rad, min(self.bank_limit_rad, bank))

    def _draw_goal(self) -> tuple[float, float]:
        return float(self._rng.uniform(*self._world.x)), float(self._rng.uniform(*self._world.y))


def intruder_bank_limit_rad(scenario: Scenario) -> float:
    """The bank limit the scenario's intruders fly within: their aircraft's own
    (``intruders.aircraft``'s autopilot XML), not the ownship's ``avoidance.bank_limit_deg``
    (the fallback for an aircraft that declares none)."""
    return flown_bank_limit_rad(scenario.intruders.aircraft, scenario.avoidance.bank_limit_deg)


def make_pilots(
    scenario: Scenario,
    specs: Sequence[IntruderSpec],
    seed: int,
    tracks: Mapping[int, TrackLike] | None = None,
) -> list[IntruderPilot | TrackPilot]:
    """One pilot per intruder, each with its own random stream derived from ``seed``
    (independent of the stream that drew the intruders). ``tracks`` maps an intruder's index
    (0-based, in ``specs``) to a trajectory its :class:`TrackPilot` follows from t = 0
    instead of its behaviour."""
    streams = np.random.SeedSequence(seed).spawn(len(specs))
    pilots: list[IntruderPilot | TrackPilot] = [
        IntruderPilot(spec, np.random.default_rng(stream), scenario)
        for spec, stream in zip(specs, streams, strict=True)
    ]
    for i, track in (tracks or {}).items():
        if not 0 <= i < len(pilots):
            raise ValueError(f"a track for intruder index {i}; there are {len(pilots)}")
        pilots[i] = track_pilot(scenario, track)
    return pilots


def track_pilot(scenario: Scenario, track: TrackLike, t0: float = 0.0) -> TrackPilot:
    """A :class:`TrackPilot` for ``track`` within the scenario's bank limit and the speed
    range of its intruder aircraft."""
    lo, hi = aircraft_speed_range(scenario.intruders.aircraft)
    gain, _ = aircraft_height_loop(scenario.intruders.aircraft)
    return TrackPilot(
        track,
        bank_limit_rad=intruder_bank_limit_rad(scenario),
        speed_range=(lo, hi),
        t0=t0,
        height_gain_per_s=gain,
        period_s=PILOT_PERIOD_S,
    )


def newcomer_pilot(scenario: Scenario, spec: IntruderSpec, seed: int, number: int) -> IntruderPilot:
    """The pilot of intruder ``number`` entering mid-run (``intruders.flow: replace``), with
    its own random stream of the run's ``seed``."""
    stream = np.random.SeedSequence(seed, spawn_key=(0x4E4557, number))  # "NEW"
    return IntruderPilot(spec, np.random.default_rng(stream), scenario)
