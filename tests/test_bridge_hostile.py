"""The bridge against hostile peers (issue 14): forged signed frames that try to poison the
signing state, commands outside the world and the aircraft's limits (a ground station's aims
and the planner's setpoints alike), a fuzzed decoder, and signed frames replayed from an
earlier run. Real pymavlink bytes; sockets on 127.0.0.1 only."""

from __future__ import annotations

import math
import socket
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from uavxai.bridges import CommandEncoder, MavlinkBridge
from uavxai.bridges.operator import SETPOINT_REFUSAL, Kind
from uavxai.bridges.protocol import new_codec
from uavxai.dynamics.geodesy import LocalFrame

FRAME = LocalFrame(34.1230, 108.8370, 400.0)
KEY = bytes.fromhex("c3" * 32)
VEHICLE = 1
PLANNER_COMPONENT = mavlink.MAV_COMP_ID_ONBOARD_COMPUTER
GCS_SYSTEM, GCS_COMPONENT = 255, 190
NEAR_END_OF_TIME = 2**48 - 1000  # signing timestamps are 48 bits


class RecordingSink:
    def __init__(self) -> None:
        self.calls: list[dict] = []
        self.orbits: list[tuple] = []

    def command_ownship(self, **setpoint) -> None:
        self.calls.append(setpoint)

    def command_orbit(self, x: float, y: float, radius_m: float, clockwise: bool = True) -> None:
        self.orbits.append((x, y, radius_m, clockwise))


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Sender:
    """Packs messages as one MAVLink 2 sender (system, component, link id, signing key and
    signing timestamp all chosen by the caller, as an attacker would)."""

    def __init__(
        self,
        system: int,
        component: int,
        key: bytes | None = None,
        link_id: int = 0,
        timestamp: int | None = None,
    ) -> None:
        self.frames: list[bytes] = []
        self.codec = new_codec(self, system, component)
        if key is not None:
            self.codec.signing.secret_key = key
            self.codec.signing.sign_outgoing = True
            self.codec.signing.link_id = link_id
            self.codec.signing.timestamp = (
                timestamp if timestamp is not None else _wall_clock_timestamp()
            )

    def write(self, data: bytes) -> None:
        self.frames.append(bytes(data))

    def pack(self, msg) -> bytes:
        self.codec.send(msg)
        return self.frames.pop()


def _wall_clock_timestamp() -> int:
    return int((time.time() - 1420070400) * 100_000)


def heartbeat():
    return mavlink.MAVLink_heartbeat_message(
        mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3
    )


def forged_heartbeat(system: int, component: int, link_id: int = 0) -> bytes:
    """A HEARTBEAT on someone else's stream, signed with a random key and dated near the end
    of time: 34 bytes on the wire."""
    key = np.random.default_rng(14).bytes(32)
    frame = Sender(system, component, key, link_id, NEAR_END_OF_TIME).pack(heartbeat())
    assert len(frame) == 34
    return frame


def send_datagram(port: int, data: bytes) -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(data, ("127.0.0.1", port))


