"""The bridge on real sockets: pymavlink peers on 127.0.0.1 receive its telemetry, send it
commands (aims for the planner, never setpoints: issue 28), download its parameters, flood it
with damaged packets and test its signing."""

from __future__ import annotations

import math
import os
import random
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from uavxai.bridges import CommandEncoder, MavlinkBridge
from uavxai.bridges.operator import ARDUPLANE_MODES, SETPOINT_REFUSAL, Kind
from uavxai.bridges.protocol import ATTITUDE_ONLY_MASK
from uavxai.bridges.telemetry import ICAO_BLOCK
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.errors import UserError

FRAME = LocalFrame(34.1230, 108.8370, 400.0)
KEY = bytes.fromhex("5a" * 32)
INTRUDERS = 3
GCS_SYSTEM, GCS_COMPONENT = 255, 190
# The ground station every test's peers speak as: without it the bridge obeys no one (issue 28).
GROUND_STATIONS = [(GCS_SYSTEM, "127.0.0.1")]


class RecordingSink:
    def __init__(self) -> None:
        self.calls: list[dict] = []

    def command_ownship(self, **setpoint) -> None:
        self.calls.append(setpoint)


def traffic(t: float) -> TrafficState:
    """Ownship climbing north-east in a right turn; intruders flying west, one climbing."""
    pos = [[100 + 10 * t, 200 + 16 * t, 120 + 0.5 * t]]
    vel = [[10.0, 16.0, 0.5]]
    att = [[0.3, 0.05, math.pi / 4 + 0.1 * t]]
    for k in range(1, INTRUDERS + 1):
        climb = 2.0 if k == 2 else 0.0
        pos.append([1000 + 100 * k - 20 * t, 500 + 50 * k, 100 + 10 * k + climb * t])
        vel.append([-20.0, 0.0, climb])
        att.append([0.0, 0.0, 1.5 * math.pi])
    ids = ("ownship", *(f"intruder-{k}" for k in range(1, INTRUDERS + 1)))
    return TrafficState(
        t, ids, np.array(pos), np.array(vel), np.array(att), np.full(len(ids), 20.0)
    )


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ground_station(link: str, key: bytes | None = None):
    conn = mavutil.mavlink_connection(
        link, source_system=GCS_SYSTEM, source_component=GCS_COMPONENT
    )
    if key is not None:
        conn.setup_signing(key, sign_outgoing=True)
    return conn


def listening_station(key: bytes | None = None):
    gcs = ground_station("udpin:127.0.0.1:0", key)
    return gcs, gcs.port.getsockname()[1]


def receive(conn, quiet_s: float = 0.05) -> list:
    """Everything `conn` receives until it has been quiet for `quiet_s`."""
    messages, last = [], time.monotonic()
    while time.monotonic() - last < quiet_s:
        msg = conn.recv_msg()
        if msg is None:
            time.sleep(0.002)
            continue
        messages.append(msg)
        last = time.monotonic()
    return messages


def poll_until(bridge: MavlinkBridge, done, timeout_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        bridge.poll()
        assert time.monotonic() < deadline, "the bridge never received it"
        time.sleep(0.002)


def connected_pair(**bridge_kwargs):
    """A bridge listening on udpin and a ground station that has said hello."""
    port = free_port()
    sink = RecordingSink()
    bridge_kwargs.setdefault("ground_stations", GROUND_STATIONS)
    bridge = MavlinkBridge(1, FRAME, sink, link=f"udpin:127.0.0.1:{port}", **bridge_kwargs)
    gcs = ground_station(f"udpout:127.0.0.1:{port}", bridge_kwargs.get("signing_key"))
    gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    poll_until(bridge, lambda: bridge.counters["messages_in"] >= 1)
    return bridge, sink, gcs, port


@pytest.fixture(scope="module")
def session():
    """Two simulated seconds of telemetry, sent with udpout to a listening ground station."""
    gcs, port = listening_station()
    bridge = MavlinkBridge(1, FRAME, RecordingSink(), link=f"udpout:127.0.0.1:{port}")
    states, messages = {}, []
    for k in range(21):
        state = traffic(k / 10)
        states[round(state.t * 1000)] = state
        bridge.publish(state)
        messages += receive(gcs, quiet_s=0.01)
    messages += receive(gcs)
    yield bridge, gcs, states, messages
    bridge.close()
    gcs.close()


def of_type(messages: list, kind: str) -> list:
    return [m for m in messages if m.get_type() == kind]


# ------------------------------------------------------------------ telemetry
def test_vehicle_telemetry_at_its_rates_in_simulated_time(session):
    bridge, _, _, messages = session
    counts = {kind: len(of_type(messages, kind)) for kind in {m.get_type() for m in messages}}
    assert counts["HEARTBEAT"] == 3  # t = 0, 1, 2 s
    for kind in ("SYS_STATUS", "GLOBAL_POSITION_INT", "ATTITUDE", "VFR_HUD"):
        assert counts[kind] == 21, kind  # 10 Hz over 0..2 s
    assert counts["ADSB_VEHICLE"] == 5 * INTRUDERS  # 2 Hz
    assert counts["HOME_POSITION"] == 1
    assert counts["MISSION_CURRENT"] == 3  # with every heartbeat
    assert bridge.counters["messages_out"] == len(messages)
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in messages} == {(1, 1)}

    heartbeat = of_type(messages, "HEARTBEAT")[0]
    assert heartbeat.type == mavlink.MAV_TYPE_FIXED_WING
    # ArduPlane's autopilot and mode numbers, so ground stations name the mode
    assert heartbeat.autopilot == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert heartbeat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert heartbeat.base_mode & mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    assert heartbeat.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert heartbeat.custom_mode == ARDUPLANE_MODES["AUTO"] == ARDUPLANE_MODES[bridge.mode]
    assert heartbeat.get_header().mlen and heartbeat.get_msgbuf()[0] == 0xFD


