"""Who the bridge hears and who hears it (issue 28): ground stations by (system, host), whose
commands become aims for the planner (never setpoints), peers bounded and expiring, nothing
for spoofed senders, and a flood that leaves the link as it was. Real UDP sockets on loopback
only (all of 127.0.0.0/8 is this machine on Linux)."""

from __future__ import annotations

import logging
import math
import socket
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from uavxai.bridges import CommandEncoder, MavlinkBridge
from uavxai.bridges.link import Link
from uavxai.bridges.operator import Kind
from uavxai.bridges.protocol import MessagePacker, new_codec
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState

FRAME = LocalFrame(34.1230, 108.8370, 400.0)
KEY = bytes.fromhex("3c" * 32)
GCS = 255
STATION = [(GCS, "127.0.0.1")]


class RecordingSink:
    def __init__(self) -> None:
        self.calls: list[dict] = []

    def command_ownship(self, **setpoint) -> None:
        self.calls.append(setpoint)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def peer_socket(host: str = "127.0.0.1") -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind((host, 0))
    return s


def received(sock: socket.socket, window_s: float = 0.2) -> list[bytes]:
    """Every datagram ``sock`` receives within ``window_s``."""
    got, deadline = [], time.monotonic() + window_s
    sock.settimeout(0.01)
    while time.monotonic() < deadline:
        try:
            got.append(sock.recv(65536))
        except TimeoutError:
            continue
    return got


def decoded(datagrams: list[bytes]) -> list:
    codec = new_codec(None, GCS, 190)
    return [m for d in datagrams for m in codec.parse_buffer(d) or []]


def speeds_aimed(bridge: MavlinkBridge) -> list[float]:
    """The speeds ground stations have asked for since the last call (the queued aims)."""
    aims = bridge.take_operator_commands()
    assert all(a.kind == Kind.SPEED for a in aims), aims
    return [a.speed_mps for a in aims]


