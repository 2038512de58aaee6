"""The communication mission: transit -> on station (orbit, serving) -> return home.

Phases (announced to ground stations as STATUSTEXT, shown as the flight mode):

- ``transit``: the avoidance planner flies to the service point among traffic;
- ``on_station``: the autopilot loiters about the service point (MAV_CMD_DO_ORBIT, re-sent
  every decision) for ``mission.service_s``; every decision the orbit ahead, and the orbit
  law's own way onto it from where the aircraft is, are checked against every intruder the
  planner believes in, over the planner's horizon;
- ``avoiding``: when either comes within ``2 d_min`` of an intruder, the avoidance
  planner takes over (its commands take the aircraft off the orbit), steering for the orbit
  point it would have reached at the end of the horizon; once the orbit ahead and the way
  onto it are clear it rejoins (a new DO_ORBIT). Time avoiding counts as time on station:
  the users are still in reach, the service lost to the manoeuvre is measured by the delivery
  observer;
- ``returning``: after the service time, or when the battery reaches its reserve, the planner
  flies home; the mission is ``completed`` there (or at the end of the service time without
  ``return_home``).

Avoidance is therefore on in every phase. ``mission.service_s: 0`` or an explicit
``ownship.goal`` keep the paper's transit-only episode (no Mission object at all).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

from uavxai.avoidance.types import Decision, Intruder, Ownship, PlannerConfig
from uavxai.dynamics.loiter import GUIDANCE_PERIOD_S, orbit_guidance
from uavxai.dynamics.orbit import scenario_orbit_radius
from uavxai.dynamics.state import TrafficState
from uavxai.geometry import turn_positions
from uavxai.scenario import Scenario
from uavxai.sim.episode import EngineStep, Episode
from uavxai.vocabulary import HOLD, Outcome

CONFLICT_FACTOR = 2.0  # the orbit ahead must keep 2 d_min from every believed intruder
# "orbiting" only within this share of the radius from the circle (the share a settled orbit
# holds, tests/test_sim_mission.py); farther, the words say it is still joining the orbit
ON_ORBIT_SHARE = 0.1


class Phase(StrEnum):
    TRANSIT = "transit"
    ON_STATION = "on_station"
    AVOIDING = "avoiding"
    RETURNING = "returning"


@dataclass(frozen=True)
class MissionConfig:
    station: tuple[float, float, float]  # the service point: orbit centre and height
    home: tuple[float, float, float]
    service_s: float
    return_home: bool
    radius_m: float
    speed_mps: float  # the loiter airspeed the radius is designed for
    clockwise: bool = True

    @classmethod
    def from_scenario(cls, scenario: Scenario, station: Sequence[float]) -> MissionConfig:
        m, start = scenario.mission, scenario.ownship.start
        radius = scenario_orbit_radius(scenario)  # the radius service placement scores too
        return cls(
            station=tuple(float(v) for v in station),
            home=(float(start.x), float(start.y), float(start.h)),
            service_s=float(m.service_s),
            return_home=bool(m.return_home),
            radius_m=float(radius),
            speed_mps=float(start.speed_mps),
        )


def mission_of(scenario: Scenario, station: Sequence[float]) -> MissionConfig | None:
    """The scenario's mission, or None for a transit-only episode."""
    cfg = MissionConfig.from_scenario(scenario, station)
    if scenario.ownship.goal is not None or cfg.service_s <= 0:
        return None
    return cfg