def poll_until(bridge: MavlinkBridge, done, timeout_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        bridge.poll()
        assert time.monotonic() < deadline, "the bridge never received it"
        time.sleep(0.002)


def frames_seen(bridge: MavlinkBridge) -> int:
    c = bridge.counters
    return (
        c["messages_in"]
        + c["refused_unsigned"]
        + c["refused_bad_signature"]
        + c["refused_replay"]
        + c["refused_unknown_peer"]
    )


def listening_bridge(**kwargs) -> tuple[MavlinkBridge, RecordingSink, int]:
    port = free_port()
    sink = RecordingSink()
    kwargs.setdefault("ground_stations", [(GCS_SYSTEM, "127.0.0.1")])  # the tests' station
    bridge = MavlinkBridge(VEHICLE, FRAME, sink, link=f"udpin:127.0.0.1:{port}", **kwargs)
    return bridge, sink, port


# ------------------------------------------------------------------ forged-frame signing attack
@pytest.mark.parametrize("planner_spoke_first", [False, True])
def test_forged_frame_on_the_planners_stream_cannot_silence_the_planner(planner_spoke_first):
    """Issue 14, worst first: before the fix the forged frame's timestamp was recorded before
    its signature was checked, every later planner command was 'old' and refused, and the
    failsafe flew the aircraft."""
    bridge, sink, port = listening_bridge(signing_key=KEY, command_timeout_s=1.0)
    planner = CommandEncoder(VEHICLE, VEHICLE, signing_key=KEY)
    bridge.tick(0.0)
    if planner_spoke_first:
        assert bridge.feed(planner.encode(0.1, 0.0, 0.0)) == 2
    seen = frames_seen(bridge)

    send_datagram(port, forged_heartbeat(VEHICLE, PLANNER_COMPONENT))
    poll_until(bridge, lambda: frames_seen(bridge) > seen)
    assert bridge.counters["refused_bad_signature"] == 1
    assert bridge.counters["ignored_messages"] == 0  # refused, not "ignored"
    assert bridge.counters["messages_in"] == seen

    for k in range(1, 51):  # five simulated seconds of planner decisions at 10 Hz
        t = k / 10
        bridge.tick(t)
        assert bridge.feed(planner.encode(0.2, 0.0, t)) == 2, f"planner refused at {t} s"
    assert not bridge.failsafe_active
    assert bridge.counters["failsafe_events"] == 0
    assert bridge.counters["refused_bad_signature"] == 1
    bridge.close()


def change_altitude(h: float, frame: int = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT):
    return mavlink.MAVLink_command_long_message(
        VEHICLE, 1, mavlink.MAV_CMD_DO_CHANGE_ALTITUDE, 0, h, frame, 0, 0, 0, 0, 0
    )


def test_forged_frame_cannot_poison_a_ground_stations_stream_either():
    """Verify before recording: a keyed ground station whose stream an attacker dated near the
    end of time is still heard: its aim is taken, its setpoint refused as a setpoint (not as
    a replay)."""
    bridge, sink, port = listening_bridge(signing_key=KEY)
    send_datagram(port, forged_heartbeat(GCS_SYSTEM, GCS_COMPONENT))
    poll_until(bridge, lambda: frames_seen(bridge) >= 1)
    assert bridge.counters["refused_bad_signature"] == 1

    gcs = Sender(GCS_SYSTEM, GCS_COMPONENT, KEY)
    send_datagram(port, gcs.pack(change_altitude(150.0)))
    poll_until(bridge, lambda: frames_seen(bridge) >= 2)
    assert bridge.counters["refused_replay"] == 0
    assert bridge.counters["operator_commands"] == 1
    [aim] = bridge.take_operator_commands()
    assert (aim.kind, aim.h, aim.source) == (Kind.ALTITUDE, 150.0, GCS_SYSTEM)

    bank = mavlink.MAVLink_set_attitude_target_message(
        0, VEHICLE, 1, 0b0100_0111, [math.cos(0.15), math.sin(0.15), 0.0, 0.0], 0, 0, 0, 0
    )
    send_datagram(port, gcs.pack(bank))
    poll_until(bridge, lambda: frames_seen(bridge) >= 3)
    assert bridge.counters["refused_replay"] == 0
    assert bridge.counters["messages_in"] == 2
    assert bridge.counters["operator_refused"] == 1
    assert sink.calls == [] and bridge.counters["commands"] == 0
    bridge.close()


def test_every_kind_of_bad_signature_is_a_refusal_even_on_messages_accepted_unsigned():
    bridge = MavlinkBridge(VEHICLE, FRAME, RecordingSink(), signing_key=KEY)
    # unsigned HEARTBEAT: accepted (changes nothing; lets a keyless station see the vehicle)
    bridge.feed(Sender(GCS_SYSTEM, GCS_COMPONENT).pack(heartbeat()))
    assert bridge.counters["messages_in"] == 1
    # the same, wrongly signed: a forgery, refused and counted as such
    bridge.feed(forged_heartbeat(GCS_SYSTEM, GCS_COMPONENT))
    assert bridge.counters["refused_bad_signature"] == 1
    # rightly signed, then replayed: the replay is refused, and counted as a replay
    signed = Sender(GCS_SYSTEM, GCS_COMPONENT, KEY).pack(heartbeat())
    bridge.feed(signed)
    bridge.feed(signed)
    assert bridge.counters["messages_in"] == 2
    assert bridge.counters["refused_bad_signature"] == 1
    assert bridge.counters["refused_replay"] == 1
    # a new stream dated more than a minute behind the bridge's clock: an old capture, refused
    stale = Sender(42, 1, KEY, timestamp=_wall_clock_timestamp() - 61 * 100_000)
    bridge.feed(stale.pack(heartbeat()))
    assert bridge.counters["refused_replay"] == 2
    assert bridge.counters["refused_bad_signature"] == 1
    assert bridge.counters["ignored_messages"] == 2  # the two genuine heartbeats only


def test_link_traffic_never_touches_the_planners_signing_state():
    """The in-process command path keeps its own stream table: even a rightly signed frame
    from the link dated in the future on the planner's stream leaves the planner obeyed."""
    bridge, sink, port = listening_bridge(signing_key=KEY)
    future = Sender(VEHICLE, PLANNER_COMPONENT, KEY, timestamp=NEAR_END_OF_TIME)
    send_datagram(port, future.pack(heartbeat()))
    poll_until(bridge, lambda: frames_seen(bridge) >= 1)
    assert bridge.counters["messages_in"] == 1
    planner = CommandEncoder(VEHICLE, VEHICLE, signing_key=KEY)
    assert bridge.feed(planner.encode(0.2, 0.0, 0.0)) == 2
    bridge.close()


# ------------------------------------------------------------------ unsafe commands are clamped
LIMITS = dict(
    alt_limits_m=(60.0, 250.0),
    speed_limits_mps=(12.0, 30.0),
    bank_limit_rad=math.radians(35.0),
    accel_limit_mps2=2.0,
    xy_limits_m=((0.0, 1500.0), (0.0, 1000.0)),
)


def ground_station(port: int):
    from pymavlink import mavutil

    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=GCS_SYSTEM, source_component=GCS_COMPONENT
    )
    gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    return gcs


def replies(gcs, until: str, timeout_s: float = 2.0) -> list:
    """What the ground station receives up to and including the first `until` message."""
    got, deadline = [], time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        msg = gcs.recv_match(blocking=True, timeout=0.05)
        if msg is not None:
            got.append(msg)
            if msg.get_type() == until:
                return got
    raise AssertionError(f"no {until} within {timeout_s} s; got {[m.get_type() for m in got]}")


def command_and_replies(bridge: MavlinkBridge, gcs, send) -> list:
    before = bridge.counters["messages_in"]
    send()
    poll_until(bridge, lambda: bridge.counters["messages_in"] > before)
    return replies(gcs, "COMMAND_ACK")