def poll_until(bridge: MavlinkBridge, done, timeout_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        bridge.poll()
        assert time.monotonic() < deadline, "the bridge never received it"
        time.sleep(0.002)


def state(t: float) -> TrafficState:
    return TrafficState(
        t,
        ("ownship", "intruder-1"),
        np.array([[100.0 + 20 * t, 200.0, 120.0], [900.0 - 20 * t, 200.0, 120.0]]),
        np.array([[20.0, 0.0, 0.0], [-20.0, 0.0, 0.0]]),
        np.array([[0.0, 0.0, math.pi / 2], [0.0, 0.0, -math.pi / 2]]),
        np.full(2, 20.0),
    )


def heartbeat(system: int = GCS, key: bytes | None = None) -> bytes:
    gcs = mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID
    return MessagePacker(system, 190, key).pack(mavlink.MAVLink_heartbeat_message(*gcs, 0, 0, 0, 3))


def listening(**kwargs) -> tuple[MavlinkBridge, RecordingSink, tuple[str, int]]:
    port = free_port()
    sink = RecordingSink()
    bridge = MavlinkBridge(1, FRAME, sink, link=f"udpin:127.0.0.1:{port}", **kwargs)
    return bridge, sink, ("127.0.0.1", port)


# ------------------------------------------------------------------ the link's peers
def test_udpin_sends_to_nobody_until_a_peer_is_admitted():
    port = free_port()
    link = Link(f"udpin:127.0.0.1:{port}", 1)
    sender = peer_socket()
    try:
        sender.sendto(b"x", ("127.0.0.1", port))
        deadline = time.monotonic() + 2.0
        while (got := link.read()) is None:
            assert time.monotonic() < deadline
        assert got == (b"x", sender.getsockname())
        assert link.peers == [] and link.read() is None
        link.write(b"telemetry")
        assert received(sender, 0.1) == []
        link.admit(sender.getsockname())
        link.write(b"telemetry")
        assert received(sender) == [b"telemetry"]
    finally:
        link.close()
        sender.close()


def test_known_peers_expire_after_silence_and_hearing_them_refreshes():
    now = [100.0]
    port = free_port()
    link = Link(f"udpin:127.0.0.1:{port}", 1, peer_timeout_s=30.0, clock=lambda: now[0])
    sender = peer_socket()
    peer = sender.getsockname()
    try:
        link.admit(peer)
        now[0] = 129.0
        assert link.peers == [peer]
        sender.sendto(b"still here", ("127.0.0.1", port))
        deadline = time.monotonic() + 2.0
        while link.read() is None:
            assert time.monotonic() < deadline
        now[0] = 158.0  # 29 s after it was last heard
        assert link.peers == [peer]
        now[0] = 159.5
        assert link.peers == []
        link.write(b"telemetry")
        assert received(sender, 0.1) == []
    finally:
        link.close()
        sender.close()


def test_known_peers_are_bounded_least_recently_heard_evicted():
    port = free_port()
    link = Link(f"udpin:127.0.0.1:{port}", 1, max_peers=2)
    a, b, c = ("127.0.0.1", 40001), ("127.0.0.2", 40002), ("127.0.0.3", 40003)
    link.admit(a)
    link.admit(b)
    link.admit(a)  # heard again: b is now the least recently heard
    link.admit(c)
    assert sorted(link.peers) == [a, c]
    link.close()


def test_udpout_target_is_a_permanent_peer_and_strangers_are_only_heard():
    station, stranger = peer_socket(), peer_socket("127.0.0.2")
    link = Link(f"udpout:127.0.0.1:{station.getsockname()[1]}", 1, peer_timeout_s=0.01)
    try:
        assert link.peers == [station.getsockname()]
        link.write(b"hello")
        data, (_, our_port) = station.recvfrom(100)
        assert data == b"hello"
        stranger.sendto(b"me too", ("127.0.0.1", our_port))
        deadline = time.monotonic() + 2.0
        while (got := link.read()) is None:
            assert time.monotonic() < deadline
        assert got == (b"me too", stranger.getsockname())
        time.sleep(0.05)  # longer than the peer timeout: the target never expires
        link.write(b"again")
        assert received(station) == [b"again"] and received(stranger, 0.1) == []
    finally:
        link.close()
        station.close()
        stranger.close()


def test_udpbcast_talks_to_who_answers_bounded_and_broadcasts_again_when_they_fall_silent():
    # A unicast loopback target stands in for the broadcast address (same socket rules).
    now = [0.0]
    target = peer_socket()
    link = Link(
        f"udpbcast:127.0.0.1:{target.getsockname()[1]}", 1, max_peers=2, peer_timeout_s=10.0,
        clock=lambda: now[0],
    )  # fmt: skip
    answers = [peer_socket(f"127.0.0.{k}") for k in (11, 12, 13)]
    try:
        link.write(b"anyone?")
        data, (_, our_port) = target.recvfrom(100)
        assert data == b"anyone?"
        for k, peer in enumerate(answers):
            now[0] = float(k)
            peer.sendto(b"me", ("127.0.0.1", our_port))
            deadline = time.monotonic() + 2.0
            while link.read() is None:
                assert time.monotonic() < deadline
        assert sorted(link.peers) == sorted(p.getsockname() for p in answers[1:])
        link.write(b"to you")
        assert [received(p, 0.1) for p in answers] == [[], [b"to you"], [b"to you"]]
        assert received(target, 0.1) == []
        now[0] = 30.0  # all silent: broadcast again
        link.write(b"anyone?")
        assert received(target) == [b"anyone?"]
    finally:
        link.close()
        for s in (target, *answers):
            s.close()


def test_tcp_peers_are_the_connected_addresses():
    port = free_port()
    server = Link(f"tcpin:127.0.0.1:{port}", 1)
    client = Link(f"tcp:127.0.0.1:{port}", 255)
    try:
        assert client.peers == [("127.0.0.1", port)]
        client.write(b"hello")
        deadline = time.monotonic() + 2.0
        while (got := server.read()) is None:
            assert time.monotonic() < deadline
        data, peer = got
        assert data == b"hello" and server.peers == [peer] and peer[0] == "127.0.0.1"
    finally:
        client.close()
        server.close()


# ------------------------------------------------------------------ who commands
def test_without_a_key_or_ground_stations_nobody_on_the_link_commands(caplog):
    bridge, sink, address = listening()
    gcs = peer_socket()
    try:
        with caplog.at_level(logging.WARNING, logger="uavxai.bridges.bridge"):
            gcs.sendto(CommandEncoder(GCS, 1).change_speed(24.0), address)
            gcs.sendto(CommandEncoder(GCS, 1).change_speed(25.0), address)
            poll_until(bridge, lambda: bridge.counters["refused_unknown_peer"] == 2)
        assert sink.calls == [] and bridge.counters["messages_in"] == 0
        assert bridge.take_operator_commands() == []
        assert received(gcs, 0.1) == []  # not even an acknowledgement
        warnings = [r.getMessage() for r in caplog.records]
        assert len(warnings) == 1  # the first refusal only; the rest are counted
        assert "127.0.0.1" in warnings[0] and "bridge.ground_stations" in warnings[0]
    finally:
        bridge.close()
        gcs.close()


def test_a_listed_ground_station_is_obeyed_and_another_system_on_its_host_is_not():
    """Obeyed: its command is taken as an aim (queued for the planner) and acknowledged."""
    bridge, sink, address = listening(ground_stations=STATION)
    gcs = peer_socket()
    try:
        gcs.sendto(CommandEncoder(GCS, 1).change_speed(24.0), address)
        poll_until(bridge, lambda: bridge.counters["operator_commands"])
        assert speeds_aimed(bridge) == [pytest.approx(24.0)]
        assert sink.calls == []  # an aim, never a setpoint
        acks = [m for m in decoded(received(gcs)) if m.get_type() == "COMMAND_ACK"]
        assert [a.result for a in acks] == [mavlink.MAV_RESULT_ACCEPTED]

        impostor = peer_socket()  # the same host, another system id
        impostor.sendto(CommandEncoder(GCS - 1, 1).change_speed(13.0), address)
        poll_until(bridge, lambda: bridge.counters["refused_unknown_peer"] == 1)
        assert speeds_aimed(bridge) == [] and bridge.counters["operator_commands"] == 1
        assert received(impostor, 0.1) == []
        impostor.close()
    finally:
        bridge.close()
        gcs.close()


def test_on_udpin_only_the_admitted_station_receives_telemetry():
    bridge, _, address = listening(ground_stations=STATION)
    gcs = peer_socket()
    garbage, stranger, impostor = peer_socket("127.0.0.5"), peer_socket("127.0.0.6"), peer_socket()
    try:
        garbage.sendto(b"\xfd\x09garbage" * 3, address)
        stranger.sendto(CommandEncoder(GCS, 1).change_speed(24.0), address)
        stranger.sendto(heartbeat(), address)
        impostor.sendto(heartbeat(GCS - 1), address)
        poll_until(bridge, lambda: bridge.counters["refused_unknown_peer"] >= 4)
        gcs.sendto(heartbeat(), address)
        poll_until(bridge, lambda: bridge.counters["messages_in"] >= 2)
        for k in range(5):
            bridge.publish(state(k / 10))
        kinds = {m.get_type() for m in decoded(received(gcs))}
        assert {"HEARTBEAT", "GLOBAL_POSITION_INT", "ADSB_VEHICLE"} <= kinds
        for outsider in (garbage, stranger, impostor):
            assert received(outsider, 0.1) == []
        assert bridge._link.peers == [gcs.getsockname()]
    finally:
        for s in (gcs, garbage, stranger, impostor):
            s.close()
        bridge.close()


def test_with_a_key_a_signed_peer_is_admitted_and_obeyed_an_unsigned_one_is_not_answered():
    bridge, sink, address = listening(signing_key=KEY)
    signed, unsigned = peer_socket("127.0.0.7"), peer_socket("127.0.0.8")
    try:
        unsigned.sendto(heartbeat(), address)
        unsigned.sendto(CommandEncoder(GCS, 1).change_speed(20.0), address)
        signed.sendto(CommandEncoder(GCS, 1, signing_key=KEY).change_speed(24.0), address)
        poll_until(bridge, lambda: bridge.counters["operator_commands"])
        poll_until(bridge, lambda: bridge.counters["refused_unsigned"] == 1)
        assert speeds_aimed(bridge) == [pytest.approx(24.0)] and sink.calls == []
        assert bridge.counters["refused_unknown_peer"] == 1  # the unsigned heartbeat
        bridge.publish(state(0.0))
        kinds = [m.get_type() for m in decoded(received(signed))]
        assert "HEARTBEAT" in kinds and "COMMAND_ACK" in kinds
        assert received(unsigned, 0.1) == []
    finally:
        bridge.close()
        signed.close()
        unsigned.close()


def test_with_a_key_and_ground_stations_a_signed_command_must_also_come_from_one():
    bridge, sink, address = listening(signing_key=KEY, ground_stations=STATION)
    listed, elsewhere = peer_socket(), peer_socket("127.0.0.9")
    try:
        elsewhere.sendto(CommandEncoder(GCS, 1, signing_key=KEY).change_speed(15.0), address)
        poll_until(bridge, lambda: bridge.counters["refused_unknown_peer"] == 1)
        assert received(elsewhere, 0.1) == []  # refused: not even acknowledged
        assert speeds_aimed(bridge) == []
        listed.sendto(CommandEncoder(GCS, 1, signing_key=KEY).change_speed(24.0), address)
        poll_until(bridge, lambda: bridge.counters["operator_commands"])
        assert speeds_aimed(bridge) == [pytest.approx(24.0)] and sink.calls == []
    finally:
        bridge.close()
        listed.close()
        elsewhere.close()


def test_a_replayed_signed_command_on_the_link_is_counted_as_a_replay():
    bridge, sink, address = listening(signing_key=KEY, ground_stations=STATION)
    gcs = peer_socket()
    frame = CommandEncoder(GCS, 1, signing_key=KEY).change_speed(24.0)
    try:
        gcs.sendto(frame, address)
        gcs.sendto(frame, address)
        poll_until(bridge, lambda: bridge.counters["refused_replay"] == 1)
        assert bridge.counters["refused_bad_signature"] == 0
        assert speeds_aimed(bridge) == [pytest.approx(24.0)] and sink.calls == []
    finally:
        bridge.close()
        gcs.close()


def test_the_planners_feed_needs_no_ground_station():
    bridge, sink, _ = listening()
    assert bridge.feed(CommandEncoder(1, 1).encode(0.2, 0.0)) == 2
    assert sink.calls == [{"bank_cmd_rad": pytest.approx(0.2)}, {"accel_cmd_mps2": 0.0}]
    assert bridge.counters["refused_unknown_peer"] == 0
    bridge.close()


# ------------------------------------------------------------------ a flood of spoofed senders
def test_a_flood_from_many_addresses_leaves_the_peers_bounded_and_the_station_obeyed():
    """Issue 28: one byte from each of 20,000 spoofed (address, port) pairs. pymavlink's udpin
    kept them all as clients and sent every frame to each; here none of them is a peer."""
    bridge, sink, address = listening(ground_stations=STATION)
    gcs = peer_socket()
    gcs.sendto(heartbeat(), address)
    poll_until(bridge, lambda: bridge.counters["messages_in"] == 1)
    link = bridge._link
    sent = 0
    try:
        for k in range(20_000):
            # 500 addresses 127.0.1.0 .. 127.0.2.243, each with 40 ports
            host = f"127.0.{1 + (k % 500) // 256}.{(k % 500) % 256}"
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                s.bind((host, 0))
                s.sendto(b"\x00", address)
            sent += 1
            if k % 200 == 199:
                bridge.poll()
                assert len(link.peers) <= 8
        bridge.poll()
        bridge.publish(state(0.0))
        assert len(link.peers) <= 8 and link.peers == [gcs.getsockname()]
        # most of the flood reached the bridge and was refused unread
        assert bridge.counters["refused_unknown_peer"] > sent // 2
        assert bridge.counters["malformed"] == 0
        assert any(m.get_type() == "HEARTBEAT" for m in decoded(received(gcs)))
        gcs.sendto(CommandEncoder(GCS, 1).change_speed(22.0), address)
        poll_until(bridge, lambda: bridge.counters["operator_commands"])
        assert speeds_aimed(bridge) == [pytest.approx(22.0)] and sink.calls == []
    finally:
        bridge.close()
        gcs.close()