class Mission(EngineStep):
    """Decides, phase by phase, who flies; an engine step of the episode it runs in."""

    def __init__(self, config: MissionConfig, announce: Callable[..., None]) -> None:
        self.config = config
        self.announce = announce
        self.phase = Phase.TRANSIT
        self.phases: dict[str, float] = {}  # first start of each phase
        self.transitions: list[tuple[float, str]] = []
        self.on_station_s = 0.0
        self.avoidance_s = 0.0
        self.outcome: Outcome | None = None
        self.service_points: list[tuple[float, float, float, float]] = []
        self._battery_low = False
        self.left: str | None = None  # why it went home before its service was done
        self._own_xy: tuple[float, float] | None = None
        self._horizon_s = 16.0
        self.suspended = False  # the operator flies elsewhere (uavxai.sim.operator)
        self.holding = False  # done, orbiting home for the others (a fleet's member 0)
        self._hold_conflict = False
        # a fleet's: done on reaching its home orbit, not the home point (:meth:`hold_home`)
        self.home_orbit = False

    # ------------------------------------------------------------------------- phases
    def _enter(self, phase: Phase, t: float, why: str, ep: Episode) -> None:
        self.phase = phase
        if phase in (Phase.TRANSIT, Phase.RETURNING):  # the height of where it now goes
            ep.path.altitude(self.goal[2], t)
        self.phases.setdefault(phase.value, round(t, 3))
        self.transitions.append((round(t, 3), phase.value))
        self.announce(f"{phase.value.replace('_', ' ')}: {why}", phase.value)

    def on_start(self, ep: Episode) -> None:
        c = self.config
        self.service_points.append((0.0, *c.station))
        self._enter(Phase.TRANSIT, ep.state.t, "to the service point", ep)

    def battery_reserve(self, ep: Episode) -> None:
        """The battery reached its reserve: go home now, whatever the phase."""
        self.leave(ep, "battery at reserve")

    def leave(self, ep: Episode, why: str) -> None:
        """Go home now, whatever the phase, for ``why`` (the battery's reserve, or a fleet's
        scripted ``fleet.leave``): :attr:`left` says why, once, unless it was going home
        already (its service done)."""
        if not self._battery_low and self.phase != Phase.RETURNING:
            self._battery_low = True
            self.left = why
            if ep.operator is not None:  # whatever the operator asked: home, as RTL
                ep.operator.release(ep, why)
            self._enter(Phase.RETURNING, ep.state.t, f"{why}, returning home", ep)

    @property
    def goal(self) -> tuple[float, float, float]:
        """Where the avoidance planner steers now: home, the service point, or, avoiding on
        station, the point of the orbit it would have reached at the end of the planner's
        horizon (the centre itself would be a goal reached in passing, which would make every
        option look as good as any other)."""
        c = self.config
        if self.holding and self._own_xy is not None:  # avoiding about home: as on station
            return self._orbit_ahead(c.home)
        if self.phase == Phase.RETURNING:
            return c.home
        if self.phase != Phase.AVOIDING or self._own_xy is None:
            return c.station
        return self._orbit_ahead(c.station)

    def _orbit_ahead(self, centre: tuple[float, float, float]) -> tuple[float, float, float]:
        """The point of the orbit about ``centre`` the aircraft would reach at the end of the
        planner's horizon: the goal while avoiding on an orbit. A fleet member holding at
        home used to aim at home itself, a goal it was already within: every branch reached
        it before the intruder's closest point, so all scored alike (Q 1.000) and the tree
        held on into a collision (round 7, fleet.yaml seed 22: 48.6 m)."""
        c = self.config
        x, y = self._own_xy
        ahead = (1.0 if c.clockwise else -1.0) * c.speed_mps * self._horizon_s / c.radius_m
        b = math.atan2(x - centre[0], y - centre[1]) + ahead
        return (
            centre[0] + c.radius_m * math.sin(b),
            centre[1] + c.radius_m * math.cos(b),
            centre[2],
        )

    @property
    def serving(self) -> bool:
        return self.phase in (Phase.ON_STATION, Phase.AVOIDING) and not self.suspended

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        if self.holding:  # where it is on its hold orbit (the goal when avoiding there)
            self._own_xy = (float(state.pos[0, 0]), float(state.pos[0, 1]))
        if self.suspended or self.holding:
            return
        c, p, t = self.config, state.pos[0], state.t
        self._own_xy = (float(p[0]), float(p[1]))
        self._horizon_s = ep.seat.config.depth * ep.seat.config.action_hold_s
        if self.phase == Phase.TRANSIT:
            if on_orbit(p, c.station, c.radius_m, ep.judge.goal_radius_m):
                why = f"orbiting {c.radius_m:.0f} m radius at {c.station[2]:.0f} m height"
                self._enter(Phase.ON_STATION, t, why, ep)
                speed = ep.path.cruise_speed(c.speed_mps)
                ep.path.orbit(*c.station, c.radius_m, c.clockwise, speed, t)
        elif self.serving:
            self.on_station_s += ep.clock.sample_s
            if self.phase == Phase.AVOIDING:
                self.avoidance_s += ep.clock.sample_s
            if self.on_station_s >= c.service_s - 1e-9:
                if c.return_home:
                    self._enter(Phase.RETURNING, t, "service time over, returning home", ep)
                else:
                    self.outcome = Outcome.COMPLETED
        elif self._home_reached(p, ep.judge.goal_radius_m):
            self.outcome = Outcome.COMPLETED

    def _home_reached(self, p: Sequence[float], goal_radius_m: float) -> bool:
        """Home: within the goal radius of it; in a fleet (:attr:`home_orbit`) its hold orbit
        reached (:func:`on_orbit`, as the station's), so the hold orbit is joined from outside
        on the side it comes from. Joined from home itself at the return's speed, the orbit
        law swung a member out to 150 m from home, towards its neighbour's hold orbit (round
        7, fleet.yaml seed 20: an NMAC, 152 m / 1 m)."""
        c = self.config
        if not self.home_orbit:
            return math.dist(p, c.home) < goal_radius_m
        return on_orbit(p, c.home, c.radius_m, goal_radius_m)

    def remaining_s(self, own: Sequence[float], speed_mps: float, goal_radius_m: float) -> float:
        """An estimate of the flight time left, from ``own`` (x, y), the legs flown at
        ``speed_mps``: the rest of the transit (to the orbit), the service time left, and the
        way home from the orbit (straight legs, ending ``goal_radius_m`` short; detours for
        traffic are not foreseen, so the estimate is refined as it flies)."""
        c = self.config
        speed = max(float(speed_mps), 1.0)
        if self.phase == Phase.RETURNING:
            return max(math.dist(own[:2], c.home[:2]) - goal_radius_m, 0.0) / speed
        home_m = math.dist(c.station[:2], c.home[:2]) - c.radius_m - goal_radius_m
        left = max(c.service_s - self.on_station_s, 0.0)
        if c.return_home:
            left += max(home_m, 0.0) / speed
        if self.phase == Phase.TRANSIT:
            to_orbit = math.dist(own[:2], c.station[:2]) - orbit_reach_m(c.radius_m, goal_radius_m)
            left += max(to_orbit, 0.0) / speed
        return left

    # ------------------------------------------------------------------------ decisions
    def decide(self, ep: Episode, own: Ownship, intruders: list[Intruder]) -> Decision | None:
        """On station: the orbit's decision (re-sent, the orbit ahead checked), or None when
        the avoidance planner must fly (transit, return, a conflict on the orbit). Holding
        (:meth:`hold_home`): the orbit about home, checked the same way."""
        if self.holding:
            return self._hold(ep, own, intruders)
        if not self.serving:
            return None
        c, t = self.config, ep.state.t
        orbit = Orbit(c.station, c.radius_m, c.clockwise, ep.path.cruise_speed(c.speed_mps))
        step = orbit_step(ep, orbit, own, intruders, self.phase == Phase.AVOIDING)
        if step.conflict is not None:
            if self.phase == Phase.ON_STATION:
                self._enter(Phase.AVOIDING, t, step.conflict, ep)
            return None
        if self.phase == Phase.AVOIDING:
            self._enter(Phase.ON_STATION, t, "orbit clear, rejoining", ep)
        said = step.decision.words[0]
        step.decision.words = (f"{ep.plan_label()}: {said}", "")  # the phase it is flown in
        return step.decision

    def set_height(self, ep: Episode, h: float) -> None:
        """The operator's height for the leg flown now (the service point's, or home's on
        the way back); on station the orbit climbs or sinks to it."""
        c = self.config
        if self.phase == Phase.RETURNING:
            self.config = dataclasses.replace(c, home=(c.home[0], c.home[1], float(h)))
        else:
            self.config = dataclasses.replace(c, station=(c.station[0], c.station[1], float(h)))
        if not self.serving:
            ep.path.altitude(float(h), ep.state.t)

    def hold_home(self) -> None:
        """Done, and waiting for the rest of its fleet (``uavxai.sim.fleet``): orbit home,
        as the other members do when done, rather than fly on past it (fleet.yaml seed 0:
        member 0 crossed its home at 27 m/s and left the world); nothing more is served, and
        the phases stop."""
        self.holding = True

    def _hold(self, ep: Episode, own: Ownship, intruders: list[Intruder]) -> Decision | None:
        c = self.config
        orbit = Orbit(c.home, c.radius_m, c.clockwise, ep.path.cruise_speed(c.speed_mps))
        step = orbit_step(ep, orbit, own, intruders, self._hold_conflict)
        self._hold_conflict = step.conflict is not None
        return step.decision

    def suspend(self) -> None:
        """The operator took the aircraft elsewhere (GUIDED, LOITER, RTL, an uploaded
        mission): the mission's phases wait, and nothing here commands, until it resumes."""
        self.suspended = True

    def resume(self, ep: Episode) -> None:
        """AUTO again: carry on from the phase it was in (its height again; the orbit is
        re-sent at the next decision)."""
        if not self.suspended:
            return
        self.suspended = False
        if not self.serving:
            ep.path.altitude(self.goal[2], ep.state.t)
        self.announce(f"AUTO: mission resumed, {self.phase.value.replace('_', ' ')}", None)

    def move_station(
        self, ep: Episode, point: Sequence[float], why: str, fly_there: bool = False
    ) -> None:
        """A re-planned service point: the orbit moves there (now, if on station). With
        ``fly_there`` (a fleet's re-cover), serving farther from the new orbit than it would
        go on station from (its radius + the goal radius), it flies there in transit, under
        its avoidance planner (with the fleet's clearance), and goes on station on reaching
        the orbit: the orbit law, moved at once, flew it there judged only by the orbit's
        check against the traffic (issue 32, round 7: up to 295 m)."""
        t = ep.state.t
        self.config = dataclasses.replace(self.config, station=tuple(float(v) for v in point))
        self.service_points.append((round(t, 3), *self.config.station))
        c = self.config
        self.announce(f"service point moved: {why}", self.phase.value)
        if self.suspended:
            return
        p = ep.state.pos[0]
        far = math.hypot(p[0] - c.station[0], p[1] - c.station[1])  # on_orbit's, said too
        if fly_there and self.serving and far > orbit_reach_m(c.radius_m, ep.judge.goal_radius_m):
            self._enter(Phase.TRANSIT, t, f"to the new service point, {far:.0f} m away", ep)
        elif self.phase == Phase.ON_STATION:
            speed = ep.path.cruise_speed(c.speed_mps)
            ep.path.orbit(*c.station, c.radius_m, c.clockwise, speed, t)
        elif self.phase == Phase.TRANSIT:
            ep.path.altitude(c.station[2], t)

    def on_end(self, ep: Episode, summary: dict) -> None:
        summary["mission"] = {
            "phases": self.phases,
            "transitions": self.transitions,
            "service_points": [list(p) for p in self.service_points],
            "on_station_s": round(self.on_station_s, 3),
            "avoiding_s": round(self.avoidance_s, 3),
            "orbit_radius_m": self.config.radius_m,
        }


