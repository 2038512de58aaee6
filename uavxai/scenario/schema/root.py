"""The scenario itself (every section, and the checks across sections: world bounds,
airspeeds, timing, wind, orbit, sensors, channel ranges) and the clock's timing rule
(`clock_ticks`, the one rule the schema refuses with and the clock counts with)."""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import Field, field_validator, model_validator

from uavxai.paths import aircraft_dir
from uavxai.scenario.aircraft import aircraft_speed_range
from uavxai.scenario.schema.base import (
    Section,
    check_slug,
)
from uavxai.scenario.schema.flight import Avoidance, Intruders, Ownship, Start
from uavxai.scenario.schema.links import Bridge, Environment, Log, Surveillance
from uavxai.scenario.schema.operations import Encounters, Fleet, Mission, Operator
from uavxai.scenario.schema.world import Comms, DynamicsConfig, Service, World
from uavxai.vocabulary import (
    CHANNEL_MODELS,
)


class Scenario(Section):
    name: Annotated[str, Field(min_length=1, max_length=200)]
    seed: Annotated[int, Field(ge=0, le=2**31 - 1)] = 0
    world: World = World()
    dynamics: DynamicsConfig = DynamicsConfig()
    comms: Comms = Comms()
    service: Service = Service()
    ownship: Ownship = Ownship()
    intruders: Intruders = Intruders()
    avoidance: Avoidance = Avoidance()
    bridge: Bridge = Bridge()
    log: Log = Log()
    environment: Environment = Environment()
    surveillance: Surveillance = Surveillance()
    mission: Mission = Mission()
    fleet: Fleet = Fleet()
    operator: Operator = Operator()
    encounters: Encounters | None = None

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        return check_slug(v, "name")

    @model_validator(mode="after")
    def _timing(self) -> Scenario:
        """What the simulation clock (uavxai.sim.clock) and the bridge's failsafe would refuse,
        refused here already so that `validate` says it."""
        clock_ticks(self.dynamics, self.avoidance)
        period = self.avoidance.decision_period_s
        timeout = self.bridge.command_timeout_s
        if not timeout > period:
            raise ValueError(
                f"bridge.command_timeout_s = {timeout:g} s must be longer than "
                f"avoidance.decision_period_s = {period:g} s, or the failsafe overrides the "
                "planner between its decisions"
            )
        return self

    @model_validator(mode="after")
    def _geometry(self) -> Scenario:
        w = self.world
        s = self.ownship.start
        if not w.contains(s.x, s.y, s.h):
            raise ValueError(
                f"ownship.start ({s.x}, {s.y}, {s.h}) lies outside the world bounds "
                f"x {list(w.x)}, y {list(w.y)}, h {list(w.h)}"
            )
        if self.ownship.goal is not None and not w.contains(*self.ownship.goal):
            raise ValueError(
                f"ownship.goal {list(self.ownship.goal)} lies outside the world bounds"
            )
        r = self.comms.users.region
        if not (w.x[0] <= r.x[0] and r.x[1] <= w.x[1] and w.y[0] <= r.y[0] and r.y[1] <= w.y[1]):
            raise ValueError(
                f"comms.users.region x {list(r.x)}, y {list(r.y)} must lie inside the world "
                f"x {list(w.x)}, y {list(w.y)}"
            )
        for i, spec in enumerate(self.intruders.list or []):
            if not w.contains(spec.x, spec.y, spec.h):
                raise ValueError(
                    f"intruders.list.{i} at ({spec.x:g}, {spec.y:g}, {spec.h:g}) lies outside the "
                    f"world bounds x {list(w.x)}, y {list(w.y)}, h {list(w.h)}"
                )
        lo, hi = self.intruders.altitude_m
        if self.intruders.list is None and not (w.h[0] <= lo and hi <= w.h[1]):
            raise ValueError(
                f"intruders.altitude_m = [{lo:g}, {hi:g}] must lie inside world.h {list(w.h)}"
            )
        for name in {self.ownship.aircraft, self.intruders.aircraft}:
            if not (aircraft_dir() / name / f"{name}.xml").is_file():
                known = sorted(
                    p.name for p in aircraft_dir().iterdir() if (p / f"{p.name}.xml").is_file()
                )
                raise ValueError(
                    f"aircraft '{name}' is not a folder under aircraft/; known: {known}"
                )
        self._flyable()
        self._encounters()
        self._channel_range()
        self._fleet()
        return self

    def member_starts(self) -> list[Start]:
        """Where each fleet member starts (member 0: ``ownship.start``): abreast, member i
        ``i * fleet.spacing_m`` to the right of the start's heading, on the same heading,
        height and speed."""
        s, f = self.ownship.start, self.fleet
        right = math.radians(s.heading_deg + 90.0)  # headings clockwise from north
        return [
            s.model_copy(update={
                "x": s.x + i * f.spacing_m * math.sin(right),
                "y": s.y + i * f.spacing_m * math.cos(right),
            })
            for i in range(f.size)
        ]  # fmt: skip

    def _fleet(self) -> None:
        """What a fleet of more than one cannot fly yet (docs/fleet.md), refused by name."""
        n = self.fleet.size
        leave = self.fleet.leave
        if leave is not None and n == 1:
            raise ValueError("fleet.leave needs a fleet (the others re-cover the users of the "
                             "one that leaves); allowed: fleet.size >= 2")  # fmt: skip
        if leave is not None and leave.member >= n:
            raise ValueError(
                f"fleet.leave.member {leave.member}: there is no such member with fleet.size "
                f"= {n}; allowed: 0 .. {n - 1}"
            )
        if n == 1:
            return
        what = f"fleet.size = {n}"
        refused = [
            (self.ownship.goal is not None, "ownship.goal (a fleet flies the mission)"),
            (self.mission.service_s <= 0, "mission.service_s = 0 (a fleet serves on station)"),
            (self.encounters is not None, "encounters"),
            (bool(self.operator.commands), "operator.commands"),
            (self.avoidance.decision_latency_s > 0, "avoidance.decision_latency_s > 0"),
        ]
        for bad, setting in refused:
            if bad:
                raise ValueError(f"{what} cannot be flown with {setting}; allowed: fleet.size 1")
        last = self.bridge.system_id + n - 1
        if last > 255:
            raise ValueError(
                f"{what}: member {n - 1} would be MAVLink system {last} (bridge.system_id + "
                "its number); allowed: bridge.system_id + fleet.size - 1 <= 255"
            )
        k = self.comms.users.k
        if k < n:
            raise ValueError(f"{what} needs at least {n} users (one per UAV), got {k}")
        w = self.world
        for i, s in enumerate(self.member_starts()):
            if not w.contains(s.x, s.y, s.h):
                raise ValueError(
                    f"{what}: member {i} would start at ({s.x:.0f}, {s.y:.0f}, {s.h:.0f}), "
                    f"outside the world x {list(w.x)}, y {list(w.y)}, h {list(w.h)}; allowed: "
                    "a smaller fleet.spacing_m or a start farther from the edge"
                )

    def _channel_range(self) -> None:
        """A 3GPP channel holds for some UAV heights and horizontal distances only; the UAV
        flies (and is served) anywhere in the world, the users stay in their region."""
        valid = CHANNEL_MODELS[self.comms.channel]
        if valid is None:
            return
        w, r = self.world, self.comms.users.region
        what = f"comms.channel {self.comms.channel} ({valid.standard})"
        if not (valid.h_min_m < w.h[0] and w.h[1] <= valid.h_max_m):
            raise ValueError(
                f"{what} holds for UAV heights {valid.h_min_m:g} m < h <= {valid.h_max_m:g} m "
                f"and world.h is {list(w.h)}; allowed: world.h inside that range (below it "
                "the standard falls back to terrestrial formulas that need a base-station mast)"
            )
        dx = max(r.x[1] - w.x[0], w.x[1] - r.x[0])
        dy = max(r.y[1] - w.y[0], w.y[1] - r.y[0])
        if math.hypot(dx, dy) > valid.d2d_max_m:
            raise ValueError(
                f"{what} holds for horizontal distances up to {valid.d2d_max_m:g} m, and a UAV "
                f"in world x {list(w.x)}, y {list(w.y)} can be {math.hypot(dx, dy):.0f} m from a "
                f"user in comms.users.region x {list(r.x)}, y {list(r.y)}; allowed: a world "
                f"whose farthest point lies within {valid.d2d_max_m:g} m of the region"
            )

    def _encounters(self) -> None:
        """An encounter scenario flies one sampled intruder per episode, to a fixed goal."""
        e = self.encounters
        if e is None:
            return
        if self.intruders.list is not None or self.intruders.flow != "none":
            raise ValueError(
                "encounters: each episode's intruder is the sampled encounter's; set "
                "intruders.flow: none and no intruders.list"
            )
        if self.ownship.goal is None:
            raise ValueError(
                "encounters: set ownship.goal (the ownship's straight path from its start to "
                "the goal is the path the encounter is placed against)"
            )
        if not (aircraft_dir() / e.aircraft / f"{e.aircraft}.xml").is_file():
            known = sorted(
                p.name for p in aircraft_dir().iterdir() if (p / f"{p.name}.xml").is_file()
            )
            raise ValueError(
                f"encounters.intruder_aircraft '{e.intruder_aircraft}' is not a folder under "
                f"aircraft/ (known: {known}; c172x and c172p mean ga_c172)"
            )
        start, goal = self.ownship.start, self.ownship.goal
        if math.dist((start.x, start.y), goal[:2]) < 1.0:
            raise ValueError("encounters: ownship.goal must lie away from ownship.start")

    def _flyable(self) -> None:
        """Speeds the aircraft can fly, from the same numbers JSBSim reads (the autopilot's
        ap/speed-min-mps and ap/speed-max-mps, see uavxai.dynamics.world._check_speed)."""
        own, intr = self.ownship.aircraft, self.intruders.aircraft
        lo, hi = aircraft_speed_range(own)
        s = self.ownship.start.speed_mps
        if not lo <= s <= hi:
            raise ValueError(
                f"ownship.start.speed_mps = {s:g} m/s: aircraft '{own}' flies between {lo:g} and "
                f"{hi:g} m/s"
            )
        a = self.avoidance.speed_mps
        if max(lo, a[0]) >= min(hi, a[1]):
            raise ValueError(
                f"avoidance.speed_mps = {list(a)}: aircraft '{own}' flies between {lo:g} and "
                f"{hi:g} m/s; the two ranges must overlap"
            )
        lo, hi = aircraft_speed_range(intr)
        for i, spec in enumerate(self.intruders.list or []):
            if not lo <= spec.speed_mps <= hi:
                raise ValueError(
                    f"intruders.list.{i}.speed_mps = {spec.speed_mps:g} m/s: aircraft '{intr}' "
                    f"flies between {lo:g} and {hi:g} m/s"
                )
        r = self.intruders.speed_mps
        if self.intruders.list is None and not (lo <= r[0] and r[1] <= hi):
            raise ValueError(
                f"intruders.speed_mps = {list(r)}: aircraft '{intr}' flies between {lo:g} and "
                f"{hi:g} m/s; the drawn speeds must lie inside"
            )
        own_lo, _ = aircraft_speed_range(own)
        wind = self.environment.wind.speed_mps
        if wind >= own_lo:
            raise ValueError(
                f"environment.wind.speed_mps = {wind:g} m/s is not below the slowest airspeed of "
                f"aircraft '{own}' ({own_lo:g} m/s): flying slowly it would be blown backwards; "
                f"allowed: below {own_lo:g} m/s"
            )
        w = self.world
        r_orbit = self.mission.orbit_radius_m
        room = min(w.x[1] - w.x[0], w.y[1] - w.y[0]) / 2
        if r_orbit is not None and r_orbit > room:
            raise ValueError(
                f"mission.orbit_radius_m = {r_orbit:g} m: the orbit does not fit in the world "
                f"(x {list(w.x)}, y {list(w.y)}); allowed: at most {room:g} m, half the world's "
                "narrower side"
            )
        sv = self.intruders
        any_intruders = bool(sv.list) if sv.list is not None else sv.count > 0
        if (
            any_intruders
            and self.surveillance.noncooperative >= 1.0
            and self.surveillance.sensor is None
        ):
            raise ValueError(
                "surveillance.noncooperative = 1 (no intruder broadcasts ADS-B) with "
                "surveillance.sensor null (no onboard sensor): the planner would see no intruder "
                "at all; give a sensor, or make noncooperative less than 1"
            )

    def with_seed(self, seed: int) -> Scenario:
        return self.model_copy(update={"seed": int(seed)})