def operator_says(bridge: MavlinkBridge, gcs, msg) -> list:
    """``msg`` from the ground station: what it hears back, up to the COMMAND_ACK."""
    return command_and_replies(bridge, gcs, lambda: gcs.mav.send(msg))


def planner_says(bridge: MavlinkBridge, gcs, msg) -> list:
    """``msg`` fed by the onboard planner, flown at once: what the ground station hears."""
    assert bridge.feed(Sender(VEHICLE, PLANNER_COMPONENT).pack(msg)) == 1
    return receive_all(gcs)


def statustexts(messages: list) -> list[str]:
    return [m.text for m in messages if m.get_type() == "STATUSTEXT"]


def acks(messages: list) -> list:
    return [m for m in messages if m.get_type() == "COMMAND_ACK"]


@pytest.fixture
def limited():
    """A bridge with the limits above, and a ground station it has heard from."""
    from uavxai.bridges.bridge import ACK_CLAMPED

    bridge, sink, port = listening_bridge(**LIMITS)
    gcs = ground_station(port)
    poll_until(bridge, lambda: bridge.counters["messages_in"] >= 1)
    yield bridge, sink, gcs, ACK_CLAMPED
    bridge.close()
    gcs.close()


ALTITUDES = pytest.mark.parametrize(
    ("param1", "frame", "flown"),
    [
        (-1000.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 60.0),  # issue 14: into the ground
        (-1000.0, mavlink.MAV_FRAME_GLOBAL, 60.0),  # MSL, below the origin
        (5000.0, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 250.0),
        (1e30, mavlink.MAV_FRAME_GLOBAL, 250.0),
    ],
)


def altitude_notice(param1: float, frame: int, flown: float) -> str:
    h = param1 - FRAME.alt0 if frame == mavlink.MAV_FRAME_GLOBAL else param1  # local h
    return f"clamped: h {h:.4g} -> {flown:.0f} m"


@ALTITUDES
def test_an_operators_altitude_outside_the_world_is_clamped_and_the_ack_says_so(
    limited, param1, frame, flown
):
    bridge, sink, gcs, clamped = limited
    got = operator_says(bridge, gcs, change_altitude(param1, frame))
    ack = got[-1]
    assert (ack.command, ack.result, ack.result_param2) == (
        mavlink.MAV_CMD_DO_CHANGE_ALTITUDE,
        mavlink.MAV_RESULT_ACCEPTED,
        clamped,
    )
    [aim] = bridge.take_operator_commands()
    assert (aim.kind, aim.h) == (Kind.ALTITUDE, flown)  # the aim, held to the world
    assert sink.calls == []  # an aim for the planner, not a setpoint
    assert statustexts(got) == [altitude_notice(param1, frame, flown)]
    assert bridge.counters["clamped_commands"] == bridge.counters["operator_commands"] == 1


@ALTITUDES
def test_the_planners_altitude_outside_the_world_is_flown_at_the_limit(
    limited, param1, frame, flown
):
    bridge, sink, gcs, _ = limited
    got = planner_says(bridge, gcs, change_altitude(param1, frame))
    assert sink.calls == [{"alt_target_m": flown}]
    assert statustexts(got) == [altitude_notice(param1, frame, flown)]
    assert acks(got) == []  # the planner's commands are not acknowledged on the ground link
    assert bridge.take_operator_commands() == []
    assert bridge.counters["clamped_commands"] == 1


def test_commands_inside_the_limits_are_taken_as_given_without_a_clamp_notice(limited):
    bridge, sink, gcs, _ = limited
    got = operator_says(bridge, gcs, change_altitude(180.0))
    assert (got[-1].result, got[-1].result_param2) == (mavlink.MAV_RESULT_ACCEPTED, 0)
    assert statustexts(got) == []
    speed = mavlink.MAV_CMD_DO_CHANGE_SPEED
    got = command_and_replies(
        bridge, gcs, lambda: gcs.mav.command_long_send(1, 1, speed, 0, 0, 22.0, -1, 0, 0, 0, 0)
    )
    assert (got[-1].result, got[-1].result_param2) == (mavlink.MAV_RESULT_ACCEPTED, 0)
    assert statustexts(got) == []
    aims = bridge.take_operator_commands()
    assert [(a.kind, a.h, a.speed_mps) for a in aims] == [
        (Kind.ALTITUDE, 180.0, None),
        (Kind.SPEED, None, 22.0),
    ]
    assert sink.calls == []
    assert bridge.counters["clamped_commands"] == 0


def change_speed(v: float):
    return mavlink.MAVLink_command_long_message(
        VEHICLE, 1, mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 0, v, -1, 0, 0, 0, 0
    )


@pytest.mark.parametrize("via", ["operator", "planner"])
@pytest.mark.parametrize(("asked", "flown"), [(200.0, 30.0), (0.5, 12.0)])
def test_speed_outside_the_aircrafts_range_is_clamped(limited, asked, flown, via):
    bridge, sink, gcs, clamped = limited
    if via == "operator":
        got = operator_says(bridge, gcs, change_speed(asked))
        assert (got[-1].result, got[-1].result_param2) == (mavlink.MAV_RESULT_ACCEPTED, clamped)
        [aim] = bridge.take_operator_commands()
        assert (aim.kind, aim.speed_mps) == (Kind.SPEED, flown)
        assert sink.calls == []
    else:
        got = planner_says(bridge, gcs, change_speed(asked))
        assert acks(got) == [] and bridge.take_operator_commands() == []
        # the airspeed flown, and the autopilot's ceiling (an operator's speed: issue 28)
        assert sink.calls == [{"speed_target_mps": flown, "speed_max_mps": flown}]
    assert statustexts(got) == [f"clamped: speed {asked:.4g} -> {flown:.0f} m/s"]
    assert bridge.counters["clamped_commands"] == 1