def test_positions_agree_with_the_local_frame(session):
    _, _, states, messages = session
    for gpi in of_type(messages, "GLOBAL_POSITION_INT"):
        state = states[gpi.time_boot_ms]
        x, y, h = state.pos[0]
        lat, lon, alt = FRAME.to_geodetic(x, y, h)
        assert gpi.lat == pytest.approx(lat * 1e7, abs=0.51)
        assert gpi.lon == pytest.approx(lon * 1e7, abs=0.51)
        assert gpi.alt == pytest.approx(alt * 1000, abs=0.51)
        assert gpi.relative_alt == pytest.approx(h * 1000, abs=0.51)
        back = FRAME.to_local(gpi.lat / 1e7, gpi.lon / 1e7, gpi.alt / 1000)
        assert np.allclose(back, (x, y, h), atol=0.02)
        assert (gpi.vx, gpi.vy, gpi.vz) == (1600, 1000, -50)  # NED cm/s
        assert gpi.hdg == round(math.degrees(state.att[0, 2]) * 100) % 36000

    for att in of_type(messages, "ATTITUDE"):
        state = states[att.time_boot_ms]
        assert (att.roll, att.pitch) == pytest.approx(tuple(state.att[0, :2]), abs=1e-6)
        assert att.yaw == pytest.approx(state.att[0, 2], abs=1e-6)
    turning = of_type(messages, "ATTITUDE")[-1]  # psi_dot = 0.1 rad/s at bank 0.3
    assert turning.yawspeed == pytest.approx(0.1 * math.cos(0.3) * math.cos(0.05), rel=1e-3)

    hud = of_type(messages, "VFR_HUD")[-1]
    assert hud.airspeed == pytest.approx(20.0)
    assert hud.groundspeed == pytest.approx(math.hypot(10, 16), rel=1e-6)
    assert hud.alt == pytest.approx(400 + 121.0, abs=1e-3) and hud.climb == pytest.approx(0.5)

    home = of_type(messages, "HOME_POSITION")[0]
    lat, lon, alt = FRAME.to_geodetic(100.0, 200.0, 0.0)
    assert (home.latitude, home.longitude) == (round(lat * 1e7), round(lon * 1e7))
    assert home.altitude == 400_000
    assert (home.x, home.y, home.z) == (200.0, 100.0, 0.0)


def test_every_intruder_is_an_adsb_vehicle(session):
    _, _, states, messages = session
    reports = of_type(messages, "ADSB_VEHICLE")
    by_icao = {}
    for r in reports:
        by_icao.setdefault(r.ICAO_address, []).append(r)
    assert sorted(by_icao) == [ICAO_BLOCK + k for k in range(1, INTRUDERS + 1)]

    last_state = states[2000]
    for k in range(1, INTRUDERS + 1):
        r = by_icao[ICAO_BLOCK + k][-1]
        assert r.callsign == f"INTR{k:02d}"
        x, y, h = last_state.pos[k]
        lat, lon, alt = FRAME.to_geodetic(x, y, h)
        assert r.lat == round(lat * 1e7) and r.lon == round(lon * 1e7)
        assert r.altitude == round(alt * 1000)
        assert r.altitude_type == mavlink.ADSB_ALTITUDE_TYPE_GEOMETRIC
        assert r.heading == 27000  # flying west
        assert r.hor_velocity == 2000
        assert r.ver_velocity == (200 if k == 2 else 0)
        for flag in ("VALID_COORDS", "VALID_ALTITUDE", "VALID_HEADING", "VALID_VELOCITY"):
            assert r.flags & getattr(mavlink, f"ADSB_FLAGS_{flag}"), flag


