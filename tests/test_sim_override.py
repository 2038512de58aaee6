"""An operator on the ground station takes command, and hands it back after the override time."""

from __future__ import annotations

import os
import socket

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.scenario import default_scenario
from uavxai.sim.build import fly
from uavxai.sim.episode import Observer
from uavxai.sim.run import mavlink_path
from uavxai.vocabulary import Outcome


def _port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Operator(Observer):
    """MAVProxy's `alt 220`: a DO_CHANGE_ALTITUDE from the ground station at t = 10 s."""

    def __init__(self, port: int) -> None:
        self.gcs = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.sent = False
        self.heights: list[tuple[float, float, str]] = []

    def on_sample(self, ep, state) -> None:
        while self.gcs.recv_match(blocking=False):
            pass  # learn the vehicle's address, drop telemetry
        if not self.sent and state.t >= 10.0:
            self.gcs.mav.command_long_send(
                1, 1, mavutil.mavlink.MAV_CMD_DO_CHANGE_ALTITUDE, 0,
                220.0, mavutil.mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, 0, 0, 0, 0, 0,
            )  # fmt: skip
            self.sent = True

    def on_decision(self, ep, event) -> None:
        self.heights.append((event.t, float(event.truth.pos[0, 2]), event.decision.planner))

    def close(self) -> None:
        self.gcs.close()


def test_an_operator_override_holds_for_its_time_and_is_handed_back() -> None:
    sc = default_scenario(
        "override",
        intruders={"count": 0},
        ownship={"goal": [1900, 1900, 120]},
        avoidance={"max_steps": 150},
        log={"rerun": False},
        bridge={"ground_stations": [[255, "127.0.0.1"]]},  # the operator's station
    )
    port = _port()
    op = Operator(port)
    planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
    build = mavlink_path(sc, f"udpout:127.0.0.1:{port}")

    def path(world):
        p = build(world)
        p.override_s = 20.0
        return p

    r = fly(sc, planner, (1900, 1900, 120), dynamics="kinematic", path=path, observers=[op])
    assert op.sent
    advised = [t for t, _, who in op.heights if "operator in command" in who]
    assert advised and 10.0 <= advised[0] <= 11.5 and 29.0 <= advised[-1] <= 31.5
    peak = max(h for _, h, _ in op.heights)
    assert peak > 150.0  # the operator's climb was flown
    assert r.outcome is Outcome.GOAL  # handed back: the mission's height and goal again
    assert r.summary["bridge"]["commands"] > r.steps
