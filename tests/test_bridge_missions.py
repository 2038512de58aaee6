"""The mission protocol, vehicle side (issue 28): a ground station uploads, downloads and clears
the ownship's mission. In memory with real frames (a pymavlink codec as the ground station and
missions read by pymavlink's own QGC WPL 110 loader), over loopback UDP through the bridge,
and with MAVProxy itself when the `gcs` extra is installed."""

from __future__ import annotations

import copy
import logging
import math
import os
import random
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from pymavlink import mavutil, mavwp
from pymavlink.dialects.v20 import common as mavlink

from uavxai.bridges import MavlinkBridge
from uavxai.bridges.missions import MissionItem, MissionServer, item_from_message
from uavxai.bridges.operator import Kind
from uavxai.bridges.telemetry import autopilot_version
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState

VEHICLE, GCS = (1, 1), (255, 190)
MISSION = mavlink.MAV_MISSION_TYPE_MISSION
HOME_MSL_M = 400.0
# Home, three waypoints, a 30 s loiter of radius 80 m, RTL: columns seq, current, frame,
# command, param1..4, x (lat), y (lon), z, autocontinue (what MAVProxy's `wp save` writes).
WPL = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t34.1230000\t108.8370000\t400.000000\t1
1\t0\t3\t16\t0\t0\t0\t0\t34.1250000\t108.8380000\t120.000000\t1
2\t0\t3\t16\t0\t0\t0\t0\t34.1271234\t108.8401234\t130.000000\t1
3\t0\t3\t16\t0\t0\t0\t0\t34.1260000\t108.8420000\t140.000000\t1
4\t0\t3\t19\t30\t0\t80\t0\t34.1240000\t108.8410000\t150.000000\t1
5\t0\t3\t20\t0\t0\t0\t0\t0\t0\t0\t1
"""


@pytest.fixture
def wpl_file(tmp_path):
    path = tmp_path / "mission.txt"
    path.write_text(WPL)
    return path


def load(path) -> mavwp.MAVWPLoader:
    loader = mavwp.MAVWPLoader(target_system=VEHICLE[0], target_component=VEHICLE[1])
    assert loader.load(str(path)) == 6
    return loader


def as_int(wp) -> mavlink.MAVLink_mission_item_int_message:
    """A loader's MISSION_ITEM as MISSION_ITEM_INT (degE7), as ground stations upload it."""
    return mavlink.MAVLink_mission_item_int_message(
        *VEHICLE, wp.seq, wp.frame, wp.command, wp.current, wp.autocontinue,
        wp.param1, wp.param2, wp.param3, wp.param4,
        round(wp.x * 1e7), round(wp.y * 1e7), wp.z, MISSION,
    )  # fmt: skip


class Wire:
    """A MissionServer and a ground-station codec joined in memory: every message either way
    is encoded to MAVLink 2 bytes and decoded again."""

    def __init__(self, **server_kwargs) -> None:
        self._to_gcs: list[bytes] = []
        self._to_vehicle: list[bytes] = []
        vehicle = mavlink.MAVLink(SimpleNamespace(write=self._to_gcs.append), *VEHICLE)
        self.server = MissionServer(vehicle.send, **server_kwargs)
        self._vehicle_in = mavlink.MAVLink(None, *VEHICLE)
        self.gcs = mavlink.MAVLink(SimpleNamespace(write=self._to_vehicle.append), *GCS)
        self.now = 0.0

    def send(self, msg, source: mavlink.MAVLink | None = None) -> list:
        """`msg` from the ground station (or another codec); the decoded replies."""
        (source or self.gcs).send(msg)
        frames, self._to_vehicle[:] = list(self._to_vehicle), []
        for frame in frames:
            for decoded in self._vehicle_in.parse_buffer(frame) or []:
                assert self.server.handle(decoded, self.now)
        return self.replies()

    def replies(self) -> list:
        frames, self._to_gcs[:] = list(self._to_gcs), []
        return [m for f in frames for m in self.gcs.parse_buffer(f) or []]

    def tick(self, dt: float) -> list:
        self.now += dt
        self.server.tick(self.now)
        return self.replies()


