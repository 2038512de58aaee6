"""The bridge in front of the real JSBSim ownship: the onboard planner's MAVLink banks it while
a ground station over loopback UDP only sets aims (its setpoints are refused), silence triggers
the failsafe, unsigned commands are refused with a key, and a real MAVProxy ground station sees
the vehicle come online."""

from __future__ import annotations

import math
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

import pytest
from pymavlink import mavutil

from uavxai.bridges.bridge import MavlinkBridge
from uavxai.bridges.operator import SETPOINT_REFUSAL, Kind
from uavxai.bridges.protocol import CommandEncoder
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.world import JSBSimWorld
from uavxai.scenario import default_scenario

KEY = bytes(range(32))


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def make_world(**overrides) -> JSBSimWorld:
    settings = {
        "ownship": {"start": {"x": 1000, "y": 1000, "h": 150, "heading_deg": 0, "speed_mps": 20}},
        "intruders": {"count": 0},
        **overrides,
    }
    sc = default_scenario("bridge", **settings)
    return JSBSimWorld(sc, seed=0), sc


def fly(world: JSBSimWorld, bridge: MavlinkBridge, seconds: float) -> None:
    for _ in range(round(seconds / 0.1)):
        world.advance(0.1)
        bridge.poll()
        bridge.publish(world.state())


class Peer:
    """An offboard script / ground station: listens for the vehicle, then talks back."""

    def __init__(self, port: int, key: bytes | None = None) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        if key is not None:
            self.conn.setup_signing(key, sign_outgoing=True)

    def wait_heartbeat(self, world: JSBSimWorld, bridge: MavlinkBridge) -> None:
        for _ in range(50):
            fly(world, bridge, 0.1)
            if self.conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.05):
                return
        raise AssertionError("no heartbeat from the vehicle")

    def bank(self, target: int, bank_rad: float) -> None:
        q = [math.cos(bank_rad / 2), math.sin(bank_rad / 2), 0.0, 0.0]
        self.conn.mav.set_attitude_target_send(0, target, 1, 0b00000111 | 0b01000000, q, 0, 0, 0, 0)

    def climb(self, target: int, h: float) -> None:
        """MAVProxy's `alt`: DO_CHANGE_ALTITUDE to a height above home."""
        self.conn.mav.command_long_send(
            target, 1, mavutil.mavlink.MAV_CMD_DO_CHANGE_ALTITUDE, 0,
            h, mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 0, 0, 0, 0, 0,
        )  # fmt: skip

    def heard(self) -> list:
        """Everything received and not yet read."""
        got = []
        while (msg := self.conn.recv_match(blocking=False)) is not None:
            got.append(msg)
        return got

    def close(self) -> None:
        self.conn.close()


@pytest.mark.parametrize("signed", [False, True])
def test_the_planner_banks_the_jsbsim_ownship_and_a_ground_station_only_aims(signed: bool) -> None:
    world, sc = make_world()
    port = free_udp_port()
    peer = Peer(port, KEY if signed else None)
    bridge = MavlinkBridge(
        1,
        LocalFrame.from_origin(sc.world.origin),
        world,
        link=f"udpout:127.0.0.1:{port}",
        signing_key=KEY if signed else None,
        command_timeout_s=30.0,
        ground_stations=[(255, "127.0.0.1")],  # the peer's system and host
    )
    try:
        peer.wait_heartbeat(world, bridge)
        assert abs(math.degrees(world.state().att[0, 0])) < 2.0
        peer.heard()
        target_h = world.ownship_command()["alt_target_m"]

        # the ground station's bank is refused, its climb queued as an aim: JSBSim flies on
        peer.bank(1, math.radians(-25))
        peer.climb(1, 200.0)
        fly(world, bridge, 3.0)
        assert bridge.counters["operator_refused"] == 1
        assert bridge.counters["commands"] == 0
        assert world.ownship_command()["bank_cmd_rad"] == 0.0
        assert world.ownship_command()["alt_target_m"] == target_h
        assert abs(math.degrees(world.state().att[0, 0])) < 2.0
        [aim] = bridge.take_operator_commands()
        assert (aim.kind, aim.h) == (Kind.ALTITUDE, 200.0)
        heard = peer.heard()
        assert SETPOINT_REFUSAL[:50] in [m.text for m in heard if m.get_type() == "STATUSTEXT"]
        acks = [(m.command, m.result) for m in heard if m.get_type() == "COMMAND_ACK"]
        climb = mavutil.mavlink.MAV_CMD_DO_CHANGE_ALTITUDE
        assert acks == [(climb, mavutil.mavlink.MAV_RESULT_ACCEPTED)]

        # the onboard planner's bank, fed in process (signed like the link when there's a key)
        planner = CommandEncoder(1, 1, signing_key=KEY if signed else None)
        assert bridge.feed(planner.attitude(math.radians(20))) == 1
        fly(world, bridge, 4.0)
        assert bridge.counters["commands"] == 1
        assert world.ownship_command()["bank_cmd_rad"] == pytest.approx(math.radians(20))
        assert math.degrees(world.state().att[0, 0]) == pytest.approx(20.0, abs=3.0)
    finally:
        bridge.close()
        peer.close()
        world.close()