def far_orbit():
    """DO_ORBIT about a point outside the world, of radius 10,000 km, at -20 m, at 500 m/s."""
    lat, lon, _ = FRAME.to_geodetic(5000.0, -300.0, 0.0)
    return mavlink.MAVLink_command_int_message(
        VEHICLE, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_CMD_DO_ORBIT, 0, 0,
        1e7, 500.0, 0, 0, round(lat * 1e7), round(lon * 1e7), -20.0,
    )  # fmt: skip


FAR_ORBIT_NOTICES = [
    "clamped: point (5000, -300) -> (1500, 0)",
    "clamped: h -20 -> 60 m",
    "clamped: radius 1e+07 -> 750 m",
    "clamped: speed 500 -> 30 m/s",
]


def test_an_operators_orbit_outside_the_world_is_pulled_in(limited):
    bridge, sink, gcs, clamped = limited
    got = operator_says(bridge, gcs, far_orbit())
    assert (got[-1].result, got[-1].result_param2) == (mavlink.MAV_RESULT_ACCEPTED, clamped)
    [aim] = bridge.take_operator_commands()
    assert aim.kind == Kind.ORBIT
    assert (aim.x, aim.y, aim.radius_m, aim.clockwise) == (1500.0, 0.0, 750.0, True)
    assert (aim.h, aim.speed_mps) == (60.0, 30.0)
    assert sink.calls == [] and sink.orbits == []
    assert statustexts(got) == FAR_ORBIT_NOTICES
    assert bridge.counters["clamped_commands"] == 1


def test_the_planners_orbit_outside_the_world_is_pulled_in(limited):
    bridge, sink, gcs, _ = limited
    got = planner_says(bridge, gcs, far_orbit())
    assert sink.calls == [{"alt_target_m": 60.0, "speed_target_mps": 30.0}]
    [(x, y, radius, clockwise)] = sink.orbits
    assert (x, y) == (1500.0, 0.0)
    assert radius == 750.0 and clockwise
    assert statustexts(got) == FAR_ORBIT_NOTICES
    assert acks(got) == [] and bridge.take_operator_commands() == []


def test_an_orbit_at_nan_height_or_off_the_globe_is_denied(limited):
    bridge, sink, gcs, _ = limited
    for lat_e7, z in ((341230000, math.nan), (2_000_000_000, 100.0)):
        got = command_and_replies(
            bridge,
            gcs,
            lambda lat_e7=lat_e7, z=z: gcs.mav.command_int_send(
                1, 1, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_CMD_DO_ORBIT, 0, 0,
                100.0, 20.0, 0, 0, lat_e7, 1088370000, z,
            ),
        )  # fmt: skip
        assert got[-1].result == mavlink.MAV_RESULT_DENIED
    assert sink.calls == [] and sink.orbits == []
    assert bridge.take_operator_commands() == []
    assert bridge.counters["operator_refused"] == 2


def test_the_planners_setpoints_beyond_bank_and_acceleration_limits_are_clamped_and_announced(
    limited,
):
    bridge, sink, gcs, _ = limited
    planner = CommandEncoder(VEHICLE, VEHICLE)
    for k in range(20):  # 2 s of 10 Hz setpoints at 80 deg of bank and 1000 m/s^2
        bridge.tick(k / 10)
        assert bridge.feed(planner.encode(math.radians(-80), 1000.0, k / 10)) == 2
    banks = [c["bank_cmd_rad"] for c in sink.calls if "bank_cmd_rad" in c]
    accels = [c["accel_cmd_mps2"] for c in sink.calls if "accel_cmd_mps2" in c]
    assert banks == [pytest.approx(math.radians(-35.0))] * 20
    assert accels == [2.0] * 20
    assert bridge.counters["clamped_commands"] == 40
    texts = [m.text for m in receive_all(gcs) if m.get_type() == "STATUSTEXT"]
    assert texts == ["bank -80 deg clamped to -35", "accel 1e+03 m/s2 clamped to 2"]


def ground_setpoints(bridge: MavlinkBridge, gcs, seconds: float = 2.0) -> None:
    """A ground station's setpoints at 10 Hz for ``seconds`` of simulated time, at 80 deg of
    bank and 1000 m/s^2, each pair read by the bridge before the next."""
    from uavxai.bridges.protocol import ATTITUDE_ONLY_MASK, roll_quaternion

    for k in range(round(seconds * 10)):
        bridge.tick(k / 10)
        gcs.mav.set_attitude_target_send(
            0, 1, 1, ATTITUDE_ONLY_MASK, roll_quaternion(math.radians(-80)), 0, 0, 0, 0
        )
        gcs.mav.set_position_target_local_ned_send(
            0, 1, 1, mavlink.MAV_FRAME_BODY_FRD, 0b110_000_111_111_111 & ~(1 << 6),
            0, 0, 0, 0, 0, 0, 1000.0, 0, 0, 0, 0,
        )  # fmt: skip
        poll_until(bridge, lambda k=k: bridge.counters["operator_refused"] >= 2 * (k + 1))