def upload(wire: Wire, items: list, legacy: bool = False):
    """The ground station's side of an upload; returns the vehicle's final MISSION_ACK. Items
    go as MISSION_ITEM_INT, or with `legacy` as they are (the loader's MISSION_ITEM)."""
    replies = wire.send(mavlink.MAVLink_mission_count_message(*VEHICLE, len(items), MISSION))
    while True:
        (reply,) = replies
        if reply.get_type() == "MISSION_ACK":
            return reply
        assert reply.get_type() == "MISSION_REQUEST_INT"
        assert (reply.target_system, reply.target_component) == GCS
        item = items[reply.seq]
        replies = wire.send(item if legacy else as_int(item))


def download(wire: Wire, legacy: bool = False) -> list:
    """The ground station's side of a download: the items, as decoded MISSION_ITEM_INT."""
    (count,) = wire.send(mavlink.MAVLink_mission_request_list_message(*VEHICLE, MISSION))
    assert count.get_type() == "MISSION_COUNT" and count.mission_type == MISSION
    assert (count.target_system, count.target_component) == GCS
    request = mavlink.MAVLink_mission_request_message if legacy else (
        mavlink.MAVLink_mission_request_int_message
    )
    items = []
    for seq in range(count.count):
        (item,) = wire.send(request(*VEHICLE, seq, MISSION))
        assert item.get_type() == "MISSION_ITEM_INT" and item.seq == seq
        assert (item.target_system, item.target_component) == GCS
        items.append(item)
    ack = mavlink.MAVLink_mission_ack_message(*VEHICLE, mavlink.MAV_MISSION_ACCEPTED, MISSION)
    assert wire.send(ack) == []  # consumed, nothing to say
    return items


def assert_matches_loader(
    items: list[MissionItem], loader: mavwp.MAVWPLoader, deg: float = 0.6e-7
) -> None:
    """`items` are the loader's; coordinates within `deg` (degE7 rounding by default)."""
    assert len(items) == loader.count()
    for item, wp in zip(items, loader.wpoints, strict=True):
        assert (item.seq, item.command, item.frame) == (wp.seq, wp.command, wp.frame)
        assert item.params == (wp.param1, wp.param2, wp.param3, wp.param4)
        assert item.autocontinue == bool(wp.autocontinue)
        if item.command == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            assert (item.lat_deg, item.lon_deg, item.alt_m) == (0.0, 0.0, 0.0)
            continue
        assert item.lat_deg == pytest.approx(wp.x, abs=deg)
        assert item.lon_deg == pytest.approx(wp.y, abs=deg)
        assert item.alt_m == pytest.approx(wp.z)


def ack_of(replies: list) -> int:
    (ack,) = replies
    assert ack.get_type() == "MISSION_ACK" and (ack.target_system, ack.target_component) == GCS
    return ack.type


@pytest.fixture
def loaded(wpl_file):
    """A server holding the file's mission."""
    wire, loader = Wire(), load(wpl_file)
    assert upload(wire, loader.wpoints).type == mavlink.MAV_MISSION_ACCEPTED
    return wire, loader


# ------------------------------------------------------------------ in memory
def test_upload_of_a_wpl_file_then_download_gives_it_back(wpl_file):
    wire, loader = Wire(), load(wpl_file)
    assert (wire.server.items, wire.server.version, wire.server.current) == ([], 0, 0)
    ack = upload(wire, loader.wpoints)
    assert ack.type == mavlink.MAV_MISSION_ACCEPTED and ack.mission_type == MISSION
    server = wire.server
    assert_matches_loader(server.items, loader)
    assert server.version == 1 and server.current == 1  # seq 0 is home, flying starts at 1
    assert not server.uploading

    downloaded = download(wire)
    assert [item_from_message(m) for m in downloaded] == server.items
    assert [m.current for m in downloaded] == [0, 1, 0, 0, 0, 0]
    assert server.version == 1  # a download changes nothing


