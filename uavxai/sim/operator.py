"""The operator in the loop: flight modes and aims from a ground station, avoidance always on.

A ground station's command (decoded by ``uavxai.bridges.operator``) says where the ownship
goes, never how it flies: the avoidance planner keeps flying it clear of traffic towards the
aim, in every mode. :class:`Operator` watches an episode, takes the commands the command path
received since the last sample, and keeps the flight mode:

- ``AUTO`` (the start): the scenario's flight (its mission, or the transit to its goal), or a
  mission uploaded from a ground station, item by item (:class:`Route` of its items);
- ``GUIDED``: to the operator's point (DO_REPOSITION, MAVProxy's ``guided``), then a loiter
  about it; DO_ORBIT loiters about its centre at once;
- ``LOITER``: a loiter about where the aircraft is when selected;
- ``RTL``: home; the flight is ``completed`` there.

A height (DO_CHANGE_ALTITUDE) changes the height of the leg flown now, a speed
(DO_CHANGE_SPEED) the airspeed the autopilot holds whenever the planner does not ask for
another. Every loiter is flown by the avoidance planner itself, steering for the point of the
circle ahead (as the mission does when it avoids on station), so the search that keeps the
ownship clear never hands the aircraft to an orbit it has not checked.

With no command ever received the episode flies exactly as without an operator.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from uavxai.avoidance.types import Decision, Intruder, Ownship
from uavxai.bridges.operator import Kind, Mode, OperatorCommand
from uavxai.dynamics.state import TrafficState
from uavxai.sim.episode import EngineStep, Episode
from uavxai.vocabulary import Outcome

# MAV_CMD numbers of the mission items a Route flies (MAVLink common.xml).
NAV_WAYPOINT, NAV_LOITER_UNLIM, NAV_LOITER_TURNS, NAV_LOITER_TIME = 16, 17, 18, 19
NAV_RETURN_TO_LAUNCH, NAV_TAKEOFF, DO_CHANGE_SPEED = 20, 22, 178


@dataclass(frozen=True)
class Leg:
    """One leg of a route: go to a point (``loiter_s`` 0), loiter about it for ``loiter_s``
    (inf: until told otherwise), or go home (``home``: the flight completes there)."""

    x: float
    y: float
    h: float
    loiter_s: float = 0.0
    radius_m: float | None = None  # None: the scenario's orbit radius
    clockwise: bool = True
    home: bool = False
    seq: int | None = None  # the mission item it came from (MISSION_ITEM_REACHED)
    speed_mps: float | None = None  # DO_CHANGE_SPEED before it


class Route(EngineStep):
    """Legs flown in order, the avoidance planner flying every one of them. Has the
    interface the episode asks of a mission: ``goal``, ``decide``, ``outcome``,
    ``serving``."""

    def __init__(self, op: Operator, legs: Sequence[Leg], label: str) -> None:
        self.op = op
        self.legs = list(legs)
        self.label = label
        self.index = 0
        self.outcome: Outcome | None = None
        self.serving = False
        self._loiter_from: float | None = None  # when the loiter of this leg began
        self._own: tuple[float, float] | None = None
        self._horizon_s = 16.0

    @property
    def leg(self) -> Leg | None:
        return self.legs[self.index] if self.index < len(self.legs) else None

    @property
    def goal(self) -> tuple[float, float, float]:
        """The leg's point; loitering, the point of the circle the ownship would reach at the
        end of the planner's horizon (the mission's rule when it avoids on station): the
        planner flies the loiter itself, so its search keeps the ownship clear all along."""
        leg = self.leg or self.legs[-1]
        if self._loiter_from is None or self._own is None:
            return (leg.x, leg.y, leg.h)
        r = self._radius(leg)
        x, y, horizon = *self._own, self._horizon_s
        ahead = (1.0 if leg.clockwise else -1.0) * self.op.loiter_speed_mps * horizon / r
        b = math.atan2(x - leg.x, y - leg.y) + ahead
        return (leg.x + r * math.sin(b), leg.y + r * math.cos(b), leg.h)

    def start(self, ep: Episode) -> None:
        self._begin(ep)

    def _begin(self, ep: Episode) -> None:
        leg = self.leg
        if leg is None:
            return
        self._loiter_from = None
        if leg.speed_mps is not None:
            ep.path.set_cruise_speed(leg.speed_mps, ep.state.t)
        ep.path.altitude(leg.h, ep.state.t)
        if leg.seq is not None:
            self.op.mission_current(ep, leg.seq)

    def set_height(self, ep: Episode, h: float) -> None:
        leg = self.leg
        if leg is not None:
            self.legs[self.index] = _with(leg, h=float(h))
            ep.path.altitude(float(h), ep.state.t)

    def _radius(self, leg: Leg) -> float:
        return leg.radius_m if leg.radius_m is not None else self.op.radius_m

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        leg, p, t = self.leg, state.pos[0], state.t
        self._own = (float(p[0]), float(p[1]))
        cfg = ep.seat.config
        self._horizon_s = cfg.depth * cfg.action_hold_s
        if leg is None or self.outcome is not None:
            return
        d = math.hypot(p[0] - leg.x, p[1] - leg.y)
        reach = ep.judge.goal_radius_m
        if leg.home:
            if math.dist(p, (leg.x, leg.y, leg.h)) < reach:
                self.op.reached(ep, leg)
                self.outcome = Outcome.COMPLETED
            return
        if leg.loiter_s <= 0:
            if d < reach:
                self._next(ep, leg)
            return
        if self._loiter_from is None and d <= self._radius(leg) + reach:
            self._loiter_from = t
        if self._loiter_from is not None and t - self._loiter_from >= leg.loiter_s - 1e-9:
            self._next(ep, leg)

    def _next(self, ep: Episode, leg: Leg) -> None:
        self.op.reached(ep, leg)
        self.index += 1
        if self.leg is None:  # the last item flown: loiter there, as ArduPlane does
            self.legs.append(_with(leg, loiter_s=math.inf, seq=None, speed_mps=None))
            ep.path.announce(f"{self.label}: last item reached, loitering", None)
        self._begin(ep)

    def decide(self, ep: Episode, own: Ownship, intruders: list[Intruder]) -> Decision | None:
        """The avoidance planner flies every leg, loiters included (None)."""
        return None


def _with(leg: Leg, **changes) -> Leg:
    return dataclasses.replace(leg, **changes)


class Operator(EngineStep):
    """The flight mode and the operator's aims, between the ground station and the planner.

    ``radius_m`` and ``loiter_speed_mps``: the loiter a mode flies when the command names
    none (the scenario's orbit); ``home``: where RTL goes."""

    def __init__(
        self, home: Sequence[float], radius_m: float, loiter_speed_mps: float
    ) -> None:
        self.home = tuple(float(v) for v in home)
        self.radius_m = float(radius_m)
        self.loiter_speed_mps = float(loiter_speed_mps)
        self.mode = Mode.AUTO
        self.route: Route | None = None  # None: the scenario's own flight (AUTO)
        self.height_m: float | None = None  # the operator's height for the scenario's goal
        self.log: list[dict] = []  # every command taken, for summary.json and explanations
        self._goal_rule = None  # the judge's goal, put aside while a route flies
        self._mission_version: int | None = None

    # --------------------------------------------------------------------------- events
    def on_start(self, ep: Episode) -> None:
        ep.operator = self
        ep.path.set_mode(self.mode.value)

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        for cmd in ep.path.operator_commands():
            self.apply(ep, cmd)
        self._follow_uploads(ep)
        if self.route is not None:
            self.route.on_sample(ep, state)

    def _follow_uploads(self, ep: Episode) -> None:
        """Flying an uploaded mission, a ground station may upload another or pick the item
        to fly next (MISSION_SET_CURRENT, ``wp set N``): fly on from the current item."""
        route = self.route
        if route is None or route.label != "AUTO":
            return
        leg = route.leg
        current = ep.path.mission_current()
        moved = leg is not None and leg.seq is not None and current != leg.seq
        if ep.path.mission_version() != self._mission_version or moved:
            self._auto(ep, current)

    def on_end(self, ep: Episode, summary: dict) -> None:
        if self.log:
            summary["operator"] = {"mode_end": self.mode.value, "commands": self.log}

    # -------------------------------------------------------------------------- queries
    def active(self, ep: Episode):
        """What the planner flies for now: a route, the scenario's mission, or None (the
        scenario's goal)."""
        return self.route if self.route is not None else ep.mission

    def aim_words(self, ep: Episode, t: float) -> str:
        """The operator's latest aim, as an explanation opens with it ("" without one)."""
        if not self.log:
            return ""
        from uavxai.xai.explain import operator_aim

        last, own = self.log[-1], ep.state
        return operator_aim(last["asked"], last["kind"], t - last["t"], self.mode.value,
                            float(own.pos[0, 2]), float(own.airspeed[0]))  # fmt: skip

    # ------------------------------------------------------------------------- commands
    def apply(self, ep: Episode, cmd: OperatorCommand) -> None:
        t = ep.state.t
        self.log.append({"t": round(t, 3), "source": cmd.source, "kind": cmd.kind.value,
                         "asked": cmd.describe()})  # fmt: skip
        handler = {
            Kind.MODE: self._mode,
            Kind.SPEED: self._speed,
            Kind.ALTITUDE: self._altitude,
            Kind.GOTO: self._goto,
            Kind.ORBIT: self._orbit,
            Kind.MISSION_START: self._mission_start,
            Kind.SET_CURRENT: self._set_current,
        }[cmd.kind]
        handler(ep, cmd)

    def _speed(self, ep: Episode, cmd: OperatorCommand) -> None:
        ep.path.set_cruise_speed(cmd.speed_mps, ep.state.t)
        ep.path.announce(f"speed {cmd.speed_mps:.1f} m/s; avoidance stays on", None)

    def _altitude(self, ep: Episode, cmd: OperatorCommand) -> None:
        plan = self.active(ep)
        if plan is not None:
            plan.set_height(ep, cmd.h)
        else:
            self.height_m = cmd.h
            ep.path.altitude(cmd.h, ep.state.t)
        ep.path.announce(f"height {cmd.h:.0f} m; avoidance stays on", None)

    def _goto(self, ep: Episode, cmd: OperatorCommand) -> None:
        leg = Leg(cmd.x, cmd.y, cmd.h, loiter_s=math.inf)
        self._fly(ep, Mode.GUIDED, Route(self, [leg], "GUIDED"),
                  f"to ({cmd.x:.0f}, {cmd.y:.0f}) at {cmd.h:.0f} m")  # fmt: skip

    def _orbit(self, ep: Episode, cmd: OperatorCommand) -> None:
        if cmd.speed_mps is not None:
            ep.path.set_cruise_speed(cmd.speed_mps, ep.state.t)
        leg = Leg(cmd.x, cmd.y, cmd.h, loiter_s=math.inf, radius_m=cmd.radius_m,
                  clockwise=cmd.clockwise)  # fmt: skip
        self._fly(ep, Mode.GUIDED, Route(self, [leg], "GUIDED"),
                  f"orbit ({cmd.x:.0f}, {cmd.y:.0f}) r {cmd.radius_m:.0f} m")  # fmt: skip

    def _mode(self, ep: Episode, cmd: OperatorCommand) -> None:
        p = ep.state.pos[0]
        if cmd.mode == Mode.AUTO:
            self._auto(ep, None)
        elif cmd.mode == Mode.RTL:
            leg = Leg(*self.home, home=True)
            self._fly(ep, Mode.RTL, Route(self, [leg], "RTL"), "returning home")
        elif cmd.mode == Mode.LOITER:
            leg = Leg(float(p[0]), float(p[1]), float(p[2]), loiter_s=math.inf)
            self._fly(ep, Mode.LOITER, Route(self, [leg], "LOITER"),
                      f"loitering about ({p[0]:.0f}, {p[1]:.0f})")  # fmt: skip
        else:  # GUIDED with no point: loiter where it is, as ArduPlane does
            leg = Leg(float(p[0]), float(p[1]), float(p[2]), loiter_s=math.inf)
            self._fly(ep, Mode.GUIDED, Route(self, [leg], "GUIDED"), "loitering here")

    def _mission_start(self, ep: Episode, cmd: OperatorCommand) -> None:
        self._auto(ep, cmd.seq)

    def _set_current(self, ep: Episode, cmd: OperatorCommand) -> None:
        pass  # the bridge set the mission's current item; _follow_uploads flies it in AUTO

    def _auto(self, ep: Episode, first: int | None) -> None:
        """AUTO: an uploaded mission if there is one (from ``first``, else its current item),
        else the scenario's own flight."""
        items = ep.path.mission_items()
        if first is None:
            first = ep.path.mission_current()
        legs = mission_legs(items, self.home, first, self.radius_m, self.loiter_speed_mps)
        self._mission_version = ep.path.mission_version()
        if legs:
            self._fly(ep, Mode.AUTO, Route(self, legs, "AUTO"), "flying the uploaded mission")
            return
        self._scenario(ep, "flying the scenario's mission")

    def release(self, ep: Episode, why: str) -> None:
        """Back to the scenario's own flight whatever the mode (the battery's reserve)."""
        if self.route is not None or self.mode != Mode.AUTO:
            self._scenario(ep, why)

    def _scenario(self, ep: Episode, why: str) -> None:
        self.route = None
        self.mode = Mode.AUTO
        if self._goal_rule is not None:
            ep.judge.goal, self._goal_rule = self._goal_rule, None
        if ep.mission is not None:
            ep.mission.resume(ep)
        else:
            ep.path.altitude(self.height_m if self.height_m is not None else ep.goal[2],
                             ep.state.t)  # fmt: skip
        ep.path.set_mode(self.mode.value)
        ep.path.announce(f"AUTO: {why}; avoidance on", None)

    def _fly(self, ep: Episode, mode: Mode, route: Route, what: str) -> None:
        if ep.mission is not None:
            ep.mission.suspend()
        if self._goal_rule is None and ep.judge.goal is not None:
            # the scenario's goal ends the episode only while the scenario's flight is flown
            self._goal_rule, ep.judge.goal = ep.judge.goal, None
        self.mode, self.route = mode, route
        ep.path.set_mode(mode.value)
        ep.path.announce(f"{mode.value}: {what}; avoidance on", None)
        route.start(ep)

    # ---------------------------------------------------------------- mission reporting
    def reached(self, ep: Episode, leg: Leg) -> None:
        if leg.seq is not None:
            ep.path.mission_reached(leg.seq)

    def mission_current(self, ep: Episode, seq: int) -> None:
        ep.path.mission_set_current(seq)


def mission_legs(
    items: Sequence, home: Sequence[float], first: int | None, radius_m: float, speed_mps: float
) -> list[Leg]:
    """The legs of an uploaded mission (``uavxai.bridges.missions.MissionItem``s in the local
    frame, as ``CommandPath.mission_items`` gives them: (seq, command, params, x, y, h)),
    ArduPilot's way: item 0 is home and is not flown; flying starts at ``first`` (>= 1)."""
    legs: list[Leg] = []
    speed = None
    start = max(1, first or 1)
    for seq, command, params, x, y, h in items:
        if seq < start:
            continue
        if command == DO_CHANGE_SPEED and params[1] > 0:
            speed = float(params[1])
            continue
        if command == NAV_TAKEOFF:
            continue  # airborne already
        if command == NAV_RETURN_TO_LAUNCH:
            legs.append(Leg(*home, home=True, seq=seq, speed_mps=speed))
            break  # nothing after RTL is flown
        loiter = 0.0
        radius = abs(params[2]) if command != NAV_WAYPOINT and params[2] else None
        if command == NAV_LOITER_UNLIM:
            loiter = math.inf
        elif command == NAV_LOITER_TIME:
            loiter = max(0.0, float(params[0]))
        elif command == NAV_LOITER_TURNS:
            loiter = -max(0.0, float(params[0]))  # turns, converted below
        leg = Leg(x, y, h, loiter_s=loiter, radius_m=radius, seq=seq, speed_mps=speed,
                  clockwise=not (command != NAV_WAYPOINT and params[2] < 0))  # fmt: skip
        legs.append(leg)
        speed = None
    return [_turns_to_time(leg, radius_m, speed_mps) for leg in legs]


def _turns_to_time(leg: Leg, radius_m: float, speed_mps: float) -> Leg:
    """NAV_LOITER_TURNS: N turns as the time N circles take at the loiter airspeed."""
    if leg.loiter_s >= 0:
        return leg
    r = leg.radius_m if leg.radius_m is not None else radius_m
    return _with(leg, loiter_s=-leg.loiter_s * 2 * math.pi * r / speed_mps)


class ScriptedOperator(EngineStep):
    """The scenario's ``operator.commands``: each sent at its time as a ground station's
    MAVLink frames (system ``operator.system_id``) through the command path's operator input,
    which decodes them with the bridge's own decoder."""

    def __init__(self, scenario) -> None:
        from uavxai.bridges.operator import GroundStationEncoder
        from uavxai.dynamics.geodesy import LocalFrame

        op = scenario.operator
        gcs = GroundStationEncoder(op.system_id, scenario.bridge.system_id,
                                   LocalFrame.from_origin(scenario.world.origin))  # fmt: skip
        self.queue = sorted(((c.t, i, gcs.scripted(c)) for i, c in enumerate(op.commands)),
                            reverse=True)  # fmt: skip
        self.sent = 0

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        while self.queue and self.queue[-1][0] <= state.t + 1e-9:
            ep.path.operator_input(self.queue.pop()[2])
            self.sent += 1