def test_a_ground_stations_setpoints_are_refused_and_explained(limited):
    bridge, sink, gcs, _ = limited
    ground_setpoints(bridge, gcs)
    assert bridge.counters["operator_refused"] == 40
    assert sink.calls == [] and bridge.counters["commands"] == 0
    assert bridge.take_operator_commands() == []
    texts = statustexts(receive_all(gcs))
    assert texts and set(texts) == {SETPOINT_REFUSAL}  # what one STATUSTEXT carries
    assert bridge.counters["clamped_commands"] == 0  # refused is not flown at a limit


def test_a_ground_stations_setpoints_are_explained_once_every_few_seconds(limited):
    """At 10 Hz for 2 s, one notice (one per CLAMP_NOTICE_PERIOD_S), not one per setpoint."""
    bridge, _, gcs, _ = limited
    ground_setpoints(bridge, gcs)
    assert statustexts(receive_all(gcs)) == [SETPOINT_REFUSAL]


def receive_all(conn, quiet_s: float = 0.1) -> list:
    messages, last = [], time.monotonic()
    while time.monotonic() - last < quiet_s:
        msg = conn.recv_msg()
        if msg is None:
            time.sleep(0.002)
            continue
        messages.append(msg)
        last = time.monotonic()
    return messages


def test_ground_stations_can_read_the_limits_as_parameters(limited):
    bridge, _, gcs, _ = limited
    gcs.mav.param_request_list_send(1, 1)
    poll_until(bridge, lambda: bridge.counters["param_requests"] == 1)
    table = {m.param_id: m.param_value for m in receive_all(gcs) if m.get_type() == "PARAM_VALUE"}
    assert (table["BRG_ALT_MIN"], table["BRG_ALT_MAX"]) == (60.0, 250.0)
    assert (table["BRG_SPD_MIN"], table["BRG_SPD_MAX"]) == (12.0, 30.0)
    assert table["BRG_BANK_LIM"] == pytest.approx(35.0)
    assert table["BRG_ACCEL_LIM"] == 2.0


def test_commands_exactly_at_the_limits_are_not_reported_as_clamped():
    """float32 on the wire: a planner command at the limit must not read as a clamp."""
    bridge = MavlinkBridge(VEHICLE, FRAME, RecordingSink(), **{**LIMITS, "accel_limit_mps2": 0.3})
    sink = bridge._sink
    planner = CommandEncoder(VEHICLE, VEHICLE)
    for k, bank_deg in enumerate((35.0, -35.0, 34.9999999)):
        assert bridge.feed(planner.encode(math.radians(bank_deg), 0.3 * (-1) ** k, k)) == 2
    assert bridge.feed(planner.change_altitude(250.0)) == 1
    assert bridge.feed(planner.change_speed(12.0)) == 1
    lat, lon, _ = FRAME.to_geodetic(1500.0, 1000.0, 0.0)  # the world's corner
    orbit = planner.orbit(round(lat * 1e7), round(lon * 1e7), 250.0, 750.0, True, 30.0)
    assert bridge.feed(orbit) == 1
    assert bridge.counters["clamped_commands"] == 0
    sink.calls.pop()
    for call in sink.calls:
        assert abs(call.get("bank_cmd_rad", 0.0)) <= math.radians(35.0)
        assert abs(call.get("accel_cmd_mps2", 0.0)) <= 0.3
    assert sink.calls[-2:] == [{"alt_target_m": 250.0},
                               {"speed_target_mps": 12.0, "speed_max_mps": 12.0}]  # fmt: skip


def test_limits_must_be_sane():
    for bad in (
        {"alt_limits_m": (-10.0, 100.0)},  # below the ground
        {"alt_limits_m": (300.0, 100.0)},
        {"speed_limits_mps": (0.0, math.inf)},
        {"bank_limit_rad": math.pi},
        {"accel_limit_mps2": 0.0},
    ):
        with pytest.raises(ValueError):
            MavlinkBridge(VEHICLE, FRAME, RecordingSink(), **bad)


# ------------------------------------------------------------------ the simulation's clock
@pytest.mark.parametrize("t", [0.0, 12.345, 4000.0])
def test_planner_commands_carry_simulated_time_boot_ms(t):
    from uavxai.bridges.framing import FrameReader

    encoder = CommandEncoder(VEHICLE, VEHICLE)
    decoded = FrameReader(new_codec(None, 250, 1), stream=False).push(encoder.encode(0.1, 0.5, t))
    attitude, accel = decoded.messages
    assert attitude.time_boot_ms == accel.time_boot_ms == round(t * 1000)
    # the old two-argument call still works (time 0)
    old = FrameReader(new_codec(None, 250, 1), stream=False).push(encoder.encode(0.1, 0.5))
    assert [m.time_boot_ms for m in old.messages] == [0, 0]


# ------------------------------------------------------------------ replay from an earlier run
def signed_altitude_commands(count: int) -> list[bytes]:
    """A keyed ground station's DO_CHANGE_ALTITUDE to 100, 101, ... m."""
    gcs = Sender(GCS_SYSTEM, GCS_COMPONENT, KEY)
    return [gcs.pack(change_altitude(100.0 + k)) for k in range(count)]


def signed_bank_frames(count: int) -> list[bytes]:
    gcs = Sender(GCS_SYSTEM, GCS_COMPONENT, KEY)
    q = [math.cos(0.1), math.sin(0.1), 0.0, 0.0]
    mask = 0b0100_0111  # attitude only
    return [
        gcs.pack(mavlink.MAVLink_set_attitude_target_message(k, VEHICLE, 1, mask, q, 0, 0, 0, 0))
        for k in range(count)
    ]