def test_heights_above_home_follow_the_frame(loaded):
    wire, _ = loaded
    items = wire.server.items
    assert items[0].height_above_home(HOME_MSL_M) == pytest.approx(0.0)  # MSL frame
    assert items[1].height_above_home(HOME_MSL_M) == pytest.approx(120.0)  # relative frame
    assert items[4].height_above_home(HOME_MSL_M) == pytest.approx(150.0)
    assert items[5].height_above_home(HOME_MSL_M) is None  # RTL is not a place


def test_clear_all_empties_the_mission(loaded):
    wire, _ = loaded
    clear = mavlink.MAVLink_mission_clear_all_message(*VEHICLE, MISSION)
    assert ack_of(wire.send(clear)) == mavlink.MAV_MISSION_ACCEPTED
    assert (wire.server.items, wire.server.version, wire.server.current) == ([], 2, 0)
    assert download(wire) == []


def test_an_empty_mission_is_accepted_at_once(loaded):
    wire, _ = loaded
    count = mavlink.MAVLink_mission_count_message(*VEHICLE, 0, MISSION)
    assert ack_of(wire.send(count)) == mavlink.MAV_MISSION_ACCEPTED
    assert wire.server.items == [] and wire.server.version == 2
    msg = wire.server.current_message()
    assert (msg.seq, msg.total, msg.mission_state) == (0, 0xFFFF, mavlink.MISSION_STATE_NO_MISSION)


def test_an_upload_that_stops_half_way_times_out_and_keeps_the_old_mission(loaded):
    wire, loader = loaded
    before = list(wire.server.items)
    replies = wire.send(mavlink.MAVLink_mission_count_message(*VEHICLE, 4, MISSION))
    for seq in range(2):
        (request,) = replies
        assert request.get_type() == "MISSION_REQUEST_INT" and request.seq == seq
        replies = wire.send(as_int(loader.wp(seq)))
    assert wire.server.uploading
    # The station falls silent: item 2 is asked for again every second of simulated time,
    # `retries` times, then the upload is given up.
    assert wire.tick(0.9) == []
    repeats = []
    for _ in range(5):
        (again,) = wire.tick(0.2) + wire.tick(0.9)
        repeats.append((again.get_type(), again.seq))
    assert repeats == [("MISSION_REQUEST_INT", 2)] * 5
    assert ack_of(wire.tick(1.1)) == mavlink.MAV_MISSION_OPERATION_CANCELLED
    assert not wire.server.uploading
    assert wire.server.items == before and wire.server.version == 1
    # A late item is ignored; the mission still stands.
    assert wire.send(as_int(loader.wp(2))) == []
    assert wire.server.items == before


def test_an_unsupported_command_refuses_the_whole_upload(loaded):
    wire, loader = loaded
    before = list(wire.server.items)
    items = list(loader.wpoints)
    land = mavlink.MAVLink_mission_item_message(
        *VEHICLE, 3, 3, mavlink.MAV_CMD_NAV_LAND, 0, 1, 0, 0, 0, 0, 34.12, 108.83, 0, MISSION
    )
    items[3] = land
    assert upload(wire, items).type == mavlink.MAV_MISSION_UNSUPPORTED
    assert wire.server.items == before and wire.server.version == 1
    assert not wire.server.uploading