def on_orbit(
    p: Sequence[float], centre: Sequence[float], radius_m: float, goal_radius_m: float
) -> bool:
    """Whether an aircraft at ``p`` (x, y, h) is on the orbit of ``radius_m`` about
    ``centre`` for the mission, which then hands it to the orbit law (a station reached, a
    fleet member's hold orbit at home reached) or keeps it there (a moved station this near
    is flown by the orbit law): within the radius + the goal radius of the centre
    horizontally, **at any height**. The loiter law climbs or sinks to the orbit's height as
    it circles (the altitude hold), and the orbit check predicts that climb on the way onto
    the orbit (:func:`way_clearance`); a height rule kept a member off its home's height
    flying under its planner for a goal inside the orbit, where every branch reaches it at
    once (docs/fleet.md, round 9). The one test of the three (the station's, home's, a moved
    station's), which had different height rules before."""
    return math.hypot(p[0] - centre[0], p[1] - centre[1]) <= orbit_reach_m(radius_m, goal_radius_m)


def orbit_reach_m(radius_m: float, goal_radius_m: float) -> float:
    """How far from an orbit's centre (horizontally) an aircraft is on it (:func:`on_orbit`):
    the radius + the goal radius."""
    return radius_m + goal_radius_m


def orbit_clearance(
    c: MissionConfig, own: Ownship, intruders: Sequence[Intruder], horizon_s: float
) -> tuple[float, str | None, float]:
    """(smallest predicted separation, who, when) between the ownship flying the orbit ahead
    for ``horizon_s`` at its speed and every intruder on its believed constant turn, less
    twice each track's position error."""
    t = np.arange(0.0, horizon_s + 1e-9, 0.5)
    cx, cy, h = c.station
    phase0 = math.atan2(own.x - cx, own.y - cy)  # the ownship's angle on the circle
    rate = (1.0 if c.clockwise else -1.0) * own.speed / c.radius_m
    ang = phase0 + rate * t
    path = np.stack([cx + c.radius_m * np.sin(ang), cy + c.radius_m * np.cos(ang)], axis=1)
    return clearance(t, np.column_stack([path, np.full(len(t), h)]), intruders, sigmas=2.0)


