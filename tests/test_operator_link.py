"""Issue 28 end to end: a pymavlink ground station on loopback UDP commands the ownship while
it avoids a head-on intruder, uploads a mission from a waypoint file, or (not allowed)
tries to drive it. The episode flies through the real MAVLink path: the planner's commands
and the station's are bytes through the bridge."""

from __future__ import annotations

import math
import os
import socket

os.environ.setdefault("MAVLINK20", "1")

import numpy as np
import pytest
from head_on import GOAL, HEAD_ON
from pymavlink import mavutil, mavwp

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.scenario import default_scenario
from uavxai.sim.build import fly
from uavxai.sim.episode import Observer
from uavxai.sim.run import mavlink_path
from uavxai.sim.spec import episode_spec
from uavxai.vocabulary import Outcome

KEY_HEX = "5a" * 32
STATION = [{"system_id": 255, "address": "127.0.0.1"}]


def _port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class GroundStation(Observer):
    """A pymavlink ground station on 127.0.0.1: it listens where the bridge sends (udpout),
    answers from there, and at given times sends commands (``script``: t -> callable)."""

    def __init__(self, port: int, script: dict, system_id: int = 255, key: bytes | None = None):
        self.gcs = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=system_id, source_component=190
        )
        if key is not None:
            self.gcs.setup_signing(key, sign_outgoing=True)
        self.script = sorted(script.items())
        self.seen: list = []
        self.path: list[tuple[float, float, float, float]] = []
        self.planners: list[str] = []

    def on_sample(self, ep, state) -> None:
        while (m := self.gcs.recv_match(blocking=False)) is not None:
            if m.get_type() != "BAD_DATA":
                self.seen.append(m)
        self.path.append((state.t, *map(float, state.pos[0])))
        while self.script and self.script[0][0] <= state.t and self.seen:
            self.script.pop(0)[1](self.gcs.mav)

    def on_decision(self, ep, event) -> None:
        self.planners.append(event.decision.planner)

    def of_type(self, kind: str) -> list:
        return [m for m in self.seen if m.get_type() == kind]

    def close(self) -> None:
        self.gcs.close()


def speed_and_height(mav) -> None:
    mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_DO_CHANGE_SPEED, 0,
                          0, 22.0, -1, 0, 0, 0, 0)  # fmt: skip
    relative = mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT
    mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_DO_CHANGE_ALTITUDE, 0,
                          135.0, relative, 0, 0, 0, 0, 0)  # fmt: skip


def _fly(station: GroundStation | None, port: int, dynamics: str = "kinematic", **changes):
    sc = default_scenario("link", **{**HEAD_ON, **changes})
    planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
    observers = [station] if station else []
    path = mavlink_path(sc, f"udpout:127.0.0.1:{port}")
    spec = episode_spec(sc, goal=GOAL, dynamics=dynamics)
    return fly(spec, planner, path=path, observers=observers)


@pytest.mark.parametrize(
    ("signed", "dynamics"),
    [(False, "kinematic"), (True, "kinematic"), (True, "jsbsim")],
    ids=["allowed-peer", "signed", "signed-jsbsim"],
)
def test_operator_commands_during_a_head_on_encounter_leave_avoidance_on(
    signed: bool, dynamics: str
) -> None:
    """The issue's measured defect: one DO_CHANGE_SPEED (unsigned from anyone, or signed from
    the ground station) turned avoidance off and the encounter collided at 48-50 m."""
    port = _port()
    key = bytes.fromhex(KEY_HEX) if signed else None
    gcs = GroundStation(port, {4.0: speed_and_height}, key=key)
    bridge = {"signing_key_hex": KEY_HEX} if signed else {"ground_stations": STATION}
    r = _fly(gcs, port, dynamics, bridge=bridge)
    counters = r.summary["bridge"]
    assert counters["operator_commands"] == 2, counters
    assert r.outcome is Outcome.GOAL
    assert r.min_separation_m > 50.0
    assert counters["failsafe_events"] == 0
    assert len(gcs.planners) == r.steps and set(gcs.planners) == {"mcts_fast"}
    acks = [a for a in gcs.of_type("COMMAND_ACK") if a.target_system == 255]
    assert sorted(a.command for a in acks) == sorted(
        [mavutil.mavlink.MAV_CMD_DO_CHANGE_SPEED, mavutil.mavlink.MAV_CMD_DO_CHANGE_ALTITUDE]
    )
    assert all(a.result == mavutil.mavlink.MAV_RESULT_ACCEPTED for a in acks)
    # only the station's commands are acknowledged to it: none of the planner's own
    assert len(gcs.of_type("COMMAND_ACK")) == 2
    # the aim was flown once clear: height and speed at the end
    t, x, y, h = gcs.path[-1]
    assert abs(h - 135.0) < 3.0
    # the heartbeat names the mode for an ArduPilot ground station
    hb = gcs.of_type("HEARTBEAT")[-1]
    assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert mavutil.mode_string_v10(hb) == "AUTO"


def test_by_default_an_unknown_peers_command_changes_nothing() -> None:
    """No ground station listed, no key: a stranger's in-limits commands are refused and the
    flight is the same to the bit as the flight without it."""
    port = _port()
    clean = GroundStation(port, {})
    r0 = _fly(clean, port)
    clean.close()
    port = _port()
    stranger = GroundStation(port, {2.0: speed_and_height, 6.0: speed_and_height})
    r1 = _fly(stranger, port)
    assert r1.summary["bridge"]["refused_unknown_peer"] >= 4
    assert r1.summary["bridge"]["operator_commands"] == 0
    assert r0.steps == r1.steps and r0.outcome == r1.outcome
    assert np.array_equal(np.array(clean.path), np.array(stranger.path))
    assert not stranger.of_type("COMMAND_ACK")


