"""How a flight command is spelled in MAVLink 2, in both directions.

A planner decision (bank_cmd_rad, accel_mps2) becomes two standard messages:

* **bank** -> SET_ATTITUDE_TARGET with the quaternion of roll = bank, pitch = 0, yaw = 0 and a
  type_mask that ignores the body rates and the throttle, so only the attitude is meant. On
  receipt only the roll angle is used: pitch belongs to the altitude hold and the heading is
  whatever the bank turns the aircraft to.
* **along-track acceleration** -> SET_POSITION_TARGET_LOCAL_NED in MAV_FRAME_BODY_FRD with a
  type_mask that uses only the acceleration fields. ``afx`` (forward, m/s^2) is the along-track
  acceleration; ``afy`` and ``afz`` are sent as 0 and ignored on receipt, because a fixed wing
  makes lateral acceleration with the bank and vertical acceleration with the altitude hold.

Ground stations may also send COMMAND_LONG MAV_CMD_DO_CHANGE_SPEED (param2, m/s) for a speed
target and MAV_CMD_DO_CHANGE_ALTITUDE (param1, m, in the frame of param2) for an altitude
target. The bridge handles those itself (`uavxai.bridges.bridge`).

Everything here uses pymavlink's v20 `common` dialect directly, so it is MAVLink 2 regardless
of the MAVLINK20 environment variable.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from pymavlink.dialects.v20 import common as mavlink

# type_mask bits set = fields to ignore.
ATTITUDE_ONLY_MASK = (
    mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
    | mavlink.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE
)
ACCELERATION_ONLY_MASK = (
    mavlink.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VY_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_VZ_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_YAW_IGNORE
    | mavlink.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE
)

AUTOPILOT_COMPONENT = 1  # the ownship's autopilot, MAV_COMP_ID_AUTOPILOT1
SIGNING_KEY_BYTES = 32
# MAVLink signing timestamps count 10 us units from 2015-01-01 00:00 UTC.
_SIGNING_EPOCH_UNIX_S = 1420070400


class SetpointError(ValueError):
    """A well-formed message whose setpoint the bridge will not obey (reason in the text)."""


def new_codec(file, system_id: int, component_id: int) -> mavlink.MAVLink:
    """A MAVLink 2 codec writing to `file` (anything with ``write(bytes)``)."""
    return mavlink.MAVLink(file, srcSystem=system_id, srcComponent=component_id)


def enable_signing(
    codec: mavlink.MAVLink,
    key: bytes,
    accept_unsigned: Callable[[int], bool] | None = None,
    link_id: int = 0,
) -> None:
    """Sign every outgoing frame with `key` (and let pymavlink check incoming ones).

    Incoming frames that are unsigned or badly signed are refused unless
    ``accept_unsigned(message_id)`` says otherwise (pymavlink then counts a refusal in
    ``codec.signing.reject_count``). pymavlink records a stream's timestamp before it checks
    the signature, so a codec that decodes hostile input must not rely on this check: the
    bridge decodes with key-less codecs and `uavxai.bridges.signing.SignatureGate` instead.
    """
    if len(key) != SIGNING_KEY_BYTES:
        raise ValueError(f"a MAVLink signing key is {SIGNING_KEY_BYTES} bytes, got {len(key)}")
    policy = accept_unsigned or (lambda _msg_id: False)
    codec.signing.secret_key = bytes(key)
    codec.signing.sign_outgoing = True
    codec.signing.link_id = link_id
    codec.signing.allow_unsigned_callback = lambda _codec, msg_id: policy(msg_id)
    # Receivers reject a new stream whose timestamp lags theirs by over a minute, so start
    # from the wall clock as the standard asks; it then only moves forward.
    codec.signing.timestamp = int(max(time.time() - _SIGNING_EPOCH_UNIX_S, 0) * 100_000)


def roll_quaternion(roll_rad: float) -> list[float]:
    """[w, x, y, z] of a pure roll (pitch 0, yaw 0)."""
    return [math.cos(roll_rad / 2), math.sin(roll_rad / 2), 0.0, 0.0]


def roll_from_quaternion(q) -> float:
    """Roll angle (rad, right wing down positive) of a [w, x, y, z] attitude quaternion."""
    w, x, y, z = (float(c) for c in q)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not math.isfinite(norm) or norm < 0.5:
        raise SetpointError(f"attitude quaternion {list(q)} is not a rotation")
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))


def bank_from_attitude_target(msg: mavlink.MAVLink_set_attitude_target_message) -> float:
    """The bank command (rad) carried by a SET_ATTITUDE_TARGET."""
    if msg.type_mask & mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE:
        raise SetpointError("SET_ATTITUDE_TARGET with the attitude ignored carries no bank")
    return roll_from_quaternion(msg.q)


def accel_from_position_target(msg: mavlink.MAVLink_set_position_target_local_ned_message) -> float:
    """The along-track acceleration (m/s^2) carried by a SET_POSITION_TARGET_LOCAL_NED."""
    if msg.coordinate_frame != mavlink.MAV_FRAME_BODY_FRD:
        raise SetpointError(
            f"SET_POSITION_TARGET_LOCAL_NED in frame {msg.coordinate_frame}; only "
            f"MAV_FRAME_BODY_FRD ({mavlink.MAV_FRAME_BODY_FRD}) acceleration is flown"
        )
    if msg.type_mask & mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE:
        raise SetpointError("SET_POSITION_TARGET_LOCAL_NED with afx ignored")
    if not math.isfinite(msg.afx):
        raise SetpointError(f"acceleration afx = {msg.afx}")
    return float(msg.afx)


class MessagePacker:
    """MAVLink messages to MAVLink 2 bytes from one sender, with its sequence numbers and, given
    a 32-byte key, its signatures."""

    def __init__(self, system_id: int, component_id: int, signing_key: bytes | None = None) -> None:
        self._frames: list[bytes] = []
        self._codec = new_codec(self, system_id, component_id)
        if signing_key is not None:
            enable_signing(self._codec, signing_key)

    def pack(self, msg: mavlink.MAVLink_message) -> bytes:
        self._codec.send(msg)
        data, self._frames = b"".join(self._frames), []
        return data

    def write(self, data: bytes) -> None:
        """pymavlink's 'file' interface: the codec hands over each finished frame."""
        self._frames.append(bytes(data))


