"""Cost of the MAVLink bridge per simulated second: the planner's commands encoded and decoded
once per second, telemetry published every 0.1 s to a UDP ground station on 127.0.0.1, with 20
intruders as ADS-B. Prints numbers; asserts nothing.

    .venv/bin/python benchmarks/performance/bench_bridge.py [--intruders 20] [--sim-seconds 300]
"""

from __future__ import annotations

import argparse
import math
import socket
import time

import numpy as np

from uavxai.bridges import CommandEncoder, MavlinkBridge
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState

PUBLISH_PERIOD_S = 0.1
DECISION_PERIOD_S = 1.0


class NullSink:
    def command_ownship(self, **_setpoint) -> None:
        pass


def traffic(t: float, intruders: int) -> TrafficState:
    n = intruders + 1
    angle = np.linspace(0.0, 2 * math.pi, n)
    pos = np.column_stack(
        [1000 + 500 * np.cos(angle + 0.02 * t), 1000 + 500 * np.sin(angle), 120 + angle]
    )
    vel = np.column_stack([-10 * np.sin(angle), 10 * np.cos(angle), np.zeros(n)])
    att = np.column_stack([np.full(n, 0.2), np.zeros(n), angle])
    ids = ("ownship", *(f"intruder-{k}" for k in range(1, n)))
    return TrafficState(t, ids, pos, vel, att, np.full(n, 20.0))


def run(intruders: int, sim_seconds: float, signing_key: bytes | None) -> dict[str, float]:
    drain = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    drain.bind(("127.0.0.1", 0))
    drain.setblocking(False)
    port = drain.getsockname()[1]
    bridge = MavlinkBridge(
        1,
        LocalFrame(34.123, 108.837, 400.0),
        NullSink(),
        link=f"udpout:127.0.0.1:{port}",
        signing_key=signing_key,
    )
    encoder = CommandEncoder(255, 1, signing_key=signing_key)
    states = [
        traffic(k * PUBLISH_PERIOD_S, intruders) for k in range(int(sim_seconds / PUBLISH_PERIOD_S))
    ]
    per_decision = round(DECISION_PERIOD_S / PUBLISH_PERIOD_S)

    publish_s = command_s = 0.0
    received = 0
    for k, state in enumerate(states):
        if k % per_decision == 0:
            start = time.perf_counter()
            bridge.feed(encoder.encode(0.1 * math.sin(k), 0.5, state.t))
            command_s += time.perf_counter() - start
        start = time.perf_counter()
        bridge.publish(state)
        publish_s += time.perf_counter() - start
        while True:  # the ground station's side, not timed
            try:
                drain.recv(2048)
                received += 1
            except BlockingIOError:
                break
    bridge.close()
    drain.close()
    decisions = math.ceil(len(states) / per_decision)
    return {
        "messages_out_per_sim_s": bridge.counters["messages_out"] / sim_seconds,
        "received_fraction": received / max(bridge.counters["messages_out"], 1),
        "us_per_publish": 1e6 * publish_s / len(states),
        "us_per_decision_encode_decode": 1e6 * command_s / decisions,
        "ms_per_sim_s": 1e3 * (publish_s + command_s) / sim_seconds,
        "us_per_message": 1e6 * publish_s / bridge.counters["messages_out"],
        "commands_obeyed": bridge.counters["commands"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--intruders", type=int, default=20)
    parser.add_argument("--sim-seconds", type=float, default=300.0)
    args = parser.parse_args()
    print(
        f"bridge cost, {args.intruders} intruders, {args.sim_seconds:.0f} s simulated, "
        f"publish every {PUBLISH_PERIOD_S} s, one decision per {DECISION_PERIOD_S} s"
    )
    for label, key in (("unsigned", None), ("signed", bytes(range(32)))):
        r = run(args.intruders, args.sim_seconds, key)
        print(
            f"  {label:8s} {r['messages_out_per_sim_s']:6.1f} msg per sim-s | "
            f"{r['us_per_publish']:7.1f} us/publish | {r['us_per_message']:5.1f} us/msg | "
            f"{r['us_per_decision_encode_decode']:6.1f} us/decision (encode+decode) | "
            f"{r['ms_per_sim_s']:5.2f} ms per sim-s (bridge alone: "
            f"{1000 / r['ms_per_sim_s']:.0f}x real time) | "
            f"received {100 * r['received_fraction']:.1f}%"
        )


if __name__ == "__main__":
    main()
