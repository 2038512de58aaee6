"""What a ground station's command means: an aim for the ownship, never a control surface.

A detect-and-avoid system protects the aircraft whatever the pilot commands; the pilot's
commands say where to go. So a command from a ground station (speed, height, a position to go
to, an orbit, a flight mode, a mission) is decoded here into an :class:`OperatorCommand`, an
aim the episode engine hands to the avoidance planner (``uavxai.sim.operator``); the planner
keeps flying the aircraft clear of traffic towards it. Nothing here writes an autopilot
setpoint. Raw setpoints from the ground (SET_ATTITUDE_TARGET, SET_POSITION_TARGET_*) would
take the aircraft away from the planner and are refused (:data:`SETPOINT_REFUSAL`).

The bridge decodes a live link's frames with :func:`decode`, and so do the campaigns' direct
path for a scenario's scripted operator (``operator.commands``): one decoder, whichever way
the bytes came.

Flight modes are ArduPlane's custom-mode numbers (HEARTBEAT.custom_mode), so that MAVProxy and
QGroundControl name them for a MAV_AUTOPILOT_ARDUPILOTMEGA fixed wing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import StrEnum

from pymavlink.dialects.v20 import common as mavlink

from uavxai.dynamics.geodesy import LocalFrame


class Mode(StrEnum):
    """The flight modes an operator may select (ArduPlane's names)."""

    AUTO = "AUTO"  # fly the mission: the uploaded one, else the scenario's
    GUIDED = "GUIDED"  # fly to the operator's point, then loiter there
    LOITER = "LOITER"  # orbit where the aircraft is
    RTL = "RTL"  # return home


# ArduPlane's custom_mode numbers (ArduPlane/mode.h), the ones ground stations name.
ARDUPLANE_MODES = {
    "MANUAL": 0, "CIRCLE": 1, "STABILIZE": 2, "TRAINING": 3, "ACRO": 4, "FBWA": 5, "FBWB": 6,
    "CRUISE": 7, "AUTOTUNE": 8, "AUTO": 10, "RTL": 11, "LOITER": 12, "TAKEOFF": 13,
    "AVOID_ADSB": 14, "GUIDED": 15,
}  # fmt: skip
MODE_NAMES = {number: name for name, number in ARDUPLANE_MODES.items()}
# The command failsafe's mode: wings level, holding height and speed.
FAILSAFE_MODE = ARDUPLANE_MODES["FBWA"]
FLYABLE = ", ".join(m.value for m in Mode)

# One STATUSTEXT holds 50 characters.
SETPOINT_REFUSAL = "setpoint refused: send mode/height/speed/point"
assert len(SETPOINT_REFUSAL) <= 50


class Kind(StrEnum):
    MODE = "mode"
    SPEED = "speed"
    ALTITUDE = "altitude"
    GOTO = "goto"  # GUIDED to a point (DO_REPOSITION, MAVProxy's `guided`)
    ORBIT = "orbit"  # GUIDED loiter about a point (DO_ORBIT)
    MISSION_START = "mission_start"  # AUTO from an item (MAV_CMD_MISSION_START)
    SET_CURRENT = "set_current"  # the mission item to fly next (MAV_CMD_DO_SET_MISSION_CURRENT)


@dataclass(frozen=True)
class OperatorCommand:
    """One aim from a ground station, in the local frame (m, m/s), already held to the limits."""

    kind: Kind
    source: int  # the ground station's MAVLink system id
    mode: Mode | None = None
    speed_mps: float | None = None
    h: float | None = None  # height above the local origin
    x: float | None = None
    y: float | None = None
    radius_m: float | None = None
    clockwise: bool = True
    seq: int | None = None  # MISSION_START: the first item flown

    def describe(self) -> str:
        """What the operator asked for, as an explanation quotes it."""
        if self.kind == Kind.MODE:
            return f"mode {self.mode}"
        if self.kind == Kind.SPEED:
            return f"{self.speed_mps:.0f} m/s"
        if self.kind == Kind.ALTITUDE:
            return f"{self.h:.0f} m"
        if self.kind == Kind.GOTO:
            return f"go to ({self.x:.0f}, {self.y:.0f}) at {self.h:.0f} m"
        if self.kind == Kind.ORBIT:
            return f"orbit ({self.x:.0f}, {self.y:.0f}) at {self.radius_m:.0f} m radius"
        if self.kind == Kind.SET_CURRENT:
            return f"mission item {self.seq} next"
        return f"mission from item {self.seq}"


@dataclass(frozen=True)
class Limits:
    """What every command is held to: the world and the aircraft."""

    alt_m: tuple[float, float]
    speed_mps: tuple[float, float]
    xy_m: tuple[tuple[float, float], tuple[float, float]]

    def alt(self, h: float) -> tuple[float, str | None]:
        return _held("h", h, *self.alt_m, "m")

    def speed(self, v: float) -> tuple[float, str | None]:
        return _held("speed", v, *self.speed_mps, "m/s")

    def point(self, x: float, y: float) -> tuple[float, float, str | None]:
        (x0, x1), (y0, y1) = self.xy_m
        cx, cy = min(max(x, x0), x1), min(max(y, y0), y1)
        # degE7 on the wire is ~1 cm: a point sent on the edge may come back just outside it.
        if math.hypot(cx - x, cy - y) > ORBIT_CENTRE_TOLERANCE_M:
            return cx, cy, f"point ({x:.0f}, {y:.0f}) -> ({cx:.0f}, {cy:.0f})"
        return cx, cy, None

    def radius(self, r: float) -> tuple[float, str | None]:
        # A circle larger than the world is no orbit of this world.
        (x0, x1), (y0, y1) = self.xy_m
        largest = max(max(x1 - x0, y1 - y0) / 2, MIN_ORBIT_RADIUS_M)
        flown = min(max(abs(r), MIN_ORBIT_RADIUS_M), largest)
        return flown, (f"radius {abs(r):.4g} -> {flown:.6g} m" if flown != abs(r) else None)


MIN_ORBIT_RADIUS_M = 1.0
ORBIT_CENTRE_TOLERANCE_M = 0.05


def _held(name: str, value: float, lo: float, hi: float, unit: str) -> tuple[float, str | None]:
    flown = min(max(value, lo), hi)
    # MAVLink carries float32: a value sent exactly at a limit may arrive a hair beyond it.
    tolerance = 1e-6 * max(1.0, abs(lo), abs(hi))
    if lo - tolerance <= value <= hi + tolerance:
        return flown, None
    return flown, f"{name} {value:.4g} -> {flown:.6g} {unit}"


@dataclass
class Decoded:
    """A ground station's message, read: the aim (or None), the clamps applied to it, or why
    it was refused (``refused``, a STATUSTEXT of at most 50 characters)."""

    command: OperatorCommand | None = None
    notes: list[str] = field(default_factory=list)
    refused: str | None = None
    result: int = mavlink.MAV_RESULT_ACCEPTED  # COMMAND_ACK result, for COMMAND_LONG/INT


def _refuse(why: str, result: int = mavlink.MAV_RESULT_DENIED) -> Decoded:
    return Decoded(refused=why[:50], result=result)


def _finite(*values: float) -> bool:
    return all(isinstance(v, (int, float)) and math.isfinite(v) for v in values)


def decode(msg, frame: LocalFrame, limits: Limits) -> Decoded | None:
    """The aim a ground station's message asks for; None for a message that is no operator
    command (telemetry requests, parameters, mission transfer)."""
    handler = _DECODERS.get(msg.get_type())
    return handler(msg, frame, limits) if handler is not None else None


def _mode_of(custom_mode: float, source: int) -> Decoded:
    number = int(custom_mode) if _finite(custom_mode) else -1
    name = MODE_NAMES.get(number)
    if name is None or name not in Mode.__members__:
        shown = name or f"#{number}"
        return _refuse(f"mode {shown} refused: use {FLYABLE}")
    return Decoded(OperatorCommand(Kind.MODE, source, mode=Mode(name)))


def _set_mode(msg, frame: LocalFrame, limits: Limits) -> Decoded:
    return _mode_of(msg.custom_mode, msg.get_srcSystem())


def _command_long(msg, frame: LocalFrame, limits: Limits) -> Decoded | None:
    return _command(msg.get_srcSystem(), msg.command, msg.param1, msg.param2, frame, limits)


def _command(
    src: int, c: int, param1: float, param2: float, frame: LocalFrame, limits: Limits
) -> Decoded | None:
    """COMMAND_LONG's aims (also when sent as COMMAND_INT, as QGroundControl does for some)."""
    if c == mavlink.MAV_CMD_DO_SET_MODE:
        if not (_finite(param1) and int(param1) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED):
            return _refuse(f"DO_SET_MODE needs a custom mode: {FLYABLE}")
        return _mode_of(param2, src)
    if c == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
        return Decoded(OperatorCommand(Kind.MODE, src, mode=Mode.RTL))
    if c == mavlink.MAV_CMD_NAV_LOITER_UNLIM:
        return Decoded(OperatorCommand(Kind.MODE, src, mode=Mode.LOITER))
    if c == mavlink.MAV_CMD_DO_SET_MISSION_CURRENT:
        if not (_finite(param1) and 0 <= param1 < 65536):
            return _refuse("DO_SET_MISSION_CURRENT: an item number")
        return Decoded(OperatorCommand(Kind.SET_CURRENT, src, seq=int(param1)))
    if c == mavlink.MAV_CMD_MISSION_START:
        first = int(param1) if _finite(param1) and param1 >= 1 else None
        return Decoded(OperatorCommand(Kind.MISSION_START, src, seq=first))
    if c == mavlink.MAV_CMD_DO_CHANGE_SPEED:
        # param1 speed type: 0 airspeed, 1 ground speed; both set the airspeed aimed for, as
        # this autopilot holds airspeed. param2 -1 ("no change") would leave only a throttle
        # change, which it does not take: refused like any speed <= 0.
        if param1 not in (0, 1) or not _finite(param2) or param2 <= 0:
            return _refuse(f"DO_CHANGE_SPEED {param2:.4g} refused: > 0 m/s")
        v, note = limits.speed(float(param2))
        return Decoded(OperatorCommand(Kind.SPEED, src, speed_mps=v), [note] if note else [])
    if c == mavlink.MAV_CMD_DO_CHANGE_ALTITUDE:
        offsets = {
            mavlink.MAV_FRAME_GLOBAL: -frame.alt0,
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: 0.0,
        }
        if param2 not in offsets or not _finite(param1):
            return _refuse("DO_CHANGE_ALTITUDE: frame GLOBAL or RELATIVE_ALT")
        return _altitude(float(param1) + offsets[int(param2)], src, limits)
    return None


def _altitude(h: float, src: int, limits: Limits) -> Decoded:
    flown, note = limits.alt(h)
    return Decoded(OperatorCommand(Kind.ALTITUDE, src, h=flown), [note] if note else [])


# COMMAND_INT frames whose z is a height above home (= the local origin's ground) or MSL.
_HEIGHT_FRAMES = {
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT: 0.0,
    mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: 0.0,
    mavlink.MAV_FRAME_GLOBAL: None,  # MSL: minus the origin's altitude
    mavlink.MAV_FRAME_GLOBAL_INT: None,
}


def _position(
    lat: float, lon: float, z: float, frame_id: int, frame: LocalFrame, limits: Limits
) -> tuple[float, float, float, list[str]] | str:
    """A global position command as a local point held to the world, or why it is refused."""
    if frame_id not in _HEIGHT_FRAMES:
        return "frame refused: GLOBAL or GLOBAL_RELATIVE_ALT"
    if not (_finite(lat, lon, z) and abs(lat) <= 90 and abs(lon) <= 180):
        return "position refused: not a finite lat/lon/alt"
    x, y, _ = frame.to_local(lat, lon, 0.0)
    offset = _HEIGHT_FRAMES[frame_id]
    h = z + (-frame.alt0 if offset is None else offset)
    cx, cy, note_xy = limits.point(float(x), float(y))
    flown_h, note_h = limits.alt(h)
    return cx, cy, flown_h, [n for n in (note_xy, note_h) if n]


def _command_int(msg, frame: LocalFrame, limits: Limits) -> Decoded | None:
    src, c = msg.get_srcSystem(), msg.command
    if c not in (mavlink.MAV_CMD_DO_ORBIT, mavlink.MAV_CMD_DO_REPOSITION):
        return _command(src, c, msg.param1, msg.param2, frame, limits)
    where = _position(msg.x / 1e7, msg.y / 1e7, msg.z, msg.frame, frame, limits)
    if isinstance(where, str):
        return _refuse(where)
    x, y, h, notes = where
    if c == mavlink.MAV_CMD_DO_REPOSITION:
        return Decoded(OperatorCommand(Kind.GOTO, src, x=x, y=y, h=h), notes)
    # DO_ORBIT: param1 radius (m, positive clockwise), param2 speed (NaN or <= 0: unchanged)
    radius = msg.param1
    if not (_finite(radius) and abs(radius) >= MIN_ORBIT_RADIUS_M):
        return _refuse(f"DO_ORBIT radius {radius:.4g} refused: >= 1 m")
    r, note = limits.radius(float(radius))
    notes += [note] if note else []
    speed = None
    if _finite(msg.param2) and msg.param2 > 0:
        speed, note = limits.speed(float(msg.param2))
        notes += [note] if note else []
    cmd = OperatorCommand(
        Kind.ORBIT, src, x=x, y=y, h=h, radius_m=r, clockwise=radius >= 0, speed_mps=speed
    )
    return Decoded(cmd, notes)


def _mission_item(msg, frame: LocalFrame, limits: Limits) -> Decoded | None:
    """MISSION_ITEM(_INT) outside a mission upload, ArduPilot's way: ``current`` 2 is a GUIDED
    "fly to" (MAVProxy's ``guided LAT LON ALT``), 3 a change of height (``changealt``)."""
    if msg.current not in (2, 3):
        return None  # part of a mission upload: the mission protocol's
    scale = 1e7 if msg.get_type() == "MISSION_ITEM_INT" else 1.0
    src = msg.get_srcSystem()
    if msg.current == 3:
        rel = msg.frame in (
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
        )  # fmt: skip
        if not _finite(msg.z):
            return _refuse("change of height refused: not finite")
        return _altitude(float(msg.z) - (0.0 if rel else frame.alt0), src, limits)
    where = _position(msg.x / scale, msg.y / scale, msg.z, msg.frame, frame, limits)
    if isinstance(where, str):
        return _refuse(where)
    x, y, h, notes = where
    return Decoded(OperatorCommand(Kind.GOTO, src, x=x, y=y, h=h), notes)


def _setpoint(msg, frame: LocalFrame, limits: Limits) -> Decoded:
    return _refuse(SETPOINT_REFUSAL)


_DECODERS = {
    "SET_MODE": _set_mode,
    "COMMAND_LONG": _command_long,
    "COMMAND_INT": _command_int,
    "MISSION_ITEM": _mission_item,
    "MISSION_ITEM_INT": _mission_item,
    "SET_ATTITUDE_TARGET": _setpoint,
    "SET_POSITION_TARGET_LOCAL_NED": _setpoint,
    "SET_POSITION_TARGET_GLOBAL_INT": _setpoint,
}


# ------------------------------------------------------------------ the ground station's side
GCS_COMPONENT = mavlink.MAV_COMP_ID_MISSIONPLANNER  # 190, as MAVProxy and QGroundControl


class GroundStationEncoder:
    """What a ground station sends for each aim, as MAVLink 2 frames: the scripted operator's
    commands (``operator.commands``) and the tests' ground stations speak through this."""

    def __init__(self, system_id: int, target_system: int, frame: LocalFrame) -> None:
        self._codec = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=GCS_COMPONENT)
        self._target = target_system
        self._frame = frame

    def _pack(self, msg) -> bytes:
        return msg.pack(self._codec)

    def _long(self, command: int, p1: float = 0.0, p2: float = 0.0) -> bytes:
        return self._pack(mavlink.MAVLink_command_long_message(
            self._target, 1, command, 0, p1, p2, 0.0, 0.0, 0.0, 0.0, 0.0
        ))  # fmt: skip

    def _int(self, command: int, x: float, y: float, h: float, p1: float, p2: float) -> bytes:
        lat, lon, _ = self._frame.to_geodetic(x, y, 0.0)
        return self._pack(mavlink.MAVLink_command_int_message(
            self._target, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, command, 0, 0,
            p1, p2, 0.0, 0.0, round(float(lat) * 1e7), round(float(lon) * 1e7), float(h),
        ))  # fmt: skip

    def altitude(self, h: float) -> bytes:
        return self._long(mavlink.MAV_CMD_DO_CHANGE_ALTITUDE, h,
                          mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)  # fmt: skip

    def speed(self, v: float) -> bytes:
        return self._long(mavlink.MAV_CMD_DO_CHANGE_SPEED, 0.0, v)

    def mode(self, name: str) -> bytes:
        flag = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        return self._long(mavlink.MAV_CMD_DO_SET_MODE, flag, ARDUPLANE_MODES[name])

    def goto(self, x: float, y: float, h: float) -> bytes:
        return self._int(mavlink.MAV_CMD_DO_REPOSITION, x, y, h, -1.0,
                         mavlink.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE)  # fmt: skip

    def orbit(self, x: float, y: float, h: float, radius_m: float, clockwise: bool) -> bytes:
        r = abs(radius_m) if clockwise else -abs(radius_m)
        return self._int(mavlink.MAV_CMD_DO_ORBIT, x, y, h, r, float("nan"))

    def scripted(self, spec) -> bytes:
        """A scenario's ``operator.commands`` entry (uavxai.scenario.OperatorCommandSpec)."""
        if spec.altitude_m is not None:
            return self.altitude(spec.altitude_m)
        if spec.speed_mps is not None:
            return self.speed(spec.speed_mps)
        if spec.mode is not None:
            return self.mode(spec.mode)
        if spec.goto is not None:
            return self.goto(*spec.goto)
        o = spec.orbit
        return self.orbit(o.x, o.y, o.h, o.radius_m, o.clockwise)
