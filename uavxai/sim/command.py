"""How a decision reaches the autopilot: one interface, two paths.

:class:`MavlinkPath` (``uavxai run``): the decision becomes MAVLink 2 bytes (stamped with
simulated ``time_boot_ms``), the bridge decodes them and writes the autopilot setpoints, and
publishes telemetry and ADS-B every sample — an external peer on the link is obeyed the same
way. :class:`DirectPath` (campaigns): the setpoints go straight to the autopilot, carried at
the precision MAVLink carries them (float32 fields, the bank as a quaternion's roll), so that
the same seed flies the same to the millimetre through either path.

A decision of the vertical action set also carries a height target (``alt_target_m``: the
ceiling band for a climb, the floor band for a descent, the leg's height otherwise). It goes
the way every height command goes, MAV_CMD_DO_CHANGE_ALTITUDE (a float32 ``param1``, height
above home), with every decision: SET_ATTITUDE_TARGET has no height and the acceleration's
SET_POSITION_TARGET_LOCAL_NED is in the body frame, where a position is relative to the
aircraft, not the height the autopilot holds.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from uavxai.avoidance.types import Decision
from uavxai.bridges.protocol import roll_from_quaternion, roll_quaternion
from uavxai.dynamics.protocol import Dynamics
from uavxai.dynamics.state import TrafficState

if TYPE_CHECKING:
    from uavxai.bridges.telemetry import Power


class CommandPath(Protocol):
    def send(self, decision: Decision, t: float) -> None:
        """Deliver the decision's setpoints at simulated time ``t``."""

    def on_sample(self, state: TrafficState) -> None:
        """After every sample: read the link, publish what is due."""

    def relay(self, frames: bytes) -> None:
        """Frames for the ground stations (the ADS-B receiver's reports), if there is a link."""

    def show_truth_traffic(self, on: bool) -> None:
        """Show the ground stations every intruder's exact state (``on``: no surveillance
        model), or only the receiver's reports that :meth:`relay` forwards."""

    @property
    def power(self) -> Power | None:
        """The power system as the link reports it (SYS_STATUS, VFR_HUD), for the battery's
        observer to fill in; None: no link to report it on."""

    def orbit(
        self, x: float, y: float, h: float, radius_m: float, clockwise: bool, speed_mps: float,
        t: float,
    ) -> None:
        """Put the autopilot in loiter about (x, y) at height h and an airspeed
        (MAV_CMD_DO_ORBIT)."""

    def announce(self, text: str, phase: str | None = None) -> None:
        """Tell the ground stations (STATUSTEXT; ``phase``: the flight mode they show)."""

    def altitude(self, h: float, t: float) -> None:
        """The height the autopilot holds (MAV_CMD_DO_CHANGE_ALTITUDE)."""

    def set_cruise_speed(self, speed_mps: float, t: float) -> None:
        """An operator's airspeed (DO_CHANGE_SPEED): the autopilot flies it and never faster;
        the planner may still slow down below it."""

    def cruise_speed(self, default: float) -> float:
        """The operator's airspeed if one was asked for, else ``default``."""

    def set_mode(self, mode: str) -> None:
        """The flight mode ground stations see (HEARTBEAT)."""

    def operator_input(self, frames: bytes) -> None:
        """MAVLink frames from the scenario's scripted operator (``operator.commands``), taken
        as from a ground station the scenario allows."""

    def operator_commands(self) -> list:
        """The operator's commands received since the last call (OperatorCommand)."""

    def mission_items(self) -> list[tuple]:
        """The mission uploaded from a ground station, as (seq, command, params, x, y, h)."""

    def mission_current(self) -> int:
        """The uploaded mission's current item (0: none)."""

    def mission_version(self) -> int:
        """Changes whenever a ground station uploads or clears a mission."""

    def mission_reached(self, seq: int) -> None:
        """Tell the ground stations an item was reached (MISSION_ITEM_REACHED)."""

    def mission_set_current(self, seq: int) -> None:
        """Tell the ground stations the item flown now (MISSION_CURRENT)."""

    def close(self) -> dict[str, int] | None:
        """Finish; returns the link's counters for summary.json (None: no link)."""