# ------------------------------------------------------------------ commands from a peer
def euler_quaternion(roll: float, pitch: float, yaw: float) -> list[float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def test_peer_answering_on_udpout_aims_but_never_commands_the_bank():
    """A listed station's bank setpoint is refused (the sink gets nothing, the station is told
    why); its DO_CHANGE_ALTITUDE becomes an aim, acknowledged. The planner's bank is flown."""
    gcs, port = listening_station()
    sink = RecordingSink()
    link = f"udpout:127.0.0.1:{port}"
    with MavlinkBridge(1, FRAME, sink, link=link, ground_stations=GROUND_STATIONS) as bridge:
        bridge.publish(traffic(0.0))
        assert gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=2.0) is not None

        q = euler_quaternion(math.radians(-25), 0.1, 2.0)
        gcs.mav.set_attitude_target_send(0, 2, 1, ATTITUDE_ONLY_MASK, q, 0, 0, 0, 0)
        gcs.mav.set_attitude_target_send(0, 1, 1, ATTITUDE_ONLY_MASK, q, 0, 0, 0, 0)
        poll_until(bridge, lambda: bridge.counters["operator_refused"] == 1)
        assert sink.calls == [] and bridge.counters["commands"] == 0
        assert bridge.counters["ignored_other_target"] == 1  # the one sent to system 2
        # why, as one STATUSTEXT carries it (50 characters)
        assert [m.text for m in of_type(receive(gcs), "STATUSTEXT")] == [SETPOINT_REFUSAL[:50]]

        change = mavlink.MAV_CMD_DO_CHANGE_ALTITUDE
        relative = mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
        gcs.mav.command_long_send(1, 1, change, 0, 180.0, relative, 0, 0, 0, 0, 0)
        ack = poll_and_ack(bridge, gcs)
        assert (ack.command, ack.result) == (change, mavlink.MAV_RESULT_ACCEPTED)
        [aim] = bridge.take_operator_commands()
        assert (aim.kind, aim.h, aim.source) == (Kind.ALTITUDE, 180.0, GCS_SYSTEM)
        assert sink.calls == [] and bridge.counters["operator_commands"] == 1

        # the same bank, from the onboard planner, is flown
        assert bridge.feed(CommandEncoder(1, 1).attitude(math.radians(-25))) == 1
        assert sink.calls == [{"bank_cmd_rad": pytest.approx(math.radians(-25), abs=1e-6)}]
    gcs.close()


def test_change_speed_from_a_station_is_acknowledged_and_becomes_an_aim():
    bridge, sink, gcs, _ = connected_pair()
    gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 24.5, -1, 0, 0, 0, 0)
    ack = poll_and_ack(bridge, gcs)
    assert ack.command == mavlink.MAV_CMD_DO_CHANGE_SPEED
    assert (ack.result, ack.result_param2) == (mavlink.MAV_RESULT_ACCEPTED, 0)
    assert (ack.target_system, ack.target_component) == (GCS_SYSTEM, GCS_COMPONENT)
    [aim] = bridge.take_operator_commands()
    assert (aim.kind, aim.speed_mps) == (Kind.SPEED, pytest.approx(24.5))
    assert sink.calls == []  # an aim for the planner, not a setpoint

    gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 0, -5, -1, 0, 0, 0, 0)
    assert poll_and_ack(bridge, gcs).result == mavlink.MAV_RESULT_DENIED
    gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_NAV_LAND, 0, 0, 0, 0, 0, 0, 0, 0)
    assert poll_and_ack(bridge, gcs).result == mavlink.MAV_RESULT_UNSUPPORTED
    assert bridge.take_operator_commands() == [] and sink.calls == []
    c = bridge.counters
    assert (c["operator_commands"], c["operator_refused"]) == (1, 1)

    # the planner's own DO_CHANGE_SPEED is flown, and not acknowledged onto the ground link
    receive(gcs)
    assert bridge.feed(CommandEncoder(1, 1).change_speed(21.0)) == 1
    assert sink.calls == [{"speed_target_mps": pytest.approx(21.0),
                           "speed_max_mps": pytest.approx(21.0)}]  # fmt: skip
    assert of_type(receive(gcs, quiet_s=0.2), "COMMAND_ACK") == []
    assert bridge.take_operator_commands() == []
    bridge.close()
    gcs.close()