@pytest.mark.parametrize(
    ("change", "result"),
    [
        ({"x": math.nan}, mavlink.MAV_MISSION_INVALID_PARAM5_X),
        ({"y": math.nan}, mavlink.MAV_MISSION_INVALID_PARAM6_Y),
        ({"z": math.inf}, mavlink.MAV_MISSION_INVALID_PARAM7),
        ({"x": 91.0}, mavlink.MAV_MISSION_INVALID_PARAM5_X),
        ({"y": -180.5}, mavlink.MAV_MISSION_INVALID_PARAM6_Y),
        ({"param2": -math.inf}, mavlink.MAV_MISSION_INVALID_PARAM2),
        ({"frame": mavlink.MAV_FRAME_LOCAL_NED}, mavlink.MAV_MISSION_UNSUPPORTED_FRAME),
        ({"frame": mavlink.MAV_FRAME_MISSION}, mavlink.MAV_MISSION_UNSUPPORTED_FRAME),
        ({"frame": 200}, mavlink.MAV_MISSION_UNSUPPORTED_FRAME),
        ({"command": 60000}, mavlink.MAV_MISSION_UNSUPPORTED),
    ],
)
def test_a_bad_value_refuses_the_upload_with_its_reason(loaded, change, result):
    wire, loader = loaded
    before = list(wire.server.items)
    items = list(loader.wpoints)
    bad = items[2] = copy.copy(items[2])
    for field, value in change.items():
        setattr(bad, field, value)
    assert upload(wire, items, legacy=True).type == result
    assert wire.server.items == before and wire.server.version == 1


def test_a_loiter_without_its_time_is_refused_but_nan_means_default_elsewhere(wpl_file):
    wire, loader = Wire(), load(wpl_file)
    items = list(loader.wpoints)
    loiter = items[4] = copy.copy(items[4])
    loiter.param1 = math.nan  # the loiter's time: required
    assert upload(wire, items).type == mavlink.MAV_MISSION_INVALID_PARAM1
    loiter.param1, loiter.param3 = 30.0, math.nan  # its radius: NaN = the default radius
    waypoint = items[1] = copy.copy(items[1])
    waypoint.param4 = math.nan  # yaw, as QGroundControl sends it
    assert upload(wire, items).type == mavlink.MAV_MISSION_ACCEPTED
    assert math.isnan(wire.server.items[4].params[2])
    assert math.isnan(download(wire)[1].param4)


def test_int_coordinates_out_of_range_are_refused(loaded):
    wire, loader = loaded
    items = [as_int(wp) for wp in loader.wpoints]
    items[1].x = 2**31 - 1  # 214.7 degrees
    assert upload(wire, items, legacy=True).type == mavlink.MAV_MISSION_INVALID_PARAM5_X
    assert wire.server.version == 1


def test_a_hostile_count_is_refused_no_space(loaded):
    wire, _ = loaded
    count = mavlink.MAVLink_mission_count_message(*VEHICLE, 65535, MISSION)  # uint16 maximum
    assert ack_of(wire.send(count)) == mavlink.MAV_MISSION_NO_SPACE
    assert not wire.server.uploading and wire.server.version == 1
    # 10**6 cannot travel in MISSION_COUNT.count (uint16); a decoded message holding it anyway
    # (another dialect, a bug upstream) is refused the same way.
    huge = mavlink.MAVLink_mission_count_message(*VEHICLE, 10**6, MISSION)
    huge._header = mavlink.MAVLink_header(huge.id, srcSystem=GCS[0], srcComponent=GCS[1])
    assert wire.server.handle(huge, wire.now)
    assert ack_of(wire.replies()) == mavlink.MAV_MISSION_NO_SPACE
    assert not wire.server.uploading


def test_legacy_mission_item_and_mission_request(wpl_file):
    wire, loader = Wire(), load(wpl_file)
    assert upload(wire, loader.wpoints, legacy=True).type == mavlink.MAV_MISSION_ACCEPTED
    # MISSION_ITEM carries float32 degrees: within a few 1e-6 degrees (< 0.5 m)
    for item, wp in zip(wire.server.items[:5], loader.wpoints, strict=False):
        assert (item.lat_deg, item.lon_deg) == pytest.approx((wp.x, wp.y), abs=4e-6)
    downloaded = download(wire, legacy=True)  # answered with MISSION_ITEM_INT, as MAVLink asks
    for item, back in zip(wire.server.items, downloaded, strict=True):
        assert (back.x, back.y) == (round(item.lat_deg * 1e7), round(item.lon_deg * 1e7))
        assert back.command == item.command and back.z == item.alt_m