def orbit_centre_on_wire(frame, x: float, y: float) -> tuple[int, int, float, float]:
    """An orbit centre as COMMAND_INT carries it (lat/lon degE7) and where that lands back
    in the local frame: both paths orbit the same point."""
    lat, lon, _ = frame.to_geodetic(x, y, 0.0)
    lat_e7, lon_e7 = round(float(lat) * 1e7), round(float(lon) * 1e7)
    xq, yq, _ = frame.to_local(lat_e7 / 1e7, lon_e7 / 1e7, 0.0)
    return lat_e7, lon_e7, float(xq), float(yq)


def wire_values(bank_cmd_rad: float, accel_mps2: float) -> tuple[float, float]:
    """The setpoints as MAVLink carries them: float32 fields, the bank as a quaternion."""
    q = np.asarray(roll_quaternion(bank_cmd_rad), dtype=np.float32)
    return roll_from_quaternion(q.tolist()), float(np.float32(accel_mps2))


class _Cruise:
    """The operator's airspeed, a ceiling: once asked for, the autopilot flies it and never
    faster (DO_CHANGE_SPEED sets its speed target and lowers its top speed to it). The planner
    keeps its accelerations (the episode gives it ``Ownship.speed_band`` up to that speed),
    so it may slow down to let traffic pass and speeds up to the operator's airspeed again."""

    _cruise: float | None = None

    def cruise_speed(self, default: float) -> float:
        return self._cruise if self._cruise is not None else default

    def set_cruise_speed(self, speed_mps: float, t: float) -> None:
        self._cruise = float(np.float32(speed_mps))
        self._speed(self._cruise, t)

    def _speed(self, speed_mps: float, t: float) -> None:
        raise NotImplementedError


class DirectPath(_Cruise):
    """Setpoints straight to the autopilot (no bytes, no bridge). A scripted operator's
    frames are decoded by the bridge's own decoder (``uavxai.bridges.operator``)."""

    def __init__(self, world: Dynamics) -> None:
        from uavxai.bridges.framing import FrameReader
        from uavxai.bridges.operator import Limits
        from uavxai.bridges.protocol import AUTOPILOT_COMPONENT, new_codec
        from uavxai.dynamics.geodesy import LocalFrame

        self._world = world
        sc = world.scenario
        self._frame = LocalFrame.from_origin(sc.world.origin)
        self.commands = 0
        self._system = sc.bridge.system_id
        self._reader = FrameReader(new_codec(None, self._system, AUTOPILOT_COMPONENT), False)
        self._limits = operator_limits(sc)
        self._limits_type = Limits
        self._received: list = []

    def orbit(self, x, y, h, radius_m, clockwise, speed_mps, t) -> None:
        _, _, xq, yq = orbit_centre_on_wire(self._frame, x, y)
        self._world.command_ownship(
            alt_target_m=float(np.float32(h)), speed_target_mps=float(np.float32(speed_mps))
        )
        self._world.command_orbit(xq, yq, float(np.float32(radius_m)), clockwise)
        self.commands += 1

    def send(self, decision: Decision, t: float) -> None:
        bank, accel = wire_values(decision.bank_cmd_rad, decision.accel_mps2)
        self._world.command_ownship(bank_cmd_rad=bank, accel_cmd_mps2=accel)
        self.commands += 2
        if decision.alt_target_m is not None:  # the vertical set's height command
            self.altitude(decision.alt_target_m, t)

    def _speed(self, speed_mps: float, t: float) -> None:
        # what the bridge does with DO_CHANGE_SPEED (MavlinkBridge._fly_planner_command)
        self._world.command_ownship(speed_target_mps=speed_mps, speed_max_mps=speed_mps)
        self.commands += 1

    def operator_input(self, frames: bytes) -> None:
        from uavxai.bridges.operator import decode

        for msg in self._reader.push(frames).messages:
            # pymavlink's message classes: only those addressed to a vehicle have the field
            if getattr(msg, "target_system", self._system) not in (self._system, 0):
                continue
            read = decode(msg, self._frame, self._limits)
            if read is not None and read.command is not None:
                self._received.append(read.command)

    def operator_commands(self) -> list:
        out, self._received = self._received, []
        return out

    def set_mode(self, mode: str) -> None:
        pass

    def mission_items(self) -> list[tuple]:
        return []

    def mission_current(self) -> int:
        return 0

    def mission_version(self) -> int:
        return 0

    def mission_reached(self, seq: int) -> None:
        pass

    def mission_set_current(self, seq: int) -> None:
        pass

    def on_sample(self, state: TrafficState) -> None:
        pass

    def relay(self, frames: bytes) -> None:
        pass

    def show_truth_traffic(self, on: bool) -> None:
        pass

    power = None  # no link: no one to show the battery to

    def announce(self, text: str, phase: str | None = None) -> None:
        pass

    def altitude(self, h: float, t: float) -> None:
        self._world.command_ownship(alt_target_m=float(np.float32(h)))
        self.commands += 1

    def close(self) -> None:
        return None