def deliver(bridge: MavlinkBridge, port: int, frames: list[bytes]) -> None:
    seen = frames_seen(bridge)
    for frame in frames:
        send_datagram(port, frame)
    poll_until(bridge, lambda: frames_seen(bridge) >= seen + len(frames))


def test_frames_captured_in_one_run_are_refused_in_the_next(tmp_path):
    state = tmp_path / "signing.json"
    captured = signed_altitude_commands(5)
    first, _, port = listening_bridge(signing_key=KEY, signing_state=state)
    deliver(first, port, captured)
    assert first.counters["operator_commands"] == 5
    assert [a.h for a in first.take_operator_commands()] == [100.0, 101.0, 102.0, 103.0, 104.0]
    first.close()
    assert state.exists() and KEY.hex() not in state.read_text()  # the key is never written

    second, sink, port = listening_bridge(signing_key=KEY, signing_state=state)
    deliver(second, port, captured)
    assert second.take_operator_commands() == [] and second.counters["refused_replay"] == 5
    assert second.counters["operator_commands"] == 0 and sink.calls == []
    assert second.counters["refused_bad_signature"] == 0
    deliver(second, port, signed_altitude_commands(1))  # the station, newly started: heard
    assert second.counters["operator_commands"] == 1
    assert [a.h for a in second.take_operator_commands()] == [100.0]
    second.close()


def test_without_saved_state_the_new_stream_window_lets_a_fresh_capture_in(tmp_path):
    """Why the state file exists: MAVLink accepts a stream it has not seen if it is at most a
    minute old, so a capture replayed into a new bridge without state is taken."""
    captured = signed_altitude_commands(3)
    bridge, sink, port = listening_bridge(signing_key=KEY)
    deliver(bridge, port, captured)
    assert bridge.counters["operator_commands"] == 3
    assert [a.h for a in bridge.take_operator_commands()] == [100.0, 101.0, 102.0]
    bridge.close()


def test_unusable_signing_state_is_ignored_with_a_warning(tmp_path, caplog):
    state = tmp_path / "signing.json"
    other = MavlinkBridge(
        VEHICLE, FRAME, RecordingSink(), signing_key=bytes(32), signing_state=state
    )
    other.feed(Sender(GCS_SYSTEM, GCS_COMPONENT, bytes(32)).pack(heartbeat()))
    other.close()  # saved under another key: not this key's history
    captured = signed_bank_frames(2)
    bridge = MavlinkBridge(VEHICLE, FRAME, RecordingSink(), signing_key=KEY, signing_state=state)
    assert bridge.feed(captured[0]) == 1
    bridge.close()

    for damage in ("{not json", '{"format": 1, "key_id": 5, "streams": "x"}', "[]", "\x00" * 9):
        state.write_text(damage)
        bridge = MavlinkBridge(
            VEHICLE, FRAME, RecordingSink(), signing_key=KEY, signing_state=state
        )
        assert bridge.feed(signed_bank_frames(1)[0]) == 1
        bridge.close()
    assert any("ignoring MAVLink signing state" in r.getMessage() for r in caplog.records)


def signing_timestamp(frame: bytes) -> int:
    low, high = struct.unpack("<IH", frame[-12:-6])
    return low + (high << 32)


def test_a_keyed_peer_dated_at_the_end_of_time_cannot_wrap_our_signing_clock(tmp_path, monkeypatch):
    """pymavlink keeps the low 48 bits of its timestamp: following a peer to 2^48 - 5 would
    wrap our own to 0 after five frames, and everyone would refuse them as old."""
    from uavxai.bridges.signing import default_state_path

    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path))
    state = default_state_path(KEY)
    assert state.parent == tmp_path / "uavxai" and KEY.hex() not in state.name
    for run in range(2):  # and again after a restart that loads the saved state
        bridge, _, port = listening_bridge(signing_key=KEY, signing_state=state)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer:
            peer.bind(("127.0.0.1", 0))
            peer.settimeout(2.0)
            late = Sender(GCS_SYSTEM - run, GCS_COMPONENT, KEY, timestamp=2**48 - 5)
            peer.sendto(late.pack(heartbeat()), ("127.0.0.1", port))
            poll_until(bridge, lambda bridge=bridge: bridge.counters["messages_in"] >= 1)
            for _ in range(10):
                bridge.announce("still signing")
            stamps = [signing_timestamp(peer.recvfrom(512)[0]) for _ in range(10)]
        assert stamps == sorted(stamps) and len(set(stamps)) == 10
        assert stamps[0] > 2**47 and stamps[-1] < 2**48 - 2**31
        bridge.close()


# ------------------------------------------------------------------ fuzzing the decoder
class StrictSink:
    """Fails the test on any setpoint outside LIMITS, or not finite (the JSBSim world raises
    on those)."""

    def __init__(self) -> None:
        self.calls = 0

    def command_ownship(self, **setpoint: float) -> None:
        self.calls += 1
        for name, value in setpoint.items():
            assert value is None or math.isfinite(value), (name, value)
        if setpoint.get("alt_target_m") is not None:
            assert 60.0 <= setpoint["alt_target_m"] <= 250.0
        if setpoint.get("speed_target_mps") is not None:
            assert 12.0 <= setpoint["speed_target_mps"] <= 30.0
        if setpoint.get("bank_cmd_rad") is not None:
            assert abs(setpoint["bank_cmd_rad"]) <= math.radians(35.0) + 1e-9
        if setpoint.get("accel_cmd_mps2") is not None:
            assert abs(setpoint["accel_cmd_mps2"]) <= 2.0

    def command_orbit(self, x: float, y: float, radius_m: float, clockwise: bool = True) -> None:
        assert 0.0 <= x <= 1500.0 and 0.0 <= y <= 1000.0 and 1.0 <= radius_m <= 750.0