def test_items_out_of_sequence_are_asked_for_again(wpl_file):
    wire, loader = Wire(), load(wpl_file)
    wire.send(mavlink.MAVLink_mission_count_message(*VEHICLE, 6, MISSION))
    (request,) = wire.send(as_int(loader.wp(0)))
    assert request.seq == 1
    for wrong in (3, 0, 5):
        (again,) = wire.send(as_int(loader.wp(wrong)))
        assert (again.get_type(), again.seq) == ("MISSION_REQUEST_INT", 1)
    assert wire.server.items == [] and wire.server.uploading


def test_the_final_ack_is_repeated_when_the_last_item_comes_again(loaded):
    wire, loader = loaded
    assert ack_of(wire.send(as_int(loader.wp(5)))) == mavlink.MAV_MISSION_ACCEPTED
    assert wire.server.version == 1  # not a second mission


def test_one_upload_at_a_time(wpl_file):
    wire, loader = Wire(), load(wpl_file)
    other = mavlink.MAVLink(SimpleNamespace(write=wire._to_vehicle.append), 254, 190)
    wire.send(mavlink.MAVLink_mission_count_message(*VEHICLE, 6, MISSION))
    denied = wire.send(mavlink.MAVLink_mission_count_message(*VEHICLE, 2, MISSION), other)
    (ack,) = denied
    assert (ack.type, ack.target_system) == (mavlink.MAV_MISSION_DENIED, 254)
    assert upload(wire, loader.wpoints).type == mavlink.MAV_MISSION_ACCEPTED  # restarts
    assert len(wire.server.items) == 6


def test_fence_and_rally_are_empty_and_not_uploadable(loaded):
    wire, _ = loaded
    for kind in (mavlink.MAV_MISSION_TYPE_FENCE, mavlink.MAV_MISSION_TYPE_RALLY):
        (count,) = wire.send(mavlink.MAVLink_mission_request_list_message(*VEHICLE, kind))
        assert (count.count, count.mission_type) == (0, kind)
        (ack,) = wire.send(mavlink.MAVLink_mission_count_message(*VEHICLE, 3, kind))
        assert (ack.type, ack.mission_type) == (mavlink.MAV_MISSION_UNSUPPORTED, kind)
        (ack,) = wire.send(mavlink.MAVLink_mission_request_int_message(*VEHICLE, 0, kind))
        assert ack.type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    assert len(wire.server.items) == 6 and wire.server.version == 1


def test_a_request_beyond_the_mission_is_an_invalid_sequence(loaded):
    wire, _ = loaded
    request = mavlink.MAVLink_mission_request_int_message(*VEHICLE, 6, MISSION)
    assert ack_of(wire.send(request)) == mavlink.MAV_MISSION_INVALID_SEQUENCE


def test_partial_lists_are_refused_at_once(loaded):
    wire, _ = loaded
    partial = mavlink.MAVLink_mission_write_partial_list_message(*VEHICLE, 1, 2, MISSION)
    assert ack_of(wire.send(partial)) == mavlink.MAV_MISSION_UNSUPPORTED
    assert wire.server.version == 1


def test_current_item_set_reached_and_reported(loaded):
    wire, _ = loaded
    server = wire.server
    msg = server.current_message()
    assert (msg.seq, msg.total, msg.mission_state) == (1, 5, mavlink.MISSION_STATE_NOT_STARTED)

    (current,) = wire.send(mavlink.MAVLink_mission_set_current_message(*VEHICLE, 3))
    assert (current.get_type(), current.seq, current.total) == ("MISSION_CURRENT", 3, 5)
    assert server.current == 3
    (warning,) = wire.send(mavlink.MAVLink_mission_set_current_message(*VEHICLE, 9))
    assert warning.get_type() == "STATUSTEXT" and "9" in warning.text
    assert server.current == 3

    server.reached(3)
    server.set_current(4)
    reached, current = wire.replies()
    assert (reached.get_type(), reached.seq) == ("MISSION_ITEM_REACHED", 3)
    assert (current.seq, current.mission_state) == (4, mavlink.MISSION_STATE_ACTIVE)
    server.reached(5)
    assert server.current_message().mission_state == mavlink.MISSION_STATE_COMPLETE
    with pytest.raises(ValueError):
        server.set_current(6)