class CommandEncoder:
    """The planner's side of the command path: decisions in, MAVLink 2 bytes out.

    ``system_id``/``component_id`` identify the sender (by default an onboard computer),
    ``target_system`` the ownship. With a 32-byte ``signing_key`` every frame is signed.
    """

    def __init__(
        self,
        system_id: int,
        target_system: int,
        signing_key: bytes | None = None,
        component_id: int = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER,
        target_component: int = AUTOPILOT_COMPONENT,
    ) -> None:
        self.target_system = target_system
        self.target_component = target_component
        self._packer = MessagePacker(system_id, component_id, signing_key)

    def encode(self, bank_cmd_rad: float, accel_mps2: float, t_s: float = 0.0) -> bytes:
        """Both setpoints of one decision, as consecutive frames."""
        return self.attitude(bank_cmd_rad, t_s) + self.acceleration(accel_mps2, t_s)

    def attitude(self, bank_cmd_rad: float, t_s: float = 0.0) -> bytes:
        msg = mavlink.MAVLink_set_attitude_target_message(
            boot_ms(t_s),
            self.target_system,
            self.target_component,
            ATTITUDE_ONLY_MASK,
            roll_quaternion(bank_cmd_rad),
            0.0,
            0.0,
            0.0,
            0.0,
        )
        return self._packer.pack(msg)

    def acceleration(self, accel_mps2: float, t_s: float = 0.0) -> bytes:
        msg = mavlink.MAVLink_set_position_target_local_ned_message(
            boot_ms(t_s),
            self.target_system,
            self.target_component,
            mavlink.MAV_FRAME_BODY_FRD,
            ACCELERATION_ONLY_MASK,
            *(0.0,) * 6,  # x, y, z, vx, vy, vz: ignored
            accel_mps2,
            0.0,
            0.0,
            0.0,
            0.0,
        )
        return self._packer.pack(msg)

    def orbit(
        self, lat_e7: int, lon_e7: int, h_m: float, radius_m: float, clockwise: bool, speed: float
    ) -> bytes:
        """MAV_CMD_DO_ORBIT (loiter) as COMMAND_INT; the bridge answers COMMAND_ACK."""
        return self._packer.pack(
            orbit_command(
                self.target_system, self.target_component, lat_e7, lon_e7, h_m, radius_m,
                clockwise, speed,
            )
        )  # fmt: skip

    def change_altitude(self, h_m: float) -> bytes:
        """MAV_CMD_DO_CHANGE_ALTITUDE to a height above home (the local h)."""
        msg = mavlink.MAVLink_command_long_message(
            self.target_system,
            self.target_component,
            mavlink.MAV_CMD_DO_CHANGE_ALTITUDE,
            0,
            float(h_m),
            mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
            *(0.0,) * 5,
        )
        return self._packer.pack(msg)

    def change_speed(self, speed_mps: float) -> bytes:
        """MAV_CMD_DO_CHANGE_SPEED to an airspeed target (the bridge answers COMMAND_ACK)."""
        msg = mavlink.MAVLink_command_long_message(
            self.target_system,
            self.target_component,
            mavlink.MAV_CMD_DO_CHANGE_SPEED,
            0,
            0.0,  # speed type: airspeed
            speed_mps,
            -1.0,  # throttle: no change
            0.0,
            0.0,
            0.0,
            0.0,
        )
        return self._packer.pack(msg)


def orbit_command(
    target_system: int,
    target_component: int,
    lat_e7: int,
    lon_e7: int,
    h_m: float,
    radius_m: float,
    clockwise: bool = True,
    speed_mps: float = float("nan"),
) -> mavlink.MAVLink_command_int_message:
    """COMMAND_INT MAV_CMD_DO_ORBIT about (lat, lon) degE7 at height ``h_m`` above home, at
    ``speed_mps`` (NaN: the current airspeed target)."""
    return mavlink.MAVLink_command_int_message(
        target_system,
        target_component,
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mavlink.MAV_CMD_DO_ORBIT,
        0,
        0,
        float(radius_m if clockwise else -radius_m),
        float(speed_mps),
        0.0,  # yaw behaviour: the default (front to the circle's tangent)
        0.0,  # orbits: forever
        int(lat_e7),
        int(lon_e7),
        float(h_m),
    )


def boot_ms(t_s: float) -> int:
    """MAVLink time_boot_ms of simulated time `t_s`."""
    return int(t_s * 1000.0) & 0xFFFFFFFF
