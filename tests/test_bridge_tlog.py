"""The bridge's telemetry log: every frame in and out, readable by pymavlink as a .tlog."""

from __future__ import annotations

import math
import socket
import struct
import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mavlink

from uavxai.bridges import CommandEncoder, MavlinkBridge
from uavxai.bridges.tlog import TlogWriter
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.errors import UserError

FRAME = LocalFrame(34.1230, 108.8370, 400.0)
GCS = 255


class Sink:
    def command_ownship(self, **setpoint) -> None:
        pass


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def state(t: float) -> TrafficState:
    return TrafficState(
        t,
        ("ownship", "intruder-1"),
        np.array([[100.0 + 20 * t, 200.0, 120.0], [900.0 - 20 * t, 200.0, 120.0]]),
        np.array([[20.0, 0.0, 0.0], [-20.0, 0.0, 0.0]]),
        np.array([[0.0, 0.0, math.pi / 2], [0.0, 0.0, -math.pi / 2]]),
        np.full(2, 20.0),
    )


def read_tlog(path) -> list:
    log = mavutil.mavlink_connection(str(path))
    messages = []
    while (msg := log.recv_match()) is not None:
        messages.append(msg)
    log.close()
    return messages


def test_tlog_frames_are_stamped_big_endian_microseconds(tmp_path):
    path = tmp_path / "a.tlog"
    with TlogWriter(path, t0_unix_s=1_700_000_000.25) as tlog:
        tlog.write(1.5, b"\xfd\x01\x02")
    data = path.read_bytes()
    assert struct.unpack(">Q", data[:8])[0] == 1_700_000_001_750_000
    assert data[8:] == b"\xfd\x01\x02"


def test_a_runs_frames_in_and_out_are_all_in_the_tlog_in_order(tmp_path):
    path = tmp_path / "run.tlog"
    port = free_port()
    started = time.time()
    bridge = MavlinkBridge(
        1, FRAME, Sink(), link=f"udpin:127.0.0.1:{port}", ground_stations=[(GCS, "127.0.0.1")],
        tlog=path,
    )  # fmt: skip
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=GCS, source_component=190
    )
    planner = CommandEncoder(1, 1)
    try:
        gcs.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        for k in range(30):  # three simulated seconds
            t = k / 10
            bridge.feed(planner.encode(0.1, 0.0, t))
            if k == 15:  # the planner's own command: flown, not acknowledged on the link
                bridge.feed(planner.change_speed(21.0))
            if k == 10:
                gcs.mav.param_request_list_send(1, 1)
            if k == 20:
                gcs.mav.command_long_send(
                    1, 1, mavlink.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 22.0, -1, 0, 0, 0, 0
                )
            deadline = time.monotonic() + 2.0
            expected = {0: 1, 10: 1, 20: 1}.get(k, 0)
            before = bridge.counters["messages_in"]
            while True:
                bridge.poll()
                if bridge.counters["messages_in"] >= before + expected:
                    break
                assert time.monotonic() < deadline, "the ground station's frame never came"
                time.sleep(0.002)
            bridge.publish(state(t))
            while gcs.recv_match(blocking=False) is not None:
                pass
    finally:
        bridge.close()
        gcs.close()
    c = bridge.counters
    assert c["param_requests"] == 1 and c["commands"] == 61  # the planner's 60 + 1
    assert c["operator_commands"] == 1  # the station's DO_CHANGE_SPEED: an aim
    assert c["messages_in"] == 61 + 3  # the planner's frames, the station's three
    messages = read_tlog(path)
    assert len(messages) == c["messages_in"] + c["messages_out"]
    stamps = [m._timestamp for m in messages]
    assert stamps == sorted(stamps)
    assert started - 1 <= stamps[0] and stamps[-1] <= started + 3.0 + 1
    kinds = {m.get_type() for m in messages}
    assert {"SET_ATTITUDE_TARGET", "PARAM_VALUE", "COMMAND_ACK", "GLOBAL_POSITION_INT"} <= kinds
    # both DO_CHANGE_SPEEDs are in, the one acknowledgement (the station's) is out
    speeds = [m for m in messages if m.get_type() == "COMMAND_LONG"]
    assert [(m.get_srcSystem(), m.param2) for m in speeds] == [(1, 21.0), (GCS, 22.0)]
    [ack] = [m for m in messages if m.get_type() == "COMMAND_ACK"]
    assert (ack.target_system, ack.result) == (GCS, mavlink.MAV_RESULT_ACCEPTED)


def test_an_existing_tlog_is_never_overwritten(tmp_path):
    path = tmp_path / "run.tlog"
    path.write_bytes(b"an earlier run")
    with pytest.raises(UserError, match="run.tlog"):
        MavlinkBridge(1, FRAME, Sink(), link=f"udpin:127.0.0.1:{free_port()}", tlog=path)
    assert path.read_bytes() == b"an earlier run"