WAYPOINTS = [  # (command, x, y, h, param1): item 0 is home, as ArduPilot's missions have it
    (16, 1000.0, 700.0, 0.0, 0.0),
    (16, 1300.0, 1100.0, 140.0, 0.0),
    (19, 1500.0, 1400.0, 150.0, 40.0),  # loiter 40 s
    (16, 1100.0, 1500.0, 130.0, 0.0),
    (20, 0.0, 0.0, 0.0, 0.0),  # RTL
]


def _waypoint_file(path, frame: LocalFrame) -> None:
    lines = ["QGC WPL 110"]
    for seq, (cmd, x, y, h, p1) in enumerate(WAYPOINTS):
        lat, lon, _ = frame.to_geodetic(x, y, 0.0) if cmd != 20 else (0.0, 0.0, 0.0)
        fr = 0 if seq == 0 else 3
        lines.append(f"{seq}\t{int(seq == 0)}\t{fr}\t{cmd}\t{p1}\t0\t0\t0\t{float(lat):.8f}\t"
                     f"{float(lon):.8f}\t{h}\t1")  # fmt: skip
    path.write_text("\n".join(lines) + "\n")


def test_a_mission_uploaded_from_a_waypoint_file_is_flown_and_reported(tmp_path) -> None:
    """The station uploads a QGC WPL file with the mission protocol, then AUTO: every item is
    flown, reported reached (MISSION_ITEM_REACHED), and RTL ends the flight at home."""
    sc0 = default_scenario("mission", **HEAD_ON)
    frame = LocalFrame.from_origin(sc0.world.origin)
    wp_file = tmp_path / "mission.txt"
    _waypoint_file(wp_file, frame)
    loader = mavwp.MAVWPLoader(target_system=1, target_component=1)
    loader.load(str(wp_file))
    assert loader.count() == len(WAYPOINTS)
    port = _port()
    state = {"n": 0}

    def upload(mav) -> None:
        mav.mission_count_send(1, 1, loader.count())

    def auto(mav) -> None:
        mav.command_long_send(1, 1, mavutil.mavlink.MAV_CMD_DO_SET_MODE, 0,
                              mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 10,
                              0, 0, 0, 0, 0)  # fmt: skip

    class Uploader(GroundStation):
        def on_sample(self, ep, st) -> None:
            super().on_sample(ep, st)
            for m in self.seen[state["n"]:]:
                if m.get_type() in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
                    item = loader.wp(m.seq)
                    self.gcs.mav.send(item)
            state["n"] = len(self.seen)

    gcs = Uploader(port, {1.0: upload, 5.0: auto})
    r = _fly(gcs, port, bridge={"ground_stations": STATION}, intruders={"count": 0},
             avoidance={"planner": "mcts_fast", "max_steps": 500})  # fmt: skip
    acks = gcs.of_type("MISSION_ACK")
    assert acks and acks[0].type == mavutil.mavlink.MAV_MISSION_ACCEPTED
    reached = [m.seq for m in gcs.of_type("MISSION_ITEM_REACHED")]
    assert reached == [1, 2, 3, 4], reached
    assert r.outcome is Outcome.COMPLETED
    assert r.summary["operator"]["mode_end"] == "AUTO"
    modes = {mavutil.mode_string_v10(h) for h in gcs.of_type("HEARTBEAT")}
    assert modes == {"AUTO"}
    current = [m.seq for m in gcs.of_type("MISSION_CURRENT")]
    assert {1, 2, 3, 4} <= set(current)
    # it flew over each waypoint and loitered near the loiter item
    pts = np.array([p[1:3] for p in gcs.path])
    for cmd, x, y, _, _ in WAYPOINTS[1:4]:
        closest = float(np.min(np.hypot(pts[:, 0] - x, pts[:, 1] - y)))
        assert closest < (160.0 if cmd == 19 else 60.0), (cmd, x, y, closest)
    assert math.isfinite(r.flight_time_s)


def test_the_runs_tlog_holds_every_frame_the_counters_count(tmp_path) -> None:
    """`uavxai run`'s link.tlog, read back with pymavlink: every frame decoded (the planner's,
    the station's) and every frame sent (telemetry, the ADS-B receiver's relayed reports,
    acknowledgements) is there, one stamped frame each, in time order."""
    port = _port()
    gcs = GroundStation(port, {3.0: speed_and_height})
    sc = default_scenario("tlog", **{**HEAD_ON, "surveillance": {"model": "adsb"}},
                          bridge={"ground_stations": STATION})  # fmt: skip
    planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
    tlog = tmp_path / "link.tlog"
    path = mavlink_path(sc, f"udpout:127.0.0.1:{port}", tlog)
    r = fly(episode_spec(sc, goal=GOAL, dynamics="kinematic"), planner, path=path, observers=[gcs])
    counters = r.summary["bridge"]
    log = mavutil.mavlink_connection(str(tlog))
    kinds: dict[str, int] = {}
    stamps = []
    while (m := log.recv_match()) is not None:
        assert m.get_type() != "BAD_DATA"
        kinds[m.get_type()] = kinds.get(m.get_type(), 0) + 1
        stamps.append(m._timestamp)
    log.close()
    assert sum(kinds.values()) == counters["messages_in"] + counters["messages_out"]
    assert kinds["ADSB_VEHICLE"] > 0 and kinds["SET_ATTITUDE_TARGET"] == r.steps
    assert kinds["COMMAND_ACK"] == 2 and kinds["HEARTBEAT"] >= r.flight_time_s - 1
    assert stamps == sorted(stamps)
    assert stamps[-1] - stamps[0] == pytest.approx(r.flight_time_s, abs=1.0)
