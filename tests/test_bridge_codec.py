"""The bridge in-process: command encoding and decoding, robust framing, signing policy, the
failsafe watchdog and telemetry arithmetic. No sockets here (see test_bridge_udp.py)."""

from __future__ import annotations

import logging
import math
import random

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from uavxai.bridges import CommandEncoder, MavlinkBridge
from uavxai.bridges.framing import FrameReader
from uavxai.bridges.protocol import (
    ACCELERATION_ONLY_MASK,
    ATTITUDE_ONLY_MASK,
    MessagePacker,
    SetpointError,
    new_codec,
    roll_from_quaternion,
)
from uavxai.bridges.telemetry import RateGate, body_rates
from uavxai.dynamics.geodesy import LocalFrame

FRAME = LocalFrame(34.1230, 108.8370, 400.0)
KEY = bytes(range(32))


class RecordingSink:
    def __init__(self) -> None:
        self.calls: list[dict] = []

    def command_ownship(self, **setpoint) -> None:
        self.calls.append(setpoint)


def make_bridge(**kwargs) -> tuple[MavlinkBridge, RecordingSink]:
    sink = RecordingSink()
    return MavlinkBridge(1, FRAME, sink, **kwargs), sink


def decode_all(data: bytes) -> list:
    return FrameReader(new_codec(None, 250, 1), stream=False).push(data).messages


# ------------------------------------------------------------------ encoding
def test_decision_travels_as_two_standard_messages():
    attitude, accel = decode_all(CommandEncoder(255, 7).encode(math.radians(20), -0.8))

    assert attitude.get_type() == "SET_ATTITUDE_TARGET"
    assert (attitude.target_system, attitude.target_component) == (7, 1)
    assert attitude.type_mask == ATTITUDE_ONLY_MASK
    assert not attitude.type_mask & mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE
    assert roll_from_quaternion(attitude.q) == pytest.approx(math.radians(20), abs=1e-6)

    assert accel.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert accel.coordinate_frame == mavlink.MAV_FRAME_BODY_FRD
    assert accel.type_mask == ACCELERATION_ONLY_MASK
    assert not accel.type_mask & mavlink.POSITION_TARGET_TYPEMASK_AX_IGNORE
    assert accel.type_mask & mavlink.POSITION_TARGET_TYPEMASK_VX_IGNORE
    assert accel.afx == pytest.approx(-0.8)
    assert attitude.get_header().mlen > 0 and attitude.get_msgbuf()[0] == 0xFD  # MAVLink 2


@pytest.mark.parametrize("bank_deg", [-60.0, -30.0, -10.0, 0.0, 5.0, 30.0, 60.0])
def test_planner_bank_and_accel_reach_the_sink(bank_deg):
    bridge, sink = make_bridge()
    obeyed = bridge.feed(CommandEncoder(255, 1).encode(math.radians(bank_deg), 0.5))
    assert obeyed == 2
    assert sink.calls[0]["bank_cmd_rad"] == pytest.approx(math.radians(bank_deg), abs=1e-6)
    assert sink.calls[1] == {"accel_cmd_mps2": pytest.approx(0.5)}
    assert bridge.counters["commands"] == 2


def test_roll_is_read_from_a_full_attitude_quaternion():
    roll, pitch, yaw = 0.4, 0.15, 2.5
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    q = [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]
    assert roll_from_quaternion(q) == pytest.approx(roll, abs=1e-12)
    assert roll_from_quaternion([2 * c for c in q]) == pytest.approx(roll, abs=1e-12)
    for bad in ([0, 0, 0, 0], [math.nan, 0, 0, 0]):
        with pytest.raises(SetpointError):
            roll_from_quaternion(bad)


def _attitude_target(target_system=1, type_mask=ATTITUDE_ONLY_MASK, q=(1.0, 0.0, 0.0, 0.0)):
    return mavlink.MAVLink_set_attitude_target_message(
        0, target_system, 1, type_mask, list(q), 0, 0, 0, 0
    )


def _pack(msg) -> bytes:
    return MessagePacker(255, 190).pack(msg)


def test_unusable_or_misaddressed_setpoints_are_not_obeyed():
    bridge, sink = make_bridge()
    bridge.feed(_pack(_attitude_target(target_system=2)))
    bridge.feed(_pack(_attitude_target(q=(0.0, 0.0, 0.0, 0.0))))
    bridge.feed(_pack(_attitude_target(type_mask=mavlink.ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE)))
    ned_accel = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, mavlink.MAV_FRAME_LOCAL_NED, ACCELERATION_ONLY_MASK, *[0.0] * 6, 1.0, 0, 0, 0, 0
    )
    bridge.feed(_pack(ned_accel))
    assert sink.calls == []
    assert bridge.counters["ignored_other_target"] == 1
    assert bridge.counters["rejected_commands"] == 3