def test_the_vehicle_says_it_takes_int_missions():
    capabilities = autopilot_version().capabilities
    assert capabilities & mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT


def test_the_server_consumes_only_mission_messages():
    server = MissionServer(lambda msg: None)
    heartbeat = mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)
    assert not server.handle(heartbeat, 0.0)
    assert set(server._handlers) == set(MissionServer.MESSAGES)


_INT_RANGES = {
    "uint8_t": (0, 255),
    "uint16_t": (0, 0xFFFF),
    "int16_t": (-(2**15), 2**15 - 1),
    "int32_t": (-(2**31), 2**31 - 1),
    "uint32_t": (0, 2**32 - 1),
}
_EDGE_FLOATS = (math.nan, math.inf, -math.inf, 0.0, -1.0, 3.4e38, -3.4e38, 1e-45)


def _random_fields(msg_class, rng: random.Random) -> list:
    """Every field of `msg_class` filled with a value its wire type can carry, edge values
    (NaN, infinities, extremes) much more often than chance would give them."""
    values = []
    for kind in msg_class.fieldtypes:
        if kind == "float":
            values.append(rng.choice([*_EDGE_FLOATS, rng.uniform(-1e9, 1e9)]))
        else:
            lo, hi = _INT_RANGES[kind]
            values.append(rng.choice([lo, hi, 0, 1, rng.randint(lo, hi)]))
    return values


def test_no_field_value_makes_the_server_raise_or_grow(caplog):
    """Random and extreme values in every field of every mission message, as frames from two
    stations, with time passing: handle never raises and memory stays bounded."""
    rng = random.Random(28)
    wire = Wire(max_items=50)
    other = mavlink.MAVLink(SimpleNamespace(write=wire._to_vehicle.append), 7, 1)
    classes = [
        mavlink.mavlink_map[getattr(mavlink, f"MAVLINK_MSG_ID_{name}")]
        for name in MissionServer.MESSAGES
    ]
    for k in range(3000):
        cls = rng.choice(classes)
        msg = cls(*_random_fields(cls, rng))
        if cls.msgname == "MISSION_COUNT" and k % 3:
            msg.count = rng.randint(0, 60)  # let uploads start, so items meet one
        wire.send(msg, other if k % 5 == 0 else None)
        wire.tick(rng.choice([0.0, 0.3, 2.0]))
        assert len(wire.server.items) <= 50
        up = wire.server._upload
        assert up is None or len(up.received) <= up.count <= 50
    assert wire.server.version >= 1  # some uploads and clears went through
    # `handle` logs any exception it had to catch: there must be none to catch.
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR]


# ------------------------------------------------------------------ over loopback UDP
FRAME = LocalFrame(34.1230, 108.8370, HOME_MSL_M)
# The ground station every test's peer speaks as: the bridge hears no one else (issue 28).
GROUND_STATIONS = [(GCS[0], "127.0.0.1")]
WAIT_S = 20.0  # the longest any step below waits: a lost reply fails the test, never hangs it


class IdleSink:
    def command_ownship(self, **setpoint) -> None:
        pass

    def command_orbit(self, x: float, y: float, radius_m: float, clockwise: bool = True) -> None:
        pass