def test_requested_messages_are_sent_on_demand():
    bridge, _, gcs, _ = connected_pair()
    bridge.publish(traffic(0.0))
    receive(gcs)
    request = mavlink.MAV_CMD_REQUEST_MESSAGE
    gcs.mav.command_long_send(1, 1, request, 0, mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION, *[0] * 6)
    assert poll_and_ack(bridge, gcs).result == mavlink.MAV_RESULT_ACCEPTED
    version = gcs.recv_match(type="AUTOPILOT_VERSION", blocking=True, timeout=2.0)
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
    assert version.capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    gcs.mav.command_long_send(1, 1, mavlink.MAV_CMD_GET_HOME_POSITION, 0, *[0] * 7)
    assert poll_and_ack(bridge, gcs).result == mavlink.MAV_RESULT_ACCEPTED
    home = gcs.recv_match(type="HOME_POSITION", blocking=True, timeout=2.0)
    assert home.altitude == 400_000
    bridge.close()
    gcs.close()


def poll_and_ack(bridge: MavlinkBridge, gcs):
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline:
        bridge.poll()
        ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=0.01)
        if ack is not None:
            return ack
    raise AssertionError("no COMMAND_ACK")


def test_parameter_download_is_consistent():
    extra = {"MCTS_SIMS": 200.0, "D_MIN_M": 50.0}
    bridge, _, gcs, _ = connected_pair(params=extra)
    gcs.mav.param_request_list_send(1, 1)
    poll_until(bridge, lambda: bridge.counters["param_requests"] == 1)
    values = of_type(receive(gcs), "PARAM_VALUE")

    count = values[0].param_count
    assert count == len(values) >= len(extra) + 1
    assert {v.param_count for v in values} == {count}
    assert sorted(v.param_index for v in values) == list(range(count))
    table = {v.param_id: v.param_value for v in values}
    assert table["MCTS_SIMS"] == 200.0 and table["D_MIN_M"] == 50.0
    assert table["BRG_SYSID"] == 1.0

    gcs.mav.param_request_read_send(1, 1, b"D_MIN_M", -1)
    gcs.mav.param_set_send(1, 1, b"D_MIN_M", 5.0, mavlink.MAV_PARAM_TYPE_REAL32)
    poll_until(bridge, lambda: bridge.counters["param_sets_refused"] == 1)
    got = receive(gcs)
    replies = of_type(got, "PARAM_VALUE")
    assert [(r.param_id, r.param_value) for r in replies] == [("D_MIN_M", 50.0)] * 2
    # the set did not take, and the station is told why
    why = [m.text for m in of_type(got, "STATUSTEXT")]
    assert why == ["D_MIN_M read-only: set it in the scenario"]
    bridge.close()
    gcs.close()


# ------------------------------------------------------------------ hostile input
def test_five_hundred_damaged_packets_are_dropped_counted_and_never_obeyed():
    rng = random.Random(12)
    bridge, sink, gcs, port = connected_pair()
    encoder = CommandEncoder(GCS_SYSTEM, 1)  # the listed station's system, from its host
    valid = [encoder.attitude(0.7), encoder.acceleration(2.0), encoder.change_speed(25.0)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as attacker:
        for i in range(500):
            frame = bytearray(rng.choice(valid))
            if i % 3 == 0:
                packet = rng.randbytes(rng.randint(1, 300))
            elif i % 3 == 1:
                packet = bytes(frame[: rng.randint(1, len(frame) - 1)])
            else:
                for _ in range(rng.randint(1, 3)):
                    frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)
                packet = bytes(frame)
            attacker.sendto(packet, ("127.0.0.1", port))
            if i % 50 == 49:
                bridge.poll()
        attacker.sendto(encoder.change_altitude(140.0), ("127.0.0.1", port))
        poll_until(bridge, lambda: bridge.counters["operator_commands"])

    dropped = bridge.counters["malformed"] + bridge.counters["unknown_messages"]
    assert dropped >= 500
    # only the one intact command was taken: no damaged frame became an aim or a refusal
    [aim] = bridge.take_operator_commands()
    assert (aim.kind, aim.h) == (Kind.ALTITUDE, pytest.approx(140.0))
    assert bridge.counters["operator_commands"] == 1
    assert bridge.counters["operator_refused"] == 0
    assert sink.calls == [] and bridge.counters["commands"] == 0
    bridge.close()
    gcs.close()