def straight_clearance(
    own: Ownship, intruders: Sequence[Intruder], horizon_s: float
) -> tuple[float, str | None, float]:
    """:func:`clearance` of the ownship flying straight on from where it is, at its ground
    velocity, for ``horizon_s``, against each intruder's track as believed (no error taken
    off): the next decision period's prediction of an orbit decision."""
    t = np.arange(0.0, horizon_s + 1e-9, 0.5)
    vx, vy = _ground_velocity(own)
    path = np.column_stack([own.x + vx * t, own.y + vy * t, np.full(len(t), own.h)])
    return clearance(t, path, intruders, sigmas=0.0)


def _ground_velocity(own: Ownship) -> tuple[float, float]:
    """The ownship's ground velocity (east, north), or its air velocity if none is known."""
    return own.ground_velocity or (
        own.speed * math.sin(own.heading), own.speed * math.cos(own.heading)
    )


def way_clearance(
    orbit: Orbit, own: Ownship, intruders: Sequence[Intruder], horizon_s: float,
    config: PlannerConfig,
) -> tuple[float, str | None, float]:
    """:func:`clearance` of the way the orbit law would fly the ownship if handed it now, for
    ``horizon_s``: from where it is, onto the orbit and along it (``OrbitGuidance.fly`` at the
    loiter law's rate, within ``config``'s bank and roll rate limits; the height towards the
    orbit's at the climb rate), against each intruder's track less twice its position error,
    as the circle's check; the law is the one the worlds fly (``loiter.orbit_guidance``).
    The circle from the ownship's bearing (:func:`orbit_clearance`) is
    the way only once it is on the orbit: fleet-mission.yaml seed 1's member 2, handed back
    221 m from its station's centre with the circle clear, was flown by the law out to 320 m
    and into intruder 14 (48.6 m; docs/fleet.md)."""
    x, y, _ = orbit.centre
    law = orbit_guidance(config.bank_limit_deg, x, y, orbit.radius_m, orbit.clockwise)
    bank = own.bank if own.phi is None else own.phi
    roll = math.radians(config.roll_rate_limit_deg_s)
    xy = law.fly((own.x, own.y), _ground_velocity(own), bank, roll, horizon_s, GUIDANCE_PERIOD_S)
    t = GUIDANCE_PERIOD_S * np.arange(len(xy))
    climb = config.climb_rate_mps * t
    h = own.h + np.clip(orbit.centre[2] - own.h, -climb, climb)
    return clearance(t, np.column_stack([xy, h]), intruders, sigmas=2.0)