def test_unsigned_command_refused_with_a_key() -> None:
    world, sc = make_world()
    port = free_udp_port()
    peer = Peer(port, key=None)  # a peer without the key
    bridge = MavlinkBridge(
        1,
        LocalFrame.from_origin(sc.world.origin),
        world,
        link=f"udpout:127.0.0.1:{port}",
        signing_key=KEY,
        command_timeout_s=30.0,
    )
    try:
        peer.wait_heartbeat(world, bridge)
        peer.bank(1, math.radians(25))
        fly(world, bridge, 3.0)
        assert bridge.counters["refused_unsigned"] >= 1
        assert bridge.counters["operator_refused"] == 0  # refused unread, at the signature
        assert world.ownship_command()["bank_cmd_rad"] == 0.0
        assert abs(math.degrees(world.state().att[0, 0])) < 2.0
    finally:
        bridge.close()
        peer.close()
        world.close()


def test_command_silence_rolls_wings_level(caplog: pytest.LogCaptureFixture) -> None:
    """The planner banks the aircraft through MAVLink bytes, then falls silent: after the
    timeout the bridge commands wings level and JSBSim rolls out, holding speed and height."""
    world, sc = make_world()
    bridge = MavlinkBridge(1, LocalFrame.from_origin(sc.world.origin), world, command_timeout_s=2.0)
    encoder = CommandEncoder(1, 1)
    try:
        bridge.feed(encoder.encode(math.radians(20), 0.5))
        fly(world, bridge, 1.5)
        assert math.degrees(world.state().att[0, 0]) > 10
        with caplog.at_level("WARNING"):
            fly(world, bridge, 6.0)
        s = world.state()
        assert bridge.counters["failsafe_events"] == 1
        assert world.ownship_command()["bank_cmd_rad"] == 0.0
        assert world.ownship_command()["accel_cmd_mps2"] == 0.0
        assert abs(math.degrees(s.att[0, 0])) < 3.0
        assert abs(s.pos[0, 2] - 150) < 10
        assert any("wings level" in r.getMessage() for r in caplog.records)
    finally:
        bridge.close()
        world.close()


@pytest.mark.skipif(
    shutil.which("mavproxy.py") is None
    and not (Path(sys.executable).parent / "mavproxy.py").exists(),
    reason="MAVProxy not installed (the `gcs` extra)",
)
def test_mavproxy_sees_the_vehicle_online(tmp_path: Path) -> None:
    port = free_udp_port()
    mavproxy = shutil.which("mavproxy.py") or str(Path(sys.executable).parent / "mavproxy.py")
    world, sc = make_world(intruders={"count": 3, "min_start_distance_m": 200})
    bridge = MavlinkBridge(
        1,
        LocalFrame.from_origin(sc.world.origin),
        world,
        link=f"udpout:127.0.0.1:{port}",
        command_timeout_s=60.0,
        ground_stations=[(255, "127.0.0.1")],  # MAVProxy's system: its parameter requests
    )
    log = (tmp_path / "mavproxy.log").open("w")
    proc = subprocess.Popen(
        [
            sys.executable,
            mavproxy,
            f"--master=udpin:127.0.0.1:{port}",
            "--daemon",
            f"--state-basedir={tmp_path}",
            "--default-modules=link,adsb",
            f"--logfile={tmp_path / 'mav.tlog'}",
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        stdin=subprocess.DEVNULL,
        cwd=tmp_path,
        env={**os.environ, "HOME": str(tmp_path)},
    )
    text = ""
    try:
        deadline = time.monotonic() + 40
        while time.monotonic() < deadline:
            fly(world, bridge, 1.0)  # flown in real time: MAVProxy judges liveness by the clock
            time.sleep(0.9)
            text = (tmp_path / "mavproxy.log").read_text(errors="replace")
            if "online system 1" in text:
                break
        assert "Detected vehicle 1:1" in text, text[-2000:]
        assert "online system 1" in text, text[-2000:]
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
        bridge.close()
        world.close()