_TICK_TOL = 1e-6


def _whole_ticks(seconds: float, tick_s: float) -> int | None:
    """``seconds`` as a whole number (>= 1) of ``tick_s``, or None (the clock's rule)."""
    n = round(seconds / tick_s)
    if n < 1 or abs(n * tick_s - seconds) > _TICK_TOL * max(1.0, seconds):
        return None
    return n


def clock_ticks(dynamics: DynamicsConfig, avoidance: Avoidance) -> tuple[int, int, int]:
    """(ticks per sample, per decision, of latency) of the simulation clock
    (:class:`uavxai.sim.clock.Clock`), time counted in whole integrator ticks of
    1 / ``dynamics.rate_hz``; ValueError naming the setting when a period is not a whole number
    of ticks (a 100 Hz integrator with 30 Hz samples would decide every 0.9 s while the
    planner assumes 1 s), the decision period not a whole number of samples, or the latency
    not a whole number of samples shorter than the decision period. The one rule: the schema
    refuses with it at load, and the clock counts with it."""
    rate, traj = dynamics.rate_hz, dynamics.trajectory_hz
    period = avoidance.decision_period_s
    tick = 1.0 / rate
    sample = _whole_ticks(1.0 / traj, tick)
    if sample is None:
        raise ValueError(
            f"dynamics.rate_hz ({rate:g}) must be a whole multiple of dynamics.trajectory_hz "
            f"({traj:g}), e.g. 120 and 10"
        )
    decision = _whole_ticks(period, tick)
    if decision is None:
        raise ValueError(
            f"avoidance.decision_period_s = {period:g} s must be a whole number (>= 1) of "
            f"integrator steps of 1 / dynamics.rate_hz = {tick:g} s"
        )
    if decision % sample:
        raise ValueError(
            f"avoidance.decision_period_s = {period:g} s must be a whole number of "
            f"trajectory samples (1 / dynamics.trajectory_hz = {1 / traj:g} s)"
        )
    latency = avoidance.decision_latency_s
    lag = _whole_ticks(latency, tick) if latency > 0 else 0
    if lag is None or lag % sample or not latency < period:
        raise ValueError(
            f"avoidance.decision_latency_s = {latency:g} s must be 0 or a whole number of "
            f"trajectory samples (1 / dynamics.trajectory_hz = {1 / traj:g} s) shorter than "
            f"avoidance.decision_period_s = {period:g} s"
        )
    return sample, decision, lag