def clearance(
    t: np.ndarray, path: np.ndarray, intruders: Sequence[Intruder], sigmas: float
) -> tuple[float, str | None, float]:
    """(smallest predicted separation, who, when) between the ownship at ``path`` (T, 3)
    at times ``t`` and every intruder on its believed constant turn, less ``sigmas`` times
    each track's position error."""
    if not intruders:
        return math.inf, None, 0.0
    pos = np.array([(i.x, i.y, i.h) for i in intruders], dtype=float)
    vel = np.array([(i.vx, i.vy, i.vh) for i in intruders], dtype=float)
    ahead = turn_positions(pos, vel, t, np.array([i.turn_rate for i in intruders]))  # (T, N, 3)
    d = np.sqrt(np.sum((path[:, None, :] - ahead) ** 2, axis=2))
    # the track's uncertainty shrinks the room believed
    d = d - sigmas * np.array([i.sigma_m for i in intruders])[None, :]
    k = np.argmin(d, axis=0)  # each intruder's closest instant (the first on a tie)
    j = int(np.argmin(d[k, np.arange(len(intruders))]))  # the closest intruder (the first)
    who = f"intruder {str(intruders[j].id).removeprefix('intruder-')}"
    return float(d[k[j], j]), who, float(t[k[j]])


@dataclass(frozen=True)
class Orbit:
    """A loiter about ``centre`` (x, y, h) at ``radius_m``, flown at ``speed_mps``."""

    centre: tuple[float, float, float]
    radius_m: float
    clockwise: bool
    speed_mps: float


