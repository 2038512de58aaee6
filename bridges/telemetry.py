"""Telemetry messages built from a TrafficState: the ownship as ground stations expect a vehicle,
the intruders as ADS-B traffic. Pure functions; the bridge decides when to send them.

SI and ENU come in, MAVLink units go out, and only here:

* GLOBAL_POSITION_INT: lat/lon degE7, alt = MSL (mm), relative_alt = h above the local origin
  (mm; the default home is on the ground below the start, so this is "above home"),
  vx/vy/vz NED (cm/s), hdg = psi (cdeg).
* ATTITUDE: roll = phi, pitch = theta, yaw = psi wrapped to (-pi, pi] (rad; NED yaw is
  clockwise from north, the same convention as psi); body rates from the attitude change
  between two published states.
* VFR_HUD: airspeed = true airspeed, groundspeed (m/s), heading (deg), alt MSL (m), climb (m/s).
* ADSB_VEHICLE: lat/lon degE7, geometric altitude MSL (mm), course over ground (cdeg),
  horizontal speed (cm/s), vertical speed up (cm/s).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState, is_member
from uavxai.geometry import wrap_angle

from .operator import ARDUPLANE_MODES, FAILSAFE_MODE
from .protocol import boot_ms

# Simulated intruders get addresses from one made-up block, numbered as intruder-N, so a ground
# station can tell them apart and they are flagged ADSB_FLAGS_SIMULATED as well.
ICAO_BLOCK = 0xF00000
ADSB_FLAGS = (
    mavlink.ADSB_FLAGS_VALID_COORDS
    | mavlink.ADSB_FLAGS_VALID_ALTITUDE
    | mavlink.ADSB_FLAGS_VALID_HEADING
    | mavlink.ADSB_FLAGS_VALID_VELOCITY
    | mavlink.ADSB_FLAGS_VALID_CALLSIGN
    | mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID
    | mavlink.ADSB_FLAGS_SIMULATED
)
_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
)
# MISSION_INT: MAVLink asks every vehicle that takes missions to set it (bridges.missions), and
# ground stations that see it upload MISSION_ITEM_INT (cm) rather than float MISSION_ITEM.
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
)
_UINT16_UNKNOWN = 0xFFFF
# Below this ground speed the course is noise; ADS-B then reports the heading instead.
_MIN_COURSE_SPEED_MPS = 0.5


class RateGate:
    """Opens at `rate_hz` of simulated time, phase-locked to its first opening, so rates hold
    however often (and however evenly) the caller asks."""

    _SLACK_S = 1e-6  # float noise in summed time steps must not skip a beat

    def __init__(self, rate_hz: float) -> None:
        if not rate_hz > 0:
            raise ValueError(f"a message rate must be positive, got {rate_hz} Hz")
        self.period_s = 1.0 / rate_hz
        self._next: float | None = None

    def due(self, t: float) -> bool:
        if self._next is not None and t < self._next - self._SLACK_S:
            return False
        behind = self._next is None or t - self._next >= self.period_s
        self._next = t + self.period_s if behind else self._next + self.period_s
        return True

    def restart(self) -> None:
        self._next = None




def heartbeat(failsafe: bool, mode: str = "AUTO") -> mavlink.MAVLink_heartbeat_message:
    """An ArduPlane-compatible HEARTBEAT: MAV_AUTOPILOT_ARDUPILOTMEGA and ArduPlane's custom
    mode numbers, so that MAVProxy and QGroundControl name the mode (AUTO, GUIDED, LOITER,
    RTL; FBWA while the command failsafe holds the wings level)."""
    custom = FAILSAFE_MODE if failsafe else ARDUPLANE_MODES[mode]
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_FIXED_WING,
        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
        mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
        | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        custom,
        mavlink.MAV_STATE_CRITICAL if failsafe else mavlink.MAV_STATE_ACTIVE,
        3,
    )


@dataclass
class Power:
    """What the vehicle reports of its power system (None: not simulated)."""

    voltage_v: float | None = None
    current_a: float | None = None
    soc: float | None = None  # state of charge, 0..1
    throttle: float | None = None  # 0..1


def sys_status(errors_comm: int, power: Power | None = None) -> mavlink.MAVLink_sys_status_message:
    """Healthy sensors and controllers, the battery when simulated, dropped input bytes as
    comm errors."""
    p = power or Power()
    return mavlink.MAVLink_sys_status_message(
        _SENSORS,
        _SENSORS,
        _SENSORS,
        0,
        _UINT16_UNKNOWN if p.voltage_v is None else min(round(p.voltage_v * 1000), 0xFFFE),
        -1 if p.current_a is None else min(round(p.current_a * 100), 0x7FFF),
        -1 if p.soc is None else max(0, min(100, round(100 * p.soc))),
        0,
        min(errors_comm, 0xFFFF),
        0,
        0,
        0,
        0,
    )


def global_position_int(
    state: TrafficState, frame: LocalFrame
) -> mavlink.MAVLink_global_position_int_message:
    x, y, h = state.pos[0]
    ve, vn, vu = state.vel[0]
    lat, lon, alt = frame.to_geodetic(x, y, h)
    return mavlink.MAVLink_global_position_int_message(
        boot_ms(state.t),
        _deg_e7(lat),
        _deg_e7(lon),
        round(float(alt) * 1000.0),
        round(float(h) * 1000.0),
        _int16(vn * 100.0),
        _int16(ve * 100.0),
        _int16(-vu * 100.0),
        _cdeg(state.att[0, 2]),
    )


def attitude(state: TrafficState, rates: np.ndarray) -> mavlink.MAVLink_attitude_message:
    phi, theta, psi = state.att[0]
    p, q, r = rates
    yaw = wrap_angle(float(psi))
    return mavlink.MAVLink_attitude_message(boot_ms(state.t), phi, theta, yaw, p, q, r)


def vfr_hud(
    state: TrafficState, frame: LocalFrame, power: Power | None = None
) -> mavlink.MAVLink_vfr_hud_message:
    _, _, alt = frame.to_geodetic(*state.pos[0])
    heading_deg = round(math.degrees(state.att[0, 2])) % 360
    throttle = None if power is None else power.throttle
    return mavlink.MAVLink_vfr_hud_message(
        state.airspeed[0],
        state.ground_speed[0],
        heading_deg,
        0 if throttle is None else max(0, min(100, round(100 * throttle))),
        float(alt),
        state.vel[0, 2],
    )


def home_position(
    frame: LocalFrame, home: tuple[float, float, float], t: float
) -> mavlink.MAVLink_home_position_message:
    x, y, h = home
    lat, lon, alt = frame.to_geodetic(x, y, h)
    return mavlink.MAVLink_home_position_message(
        _deg_e7(lat),
        _deg_e7(lon),
        round(float(alt) * 1000.0),
        y,  # local NED: north
        x,  # east
        -h,  # down
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        int(t * 1e6),
    )


def autopilot_version() -> mavlink.MAVLink_autopilot_version_message:
    return mavlink.MAVLink_autopilot_version_message(
        CAPABILITIES, 0, 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 0
    )


def adsb_vehicles(
    state: TrafficState, frame: LocalFrame, emitter_type: int = mavlink.ADSB_EMITTER_TYPE_UAV
) -> list:
    """One ADSB_VEHICLE per intruder (rows 1..N), of the intruders' ``emitter_type`` (their
    aircraft's category, uavxai.surveillance.emitters); a fleet's other members
    (``ownship-i``) are systems of their own on the link, not traffic."""
    if state.n < 2:
        return []
    pos, vel = state.pos[1:], state.vel[1:]
    lat, lon, alt = frame.to_geodetic(pos[:, 0], pos[:, 1], pos[:, 2])
    speed = state.ground_speed[1:]
    course = np.where(
        speed >= _MIN_COURSE_SPEED_MPS, np.arctan2(vel[:, 0], vel[:, 1]), state.att[1:, 2]
    )
    messages = []
    for k, ident in enumerate(state.ids[1:]):
        if is_member(ident):
            continue
        number = intruder_number(ident, k + 1)
        messages.append(
            mavlink.MAVLink_adsb_vehicle_message(
                ICAO_BLOCK + number,
                _deg_e7(lat[k]),
                _deg_e7(lon[k]),
                mavlink.ADSB_ALTITUDE_TYPE_GEOMETRIC,
                round(float(alt[k]) * 1000.0),
                _cdeg(course[k]),
                min(round(float(speed[k]) * 100.0), 0xFFFF),
                _int16(vel[k, 2] * 100.0),
                callsign(number).encode("ascii"),
                emitter_type,
                0,
                ADSB_FLAGS,
                0,
            )
        )
    return messages


def intruder_number(ident: str, fallback: int) -> int:
    """N of "intruder-N" (the public id), else the row number."""
    tail = ident.rsplit("-", 1)[-1]
    return int(tail) if tail.isdigit() else fallback


def callsign(number: int) -> str:
    return f"INTR{number:02d}"[:8]


def body_rates(att_before: np.ndarray, att_now: np.ndarray, dt: float) -> np.ndarray:
    """Body rates p, q, r (rad/s) from two (phi, theta, psi) samples `dt` apart."""
    if dt <= 0:
        return np.zeros(3)
    d = np.asarray(att_now, dtype=float) - np.asarray(att_before, dtype=float)
    phi_dot, theta_dot, psi_dot = wrap_angle(d) / dt
    phi, theta, _ = att_now
    sp, cp, ct = math.sin(phi), math.cos(phi), math.cos(theta)
    return np.array(
        [
            phi_dot - psi_dot * math.sin(theta),
            theta_dot * cp + psi_dot * sp * ct,
            -theta_dot * sp + psi_dot * cp * ct,
        ]
    )


def _deg_e7(deg) -> int:
    return round(float(deg) * 1e7)


def _cdeg(angle_rad) -> int:
    return round(math.degrees(float(angle_rad)) * 100.0) % 36000


def _int16(value) -> int:
    return max(-32768, min(32767, round(float(value))))