_NASTY = (math.nan, math.inf, -math.inf, 3e38, -3e38, 0.0, -0.0, 1e-45, -1.0)
_COMMANDS = (
    mavlink.MAV_CMD_DO_CHANGE_SPEED,
    mavlink.MAV_CMD_DO_CHANGE_ALTITUDE,
    mavlink.MAV_CMD_REQUEST_MESSAGE,
    mavlink.MAV_CMD_GET_HOME_POSITION,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    mavlink.MAV_CMD_DO_ORBIT,
    mavlink.MAV_CMD_NAV_LAND,
)


def nasty_float(rng) -> float:
    if rng.random() < 0.4:
        return float(rng.choice(_NASTY))
    return float(rng.normal(0.0, 10.0 ** rng.integers(0, 6)))


def hostile_message(rng):
    """A well-formed message of a type the bridge handles, with hostile contents."""
    f = lambda: nasty_float(rng)  # noqa: E731
    target = int(rng.choice([VEHICLE, VEHICLE, 0, 2, 255]))
    component = int(rng.choice([1, 1, 0, 190]))
    kind = rng.integers(0, 8)
    if kind == 0:
        q = [f() for _ in range(4)]
        return mavlink.MAVLink_set_attitude_target_message(
            int(rng.integers(0, 2**32)), target, component, int(rng.integers(0, 256)), q,
            f(), f(), f(), f(),
        )  # fmt: skip
    if kind == 1:
        frame = int(rng.choice([mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_LOCAL_NED, 99]))
        return mavlink.MAVLink_set_position_target_local_ned_message(
            0, target, component, frame, int(rng.integers(0, 2**16)), *(f() for _ in range(11))
        )
    if kind == 2:
        command = int(rng.choice(_COMMANDS)) if rng.random() < 0.8 else int(rng.integers(0, 2**16))
        return mavlink.MAVLink_command_long_message(
            target, component, command, int(rng.integers(0, 256)), *(f() for _ in range(7))
        )
    if kind == 3:
        frame = int(rng.choice([mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL]))
        return mavlink.MAVLink_command_int_message(
            target, component, frame, mavlink.MAV_CMD_DO_ORBIT, 0, 0, f(), f(), f(), f(),
            int(rng.integers(-(2**31), 2**31)), int(rng.integers(-(2**31), 2**31)), f(),
        )  # fmt: skip
    if kind == 4:
        name = bytes(rng.integers(0, 256, int(rng.integers(0, 17)), dtype=np.uint8))
        return mavlink.MAVLink_param_request_read_message(
            target, component, name, int(rng.integers(-(2**15), 2**15))
        )
    if kind == 5:
        return mavlink.MAVLink_param_request_list_message(target, component)
    if kind == 6:
        name = bytes(rng.integers(0, 256, int(rng.integers(0, 17)), dtype=np.uint8))
        return mavlink.MAVLink_param_set_message(target, component, name, f(), 9)
    return heartbeat()