class MavlinkPath(_Cruise):
    """The planner as a companion computer: its commands are bytes through the bridge.

    A ground station's command on the link (a DO_CHANGE_ALTITUDE from MAVProxy, a mode, a
    mission) is an aim: the bridge decodes it and :meth:`operator_commands` hands it to the
    episode's operator (``uavxai.sim.operator``); the planner keeps flying."""

    def __init__(self, bridge, encoder) -> None:
        self.bridge = bridge
        self._encoder = encoder

    def send(self, decision: Decision, t: float) -> None:
        self.bridge.feed(self._encoder.encode(decision.bank_cmd_rad, decision.accel_mps2, t))
        if decision.alt_target_m is not None:  # the vertical set's height command
            self.altitude(decision.alt_target_m, t)

    def _speed(self, speed_mps: float, t: float) -> None:
        self.bridge.feed(self._encoder.change_speed(speed_mps))

    def orbit(self, x, y, h, radius_m, clockwise, speed_mps, t) -> None:
        lat_e7, lon_e7, _, _ = orbit_centre_on_wire(self.bridge.frame, x, y)
        self.bridge.feed(self._encoder.orbit(lat_e7, lon_e7, h, radius_m, clockwise, speed_mps))

    def on_sample(self, state: TrafficState) -> None:
        self.bridge.poll()
        self.bridge.publish(state)

    def operator_input(self, frames: bytes) -> None:
        self.bridge.feed_operator(frames)

    def operator_commands(self) -> list:
        return self.bridge.take_operator_commands()

    def set_mode(self, mode: str) -> None:
        self.bridge.mode = mode

    def mission_items(self) -> list[tuple]:
        return self.bridge.mission_items_local()

    def mission_current(self) -> int:
        return self.bridge.missions.current

    def mission_version(self) -> int:
        return self.bridge.missions.version

    def mission_reached(self, seq: int) -> None:
        self.bridge.missions.reached(seq)

    def mission_set_current(self, seq: int) -> None:
        self.bridge.missions.set_current(seq)

    def relay(self, frames: bytes) -> None:
        self.bridge.relay(frames)

    def show_truth_traffic(self, on: bool) -> None:
        self.bridge.truth_adsb = on

    @property
    def power(self) -> Power:
        return self.bridge.power

    def announce(self, text: str, phase: str | None = None) -> None:
        if phase is not None:
            self.bridge.phase = phase
        self.bridge.announce(text)

    def altitude(self, h: float, t: float) -> None:
        self.bridge.feed(self._encoder.change_altitude(h))

    def close(self) -> dict[str, int]:
        counters = dict(self.bridge.counters)
        self.bridge.close()
        return counters


def operator_limits(scenario):
    """What an operator's commands are held to: the scenario's world and the aircraft."""
    from uavxai.bridges.operator import Limits
    from uavxai.scenario import aircraft_speed_range

    w = scenario.world
    return Limits(
        alt_m=(float(w.h[0]), float(w.h[1])),
        speed_mps=tuple(float(v) for v in aircraft_speed_range(scenario.ownship.aircraft)),
        xy_m=((float(w.x[0]), float(w.x[1])), (float(w.y[0]), float(w.y[1]))),
    )