# ------------------------------------------------------------------ framing
def test_framing_recovers_good_frames_around_garbage_and_damage():
    encoder = CommandEncoder(255, 1)
    good = encoder.attitude(0.1)
    damaged = bytearray(encoder.attitude(0.2))
    damaged[12] ^= 0x10  # payload bit: CRC fails
    truncated = encoder.acceleration(0.3)[:-5]
    data = b"\x00garbage\xfd" + good + bytes(damaged) + encoder.acceleration(0.4) + truncated

    parsed = FrameReader(new_codec(None, 1, 1), stream=False).push(data)

    kinds = [(m.get_type(), round(getattr(m, "afx", 0.0), 6)) for m in parsed.messages]
    assert kinds == [("SET_ATTITUDE_TARGET", 0.0), ("SET_POSITION_TARGET_LOCAL_NED", 0.4)]
    assert parsed.malformed == 3  # the leading garbage, the damaged frame, the truncated tail


def test_stream_framing_reassembles_frames_split_anywhere():
    data = CommandEncoder(255, 1).encode(0.25, 1.5) * 3
    for cut in range(1, len(data)):
        reader = FrameReader(new_codec(None, 1, 1), stream=True)
        first, second = reader.push(data[:cut]), reader.push(data[cut:])
        assert len(first.messages) + len(second.messages) == 6
        assert first.malformed == second.malformed == 0


def test_mutated_and_random_datagrams_are_counted_never_obeyed():
    rng = random.Random(5)
    encoder = CommandEncoder(255, 1)
    bridge, sink = make_bridge()
    valid = [encoder.attitude(0.7), encoder.acceleration(2.0), encoder.change_speed(25.0)]
    for i in range(500):
        frame = bytearray(rng.choice(valid))
        if i % 3 == 0:
            packet = bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 300)))
        elif i % 3 == 1:
            packet = bytes(frame[: rng.randint(1, len(frame) - 1)])
        else:
            for _ in range(rng.randint(1, 3)):
                frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)
            packet = bytes(frame)
        before = bridge.counters["malformed"] + bridge.counters["unknown_messages"]
        assert bridge.feed(packet) == 0
        assert bridge.counters["malformed"] + bridge.counters["unknown_messages"] > before
    assert sink.calls == []
    assert bridge.counters["commands"] == 0
    assert bridge.feed(encoder.attitude(0.7)) == 1  # still listening


# ------------------------------------------------------------------ signing
def test_signed_commands_obeyed_unsigned_and_wrongly_signed_refused():
    bridge, sink = make_bridge(signing_key=KEY)
    assert bridge.feed(CommandEncoder(255, 1).encode(0.3, 0.0)) == 0
    assert bridge.feed(CommandEncoder(254, 1, signing_key=bytes(32)).encode(0.3, 0.0)) == 0
    assert sink.calls == []
    assert bridge.counters["refused_unsigned"] == 2
    assert bridge.counters["refused_bad_signature"] == 2

    assert bridge.feed(CommandEncoder(253, 1, signing_key=KEY).encode(0.3, 0.0)) == 2
    assert sink.calls[0]["bank_cmd_rad"] == pytest.approx(0.3, abs=1e-6)


def test_a_replayed_signed_command_is_refused():
    bridge, sink = make_bridge(signing_key=KEY)
    frame = CommandEncoder(253, 1, signing_key=KEY).attitude(0.3)
    assert bridge.feed(frame) == 1
    assert bridge.feed(frame) == 0
    assert bridge.counters["refused_replay"] == 1  # a replay, not a forgery
    assert bridge.counters["refused_bad_signature"] == 0
    assert len(sink.calls) == 1


def test_unsigned_heartbeat_accepted_but_not_a_command():
    bridge, sink = make_bridge(signing_key=KEY)
    heartbeat = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3)
    bridge.feed(_pack(heartbeat))
    assert bridge.counters["messages_in"] == 1
    assert bridge.counters["refused_unsigned"] == 0
    bridge.feed(_pack(mavlink.MAVLink_param_set_message(1, 1, b"BRG_SYSID", 9.0, 9)))
    assert bridge.counters["refused_unsigned"] == 1
    assert sink.calls == []