# ------------------------------------------------------------------ signing
def test_signing_refuses_unsigned_and_foreign_commands_and_signs_telemetry():
    bridge, sink, keyed, port = connected_pair(signing_key=KEY)
    unsigned = ground_station(f"udpout:127.0.0.1:{port}")
    foreign = ground_station(f"udpout:127.0.0.1:{port}", key=bytes(32))
    q = euler_quaternion(0.35, 0.0, 0.0)

    speed = mavlink.MAV_CMD_DO_CHANGE_SPEED

    unsigned.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
    unsigned.mav.command_long_send(1, 1, speed, 0, 0, 15.0, -1, 0, 0, 0, 0)
    foreign.mav.command_long_send(1, 1, speed, 0, 0, 16.0, -1, 0, 0, 0, 0)
    poll_until(bridge, lambda: bridge.counters["refused_bad_signature"] == 1)
    assert bridge.counters["refused_unsigned"] == 1
    assert bridge.take_operator_commands() == [] and sink.calls == []
    assert bridge.counters["operator_commands"] == bridge.counters["operator_refused"] == 0
    assert bridge.counters["messages_in"] == 2  # the keyed and the unsigned heartbeats

    keyed.mav.command_long_send(1, 1, speed, 0, 0, 24.0, -1, 0, 0, 0, 0)
    assert poll_and_ack(bridge, keyed).result == mavlink.MAV_RESULT_ACCEPTED
    [aim] = bridge.take_operator_commands()
    assert (aim.kind, aim.speed_mps) == (Kind.SPEED, pytest.approx(24.0))
    # even signed, a setpoint from the ground is refused: the sink never hears the link
    keyed.mav.set_attitude_target_send(0, 1, 1, ATTITUDE_ONLY_MASK, q, 0, 0, 0, 0)
    poll_until(bridge, lambda: bridge.counters["operator_refused"] == 1)
    assert sink.calls == []

    bridge.publish(traffic(0.0))
    heartbeat = keyed.recv_match(type="HEARTBEAT", blocking=True, timeout=2.0)
    assert heartbeat is not None and heartbeat.get_signed()
    assert keyed.mav.signing.goodsig_count >= 1 and keyed.mav.signing.badsig_count == 0
    for conn in (bridge, keyed, unsigned, foreign):
        conn.close()


# ------------------------------------------------------------------ links
def test_tcp_link_carries_commands_and_telemetry():
    port = free_port()
    sink = RecordingSink()
    link = f"tcpin:127.0.0.1:{port}"
    with MavlinkBridge(1, FRAME, sink, link=link, ground_stations=GROUND_STATIONS) as bridge:
        gcs = ground_station(f"tcp:127.0.0.1:{port}")
        station = CommandEncoder(GCS_SYSTEM, 1)
        for k in range(3):  # several frames in one stream, parsed across reads
            gcs.write(station.change_altitude(100.0 + 10 * k) + station.change_speed(20.0 + k))
        poll_until(bridge, lambda: bridge.counters["operator_commands"] == 6)
        aims = bridge.take_operator_commands()
        assert [a.h for a in aims[::2]] == pytest.approx([100.0, 110.0, 120.0])
        assert [a.speed_mps for a in aims[1::2]] == pytest.approx([20.0, 21.0, 22.0])
        assert sink.calls == []
        acks = [gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=2.0) for _ in range(6)]
        assert [a.result for a in acks if a is not None] == [mavlink.MAV_RESULT_ACCEPTED] * 6
        bridge.publish(traffic(0.0))
        assert gcs.recv_match(type="GLOBAL_POSITION_INT", blocking=True, timeout=2.0)
        gcs.close()


@pytest.mark.parametrize(
    "link",
    [
        "14550",
        "udpout:127.0.0.1",
        "udpout:127.0.0.1:99999",
        "serial:/dev/ttyS0:57600",
        "udpin:203.0.113.7:14550",  # not an address of this machine: bind fails
        "tcp:127.0.0.1:PORT_CLOSED",
    ],
)
def test_unusable_links_are_user_errors_naming_the_allowed_forms(link):
    link = link.replace("PORT_CLOSED", str(free_port()))
    with pytest.raises(UserError) as err:
        MavlinkBridge(1, FRAME, RecordingSink(), link=link)
    message = str(err.value)
    assert repr(link) in message and "udpout:HOST:PORT" in message and "tcp:HOST:PORT" in message


def test_mavutil_imported_first_still_speaks_mavlink2():
    code = (
        "import os; os.environ.pop('MAVLINK20', None)\n"
        "from pymavlink import mavutil\n"
        "assert mavutil.mavlink.WIRE_PROTOCOL_VERSION == '1.0'\n"
        "import uavxai.bridges\n"
        "print(mavutil.mavlink.WIRE_PROTOCOL_VERSION)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "MAVLINK20"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "2.0"