@dataclass(frozen=True)
class OrbitStep:
    decision: Decision | None  # the orbit's decision (None: the planner must fly)
    conflict: str | None  # why the orbit ahead is not clear (None: it is)


def orbit_step(
    ep: Episode, orbit: Orbit, own: Ownship, intruders: list[Intruder], avoiding: bool
) -> OrbitStep:
    """One decision on an orbit: check the orbit ahead against every believed intruder over
    the planner's horizon; clear, re-send the orbit (MAV_CMD_DO_ORBIT) and say so, else say
    what conflicts. Hysteresis: leave the orbit below 2 d_min, rejoin only above 3 d_min
    (``avoiding``), so that a pass near the threshold does not toggle every decision."""
    horizon = ep.seat.config.depth * ep.seat.config.action_hold_s
    c = MissionConfig(orbit.centre, orbit.centre, 0.0, False, orbit.radius_m, orbit.speed_mps,
                      orbit.clockwise)  # fmt: skip
    circle = orbit_clearance(c, own, intruders, horizon)
    way = way_clearance(orbit, own, intruders, horizon, ep.seat.config)
    # the nearer of the two is the orbit's prediction (the circle's on a tie)
    sep, who, when = way if way[0] < circle[0] else circle
    what = "the way onto the orbit" if way[0] < circle[0] else "the orbit"
    d_min = ep.judge.d_min_m
    limit = (CONFLICT_FACTOR + (1.0 if avoiding else 0.0)) * d_min
    if sep < limit:
        return OrbitStep(None, f"{who} would pass {what} at {sep:.0f} m in {when:.0f} s")
    x, y, h = orbit.centre
    ep.path.orbit(x, y, h, orbit.radius_m, orbit.clockwise, orbit.speed_mps, ep.state.t)
    period = ep.seat.config.decision_period_s  # the record's field is over one period
    next_period = straight_clearance(own, intruders, period)[0]
    said = orbit_words(orbit, own, (sep, who, when), CONFLICT_FACTOR * d_min, what)
    decision = Decision(
        bank_cmd_rad=float(ep.world.ownship_command()["bank_cmd_rad"]),
        accel_mps2=0.0,
        action=HOLD,
        children=[],
        predicted_min_separation_m=next_period,
        branch_min_separation_m=sep,
        confidence=1.0,
        planner="orbit",
        d_min_m=d_min,
        words=(said, ""),  # Mission.decide opens it with the phase, once that is settled
    )
    return OrbitStep(decision, None)


def orbit_words(
    orbit: Orbit, own: Ownship, clearance: tuple[float, str | None, float], limit_m: float,
    what: str = "the orbit",
) -> str:
    """What an orbit decision says: on the circle or still joining it (how far from the
    centre), and the orbit's prediction worded as the conditional it is: intruders holding
    their present turn, each track's 2-sigma error taken off, never flown (issue 30: an
    aircraft 400 m out was said to be orbiting at 300 m, and a pass predicted at 151 m was
    flown at 99 m)."""
    x, y, h = orbit.centre
    r = orbit.radius_m
    d = math.hypot(own.x - x, own.y - y)
    if abs(d - r) <= ON_ORBIT_SHARE * r:
        where = f"orbiting ({x:.0f}, {y:.0f}) at {r:.0f} m radius, {h:.0f} m height"
    else:
        where = f"joining the orbit about ({x:.0f}, {y:.0f}), {d:.0f} m from its centre, "
        where += f"radius {r:.0f} m"
    sep, who, when = clearance
    if who is None:
        return where
    return (
        f"{where}; {who} predicted to pass {what} ahead at {sep:.0f} m in {when:.0f} s if "
        f"it holds its present turn (2-sigma track error taken off; the orbit is left below "
        f"{limit_m:.0f} m)"
    )