def hostile_datagram(rng, senders: list[Sender]) -> bytes:
    """Frames with hostile contents, then bit flips, truncations, garbage and splices."""
    frames = [senders[int(rng.integers(len(senders)))].pack(hostile_message(rng))]
    for _ in range(int(rng.integers(0, 3))):
        frames.append(senders[int(rng.integers(len(senders)))].pack(hostile_message(rng)))
    data = bytearray(b"".join(frames))
    damage = rng.integers(0, 5)
    if damage == 1:  # bit flips
        for bit in rng.integers(0, 8 * len(data), int(rng.integers(1, 9))):
            data[bit // 8] ^= 1 << (bit % 8)
    elif damage == 2:  # cut anywhere
        data = data[: int(rng.integers(1, len(data)))]
    elif damage == 3:  # garbage around and between
        garbage = lambda: bytes(rng.integers(0, 256, int(rng.integers(0, 40)), dtype=np.uint8))  # noqa: E731
        data = bytearray(garbage() + bytes(data[: len(data) // 2]) + garbage() + bytes(data))
    elif damage == 4:  # pure noise, rich in start markers and signing flags
        markers = np.array([0xFD, 0xFE, 0x01, 0x00, 0xFF], dtype=np.uint8)
        noise = rng.integers(0, 256, int(rng.integers(1, 300)), dtype=np.uint8)
        spots = rng.random(len(noise)) < 0.2
        noise[spots] = rng.choice(markers, int(spots.sum()))
        data = bytearray(noise.tobytes())
    return bytes(data)


def fuzz_senders(rng, key: bytes | None) -> list[Sender]:
    senders = [Sender(GCS_SYSTEM, GCS_COMPONENT)]  # unsigned
    if key is not None:
        keyed = Sender(GCS_SYSTEM, GCS_COMPONENT, key)  # the keyed ground station, often
        senders += [keyed] * 6
        for _ in range(6):  # forgers, on the planner's stream among others, dated anywhere
            system, component = (
                (VEHICLE, PLANNER_COMPONENT) if rng.random() < 0.5 else rng.integers(0, 256, 2)
            )
            senders.append(
                Sender(
                    int(system),
                    int(component),
                    rng.bytes(32),
                    link_id=int(rng.integers(0, 2)),
                    timestamp=int(rng.integers(0, 2**48 - 10**6)),
                )  # fmt: skip
            )
    return senders


COUNTED = (
    "messages_in", "malformed", "unknown_messages", "refused_unsigned", "refused_bad_signature",
    "refused_replay", "refused_unknown_peer",
)  # fmt: skip


@pytest.mark.parametrize("key", [None, KEY], ids=["unsigned", "signed"])
def test_fuzzed_frames_never_raise_are_counted_and_the_planner_is_still_obeyed(key):
    rng = np.random.default_rng(20261123)
    bridge, _, port = listening_bridge(signing_key=key, **LIMITS)
    sink = StrictSink()
    bridge._sink = sink  # the strict sink checks every setpoint against LIMITS
    senders = fuzz_senders(rng, key)
    planner = CommandEncoder(VEHICLE, VEHICLE, signing_key=key)
    assert bridge.feed(planner.encode(0.1, 0.0, 0.0)) == 2

    datagrams = 3000
    for n in range(datagrams):
        bridge.tick(n * 0.01)
        data = hostile_datagram(rng, senders)
        before = sum(bridge.counters[c] for c in COUNTED)
        bridge.feed(data)  # must not raise
        assert sum(bridge.counters[c] for c in COUNTED) > before, data.hex()
    # ... and over a real socket, in bursts: a ground station's aims at most, never a setpoint
    fed = sink.calls
    sent = 0
    for _ in range(10):
        burst = [hostile_datagram(rng, senders) for _ in range(50)]
        seen = sum(bridge.counters[c] for c in COUNTED)
        for data in burst:
            send_datagram(port, data)
        sent += len(burst)
        poll_until(bridge, lambda seen=seen: sum(bridge.counters[c] for c in COUNTED) >= seen + 50)

    assert sink.calls == fed  # nothing from the link reached the autopilot
    aims = bridge.take_operator_commands()
    assert aims  # the listed (and keyed) station's commands that came through intact
    for aim in aims:  # every aim held to LIMITS
        assert aim.h is None or 60.0 <= aim.h <= 250.0, aim
        assert aim.speed_mps is None or 12.0 <= aim.speed_mps <= 30.0, aim
        assert aim.x is None or (0.0 <= aim.x <= 1500.0 and 0.0 <= aim.y <= 1000.0), aim
        assert aim.radius_m is None or 1.0 <= aim.radius_m <= 750.0, aim
    c = bridge.counters
    assert c["operator_refused"] > 0  # the listed station's setpoints and bad commands
    assert c["malformed"] > 500 and c["messages_in"] > 500
    assert c["commands"] > 20 and c["clamped_commands"] > 10 and c["rejected_commands"] > 10
    if key is not None:
        assert c["refused_bad_signature"] > 100 and c["refused_unsigned"] > 100
    # Still the planner's: its next decision is obeyed, at the next simulated instant.
    calls = sink.calls
    t = datagrams * 0.01
    bridge.tick(t)
    assert bridge.feed(planner.encode(-0.2, 0.5, t)) == 2
    assert sink.calls == calls + 2 and not bridge.failsafe_active
    bridge.close()


# ------------------------------------------------------------------ the attack, end to end
def _run_head_on(tmp_path: Path, name: str, forge: bool) -> dict:
    """`uavxai run` of the shipped head-on encounter with a signing key and a UDP link; with
    `forge`, a forged planner-stream HEARTBEAT arrives on the link every 20 ms of wall time."""
    import json
    import threading

    import yaml

    from uavxai.cli import main

    port = free_port()
    scenario = yaml.safe_load((Path(__file__).parents[1] / "scenarios/head_on.yaml").read_text())
    scenario["bridge"] = {"signing_key_hex": KEY.hex(), "mavlink": f"udpin:127.0.0.1:{port}"}
    scenario["log"] = {"rerun": False}
    scenario["service"] = {"planner": "grid", "platform": "hover"}  # the fast exact grid
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(scenario))
    stop = threading.Event()

    def forger() -> None:
        frame = forged_heartbeat(VEHICLE, PLANNER_COMPONENT)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            while not stop.wait(0.02):
                s.sendto(frame, ("127.0.0.1", port))

    thread = threading.Thread(target=forger, daemon=True)
    if forge:
        thread.start()
    try:
        assert main(["run", str(path), "--out", str(tmp_path / name)]) == 0
    finally:
        stop.set()
        if forge:
            thread.join(timeout=2)
    return json.loads((tmp_path / name / "summary.json").read_text())


@pytest.mark.slow
def test_forged_frames_during_a_head_on_run_change_nothing(tmp_path):
    """Issue 14's reproduction: before the fix the forged frame made every planner command
    'old', the failsafe flew straight on and the head-on run ended in a collision at 47.6 m."""
    calm = _run_head_on(tmp_path, "calm", forge=False)
    attacked = _run_head_on(tmp_path, "attacked", forge=True)
    assert attacked["bridge"]["refused_bad_signature"] >= 10
    assert attacked["bridge"].get("failsafe_events", 0) == 0
    assert attacked["outcome"] == calm["outcome"] == "goal"
    assert attacked["min_separation_m"] == calm["min_separation_m"]
    assert attacked["bridge"]["commands"] == calm["bridge"]["commands"]