def ownship(t: float) -> TrafficState:
    """The ownship alone, cruising north at 120 m."""
    return TrafficState(
        t,
        ("ownship",),
        np.array([[0.0, 20.0 * t, 120.0]]),
        np.array([[0.0, 20.0, 0.0]]),
        np.zeros((1, 3)),
        np.full(1, 20.0),
    )


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def answer(bridge: MavlinkBridge, gcs, kinds: tuple[str, ...]):
    """The next message of one of `kinds` the ground station receives, polling the bridge
    (on simulated time = wall time since the call) meanwhile."""
    start = time.monotonic()
    while (elapsed := time.monotonic() - start) < WAIT_S:
        bridge.tick(bridge._now + elapsed if bridge._now is not None else elapsed)
        bridge.poll()
        msg = gcs.recv_match(type=list(kinds), blocking=False)
        if msg is not None:
            return msg
        time.sleep(0.002)
    raise AssertionError(f"no {kinds} within {WAIT_S} s")


def test_a_pymavlink_station_uploads_and_downloads_over_udp(wpl_file):
    port = free_port()
    bridge = MavlinkBridge(
        1, FRAME, IdleSink(), link=f"udpin:127.0.0.1:{port}", ground_stations=GROUND_STATIONS
    )
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=GCS[0], source_component=GCS[1]
    )
    try:
        loader = load(wpl_file)
        gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        gcs.mav.mission_count_send(*VEHICLE, loader.count(), MISSION)
        while (reply := answer(bridge, gcs, ("MISSION_REQUEST_INT", "MISSION_ACK"))).get_type() != (
            "MISSION_ACK"
        ):
            gcs.mav.send(as_int(loader.wp(reply.seq)))
        assert reply.type == mavlink.MAV_MISSION_ACCEPTED
        assert_matches_loader(bridge.missions.items, loader)

        gcs.mav.mission_request_list_send(*VEHICLE, MISSION)
        count = answer(bridge, gcs, ("MISSION_COUNT",)).count
        back = mavwp.MAVWPLoader()
        for seq in range(count):
            gcs.mav.mission_request_int_send(*VEHICLE, seq, MISSION)
            back.add(answer(bridge, gcs, ("MISSION_ITEM_INT",)))
        gcs.mav.mission_ack_send(*VEHICLE, mavlink.MAV_MISSION_ACCEPTED, MISSION)
        assert [item_from_message(m) for m in back.wpoints] == bridge.missions.items

        # The vehicle's telemetry says which item is current, once a second with the heartbeat.
        for k in range(21):
            bridge.publish(ownship(100.0 + k / 10))
        current = answer(bridge, gcs, ("MISSION_CURRENT",))
        assert (current.seq, current.total) == (1, 5)
    finally:
        gcs.close()
        bridge.close()


def test_a_station_broadcasting_an_upload_is_not_obeyed(wpl_file):
    """A write addressed to every system (target 0) is ignored; a read is answered."""
    port = free_port()
    bridge = MavlinkBridge(
        1, FRAME, IdleSink(), link=f"udpin:127.0.0.1:{port}", ground_stations=GROUND_STATIONS
    )
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=GCS[0], source_component=GCS[1]
    )
    try:
        gcs.mav.mission_count_send(0, 0, 3, MISSION)
        gcs.mav.mission_request_list_send(0, 0, MISSION)
        assert answer(bridge, gcs, ("MISSION_COUNT", "MISSION_REQUEST_INT")).count == 0
        assert not bridge.missions.uploading
        assert bridge.counters["ignored_other_target"] == 1
    finally:
        gcs.close()
        bridge.close()


# ------------------------------------------------------------------ with MAVProxy
MAVPROXY = shutil.which("mavproxy.py") or str(Path(sys.executable).parent / "mavproxy.py")