# ------------------------------------------------------------------ failsafe
def test_command_silence_triggers_the_failsafe_once_and_commands_end_it(caplog):
    bridge, sink = make_bridge(command_timeout_s=3.0)
    encoder = CommandEncoder(255, 1)
    caplog.set_level(logging.INFO, logger="uavxai.bridges")
    bridge.tick(0.0)
    bridge.feed(encoder.encode(0.4, 1.0))
    for k in range(1, 31):  # up to exactly 3.0 s of silence: not yet
        bridge.tick(k / 10)
    assert not bridge.failsafe_active and len(sink.calls) == 2

    for k in range(31, 101):
        bridge.tick(k / 10)
    assert bridge.failsafe_active
    assert sink.calls[2:] == [{"bank_cmd_rad": 0.0, "accel_cmd_mps2": 0.0}]
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert [r.getMessage() for r in warnings] == [
        "no command for 3.0 s: wings level, holding speed and altitude"
    ]
    assert bridge.counters["failsafe_events"] == 1

    bridge.feed(encoder.attitude(0.2))
    assert not bridge.failsafe_active
    assert any("resumed" in r.getMessage() for r in caplog.records)
    for k in range(101, 150):
        bridge.tick(k / 10)
    assert bridge.counters["failsafe_events"] == 2


def test_refused_commands_do_not_hold_off_the_failsafe():
    bridge, sink = make_bridge(signing_key=KEY, command_timeout_s=1.0)
    unsigned = CommandEncoder(255, 1)
    for k in range(25):
        bridge.tick(k / 10)
        bridge.feed(unsigned.attitude(0.5))
    assert bridge.failsafe_active
    assert sink.calls == [{"bank_cmd_rad": 0.0, "accel_cmd_mps2": 0.0}]


# ------------------------------------------------------------------ telemetry arithmetic
def test_rate_gate_holds_its_rate_whatever_the_call_rate():
    for call_hz in (10, 30, 120, 1000):
        gate = RateGate(4.0)
        opened = sum(gate.due(k / call_hz) for k in range(10 * call_hz))
        assert opened == 40, call_hz


def test_body_rates_of_a_coordinated_turn():
    # Level turn at bank phi: body rates are q = psi_dot sin(phi), r = psi_dot cos(phi).
    phi, psi_dot, dt = 0.5, 0.2, 0.1
    p, q, r = body_rates(np.array([phi, 0.0, 3.1]), np.array([phi, 0.0, 3.1 + psi_dot * dt]), dt)
    assert p == pytest.approx(0.0, abs=1e-12)
    assert q == pytest.approx(psi_dot * math.sin(phi))
    assert r == pytest.approx(psi_dot * math.cos(phi))
    wrapped = body_rates(np.array([0, 0, math.pi - 0.01]), np.array([0, 0, -math.pi + 0.01]), dt)
    assert wrapped[2] == pytest.approx(0.2)


def test_bridge_parameters_must_be_valid_names():
    with pytest.raises(ValueError):
        make_bridge(params={"A_NAME_LONGER_THAN_16": 1.0})
    with pytest.raises(ValueError):
        make_bridge(params={"BRG_SYSID": 3.0})


def test_time_running_backwards_starts_a_new_episode():
    bridge, sink = make_bridge(command_timeout_s=3.0)
    for k in range(50):
        bridge.tick(k / 10)
    assert bridge.failsafe_active
    bridge.tick(0.0)
    assert not bridge.failsafe_active
    for k in range(1, 31):
        bridge.tick(k / 10)
    assert bridge.counters["failsafe_events"] == 1
    bridge.tick(3.1)
    assert bridge.counters["failsafe_events"] == 2
    assert len(sink.calls) == 2


def _command(command: int, *params: float):
    params = (list(params) + [0.0] * 7)[:7]
    return mavlink.MAVLink_command_long_message(1, 1, command, 0, *params)


def test_altitude_commands_in_msl_or_relative_frames():
    bridge, sink = make_bridge()
    change = mavlink.MAV_CMD_DO_CHANGE_ALTITUDE
    bridge.feed(_pack(_command(change, 530.0, mavlink.MAV_FRAME_GLOBAL)))
    bridge.feed(_pack(_command(change, 150.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)))
    bridge.feed(_pack(_command(change, 150.0, mavlink.MAV_FRAME_LOCAL_NED)))
    assert sink.calls == [
        {"alt_target_m": pytest.approx(130.0)},
        {"alt_target_m": pytest.approx(150.0)},
    ]
    assert bridge.counters["rejected_commands"] == 1


def test_only_known_requests_are_answered_and_nothing_is_flown():
    bridge, sink = make_bridge()
    # Command 242 is not a request, even though 242 is HOME_POSITION's message id.
    for command in (mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, 242, 31000):
        bridge.feed(_pack(_command(command, mavlink.MAVLINK_MSG_ID_HOME_POSITION)))
    assert sink.calls == []
    assert bridge.counters["ignored_messages"] == 2