class MAVProxy:
    """MAVProxy as the ground station, listening on udpin. Commands go to its stdin, as an
    operator types them: `--cmd` runs before any vehicle is heard, so a `wp load` there goes
    nowhere (udpin knows no peer yet) and MAVProxy does not send it again."""

    def __init__(self, port: int, folder: Path) -> None:
        self.log_path = folder / "mavproxy.log"
        self._log = self.log_path.open("w")
        self.proc = subprocess.Popen(
            [
                sys.executable,
                MAVPROXY,
                f"--master=udpin:127.0.0.1:{port}",
                f"--state-basedir={folder}",
                "--default-modules=link,wp",
            ],
            stdin=subprocess.PIPE,
            stdout=self._log,
            stderr=subprocess.STDOUT,
            cwd=folder,
            env={**os.environ, "HOME": str(folder)},
            text=True,
        )

    def type(self, command: str) -> None:
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    @property
    def text(self) -> str:
        return self.log_path.read_text(errors="replace")

    def close(self) -> None:
        try:
            self.proc.stdin.close()  # end of input: MAVProxy exits
            self.proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            self.proc.kill()
            self.proc.wait()
        self._log.close()


def fly_until(
    bridge: MavlinkBridge,
    clock: list[float],
    done,
    what: str,
    gcs: MAVProxy,
    timeout_s: float = WAIT_S,
) -> None:
    """Publish and poll every 0.05 s of wall time (simulated time = wall time, since MAVProxy
    judges the link by its clock) until `done()`, at most `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, f"{what}: not within {timeout_s} s\n{gcs.text[-2000:]}"
        clock[0] += 0.05
        bridge.publish(ownship(clock[0]))
        bridge.poll()
        time.sleep(0.05)


@pytest.mark.gcs
@pytest.mark.skipif(not Path(MAVPROXY).exists(), reason="MAVProxy not installed (the `gcs` extra)")
def test_mavproxy_wp_load_list_save_set_and_clear(wpl_file, tmp_path):
    port = free_port()
    bridge = MavlinkBridge(
        1, FRAME, IdleSink(), link=f"udpout:127.0.0.1:{port}", command_timeout_s=600.0,
        ground_stations=GROUND_STATIONS,  # MAVProxy's system id is 255, as GCS's
    )  # fmt: skip
    gcs = MAVProxy(port, tmp_path)
    clock = [0.0]
    try:
        fly_until(bridge, clock, lambda: "online system 1" in gcs.text, "vehicle online", gcs)

        gcs.type(f"wp load {wpl_file}")
        fly_until(bridge, clock, lambda: bridge.missions.version == 1, "wp load", gcs)
        assert_matches_loader(bridge.missions.items, load(wpl_file))
        fly_until(bridge, clock, lambda: "TYPE_MISSION: ACCEPTED" in gcs.text, "the ACK", gcs)

        gcs.type("wp list")  # downloads, prints and saves to way.txt in the state folder
        fly_until(bridge, clock, lambda: "Saved waypoints to" in gcs.text, "wp list", gcs)
        assert "Requesting 6 waypoints" in gcs.text
        assert_matches_loader(bridge.missions.items, load(tmp_path / "way.txt"), deg=0.6e-6)

        saved = tmp_path / "saved.txt"
        gcs.type(f"wp save {saved}")
        fly_until(bridge, clock, lambda: f"Saved 6 waypoints to {saved}" in gcs.text, "save", gcs)
        # what the vehicle sent back, as MAVProxy writes it (6 decimals: 1e-6 degrees)
        assert_matches_loader(bridge.missions.items, load(saved), deg=0.6e-6)

        # `wp set` sends COMMAND_LONG DO_SET_MISSION_CURRENT first (MISSION_SET_CURRENT only
        # after an UNSUPPORTED): the ground station's aim, taken and acknowledged at once.
        bridge.take_operator_commands()
        gcs.type("wp set 3")
        fly_until(bridge, clock, lambda: bridge.missions.current == 3, "wp set", gcs)
        aims = [a for a in bridge.take_operator_commands() if a.kind == Kind.SET_CURRENT]
        assert [(a.seq, a.source) for a in aims] == [(3, GCS[0])]

        gcs.type("wp clear")
        fly_until(bridge, clock, lambda: bridge.missions.version == 2, "wp clear", gcs)
        assert bridge.missions.items == []
    finally:
        gcs.close()
        bridge.close()
