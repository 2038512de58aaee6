"""Speed of one MAVLink episode, clean and under a flood of spoofed datagrams (issue 28).

The episode is flown in JSBSim through the MAVLink path (`uavxai.sim.run.mavlink_path`) with
a ``udpin`` link and one listed ground station on 127.0.0.1 that says hello once a simulated
second and reads its telemetry. In the flooded run a separate process sends 20,000 one-byte
datagrams, each from its own (address, port) in 127.0.1.0-127.0.2.243 (500 addresses, all
loopback on Linux), starting when the episode starts. With pymavlink's ``udpin`` every such
sender became a client for the rest of the run and received every telemetry frame (the run
fell from 5-8x real time to 0.08x); here they are refused unread and never become peers.

Prints the real-time factor of both runs (best of ``--repeats``, alternating so both see the
same machine load), their ratio (goal: the flooded run within 10 % of the clean one), and what
the bridge counted. The attacker runs on the same cores here (on a 2-core machine its ~1 s of
sending competes with the run), so the user CPU seconds of the simulator's own process (least
of the repeats) are printed as well, and the cost of one refused datagram measured alone: those
are the bridge's cost of the flood without the attacker's.

    .venv/bin/python benchmarks/performance/bench_link_flood.py [--intruders 3] [--steps 120]
        [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import time

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("JSBSIM_DEBUG", "0")

from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from uavxai.avoidance.planners import make_planner  # noqa: E402
from uavxai.avoidance.types import PlannerConfig  # noqa: E402
from uavxai.bridges.protocol import MessagePacker  # noqa: E402
from uavxai.scenario import default_scenario  # noqa: E402
from uavxai.sim.build import fly  # noqa: E402
from uavxai.sim.episode import Observer  # noqa: E402
from uavxai.sim.run import mavlink_path  # noqa: E402
from uavxai.sim.spec import episode_spec  # noqa: E402

GCS_SYSTEM = 255
FLOOD_DATAGRAMS = 20_000
FLOOD_ADDRESSES = 500


# The attacker, a separate small process (no uavxai imports: it starts in milliseconds and
# takes nothing from the run but its CPU): ready, wait for "go", then one byte from each of
# COUNT distinct (address, port) pairs, then the seconds it took.
FLOOD = """
import socket, sys, time
port, count, addresses = (int(a) for a in sys.argv[1:4])
print("ready", flush=True)
sys.stdin.readline()
t0 = time.perf_counter()
for k in range(count):
    n = k % addresses
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((f"127.0.{1 + n // 256}.{n % 256}", 0))
        s.sendto(b"\\x00", ("127.0.0.1", port))
print(time.perf_counter() - t0, flush=True)
"""


class GroundStation(Observer):
    """The allowed station: a heartbeat every simulated second, telemetry read and dropped.
    Starts the flood (if any) when the episode starts."""

    def __init__(self, port: int, attacker: subprocess.Popen | None = None) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.setblocking(False)
        self.port, self.attacker = port, attacker
        kinds = mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID
        hello = mavlink.MAVLink_heartbeat_message(*kinds, 0, 0, 0, 3)
        self.hello = MessagePacker(GCS_SYSTEM, 190).pack(hello)
        self.next_hello, self.received = 0.0, 0

    def on_start(self, ep) -> None:
        if self.attacker is not None:
            self.attacker.stdin.write("go\n")
            self.attacker.stdin.flush()

    def on_sample(self, ep, state) -> None:
        if state.t >= self.next_hello:
            self.sock.sendto(self.hello, ("127.0.0.1", self.port))
            self.next_hello = state.t + 1.0
        while True:
            try:
                self.sock.recv(65536)
            except BlockingIOError:
                return
            self.received += 1

    def close(self) -> None:
        self.sock.close()


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def one_run(sc, flooded: bool) -> tuple[float, float, dict, int, float | None]:
    """(real-time factor, CPU s of this process (user + system: the kernel's work on every
    datagram read is the system part), bridge counters, datagrams the station received,
    seconds the flood took to send)."""
    port = free_port()
    attacker = None
    if flooded:
        attacker = subprocess.Popen(
            [sys.executable, "-c", FLOOD, str(port), str(FLOOD_DATAGRAMS), str(FLOOD_ADDRESSES)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert attacker.stdout.readline().strip() == "ready"
    station = GroundStation(port, attacker)
    planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
    flood_s = None
    t0 = os.times()
    cpu0 = t0.user + t0.system
    try:
        r = fly(
            episode_spec(sc, goal=tuple(sc.ownship.goal), dynamics="jsbsim"),
            planner,
            path=mavlink_path(sc, f"udpin:127.0.0.1:{port}"),
            observers=[station],
        )
        t1 = os.times()
        cpu = t1.user + t1.system - cpu0  # set-up included; the attacker's CPU not
    finally:
        if attacker is not None:
            out, _ = attacker.communicate(timeout=60)
            flood_s = float(out.split()[-1]) if out.strip() else None
    return r.summary["sim_realtime_factor"], cpu, r.summary["bridge"], station.received, flood_s


def refusal_cost_us(datagrams: int = 5000) -> float:
    """Microseconds of the bridge's poll per spoofed datagram (read and refused unread),
    measured alone: 50 senders on 127.0.1.x, then one timed drain."""
    from uavxai.bridges import MavlinkBridge
    from uavxai.dynamics.geodesy import LocalFrame

    class Sink:
        def command_ownship(self, **setpoint) -> None: ...

    port = free_port()
    bridge = MavlinkBridge(
        1, LocalFrame(34.1, 108.8, 400.0), Sink(), link=f"udpin:127.0.0.1:{port}",
        ground_stations=[(GCS_SYSTEM, "127.0.0.1")],
    )  # fmt: skip
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(50)]
    try:
        for k, s in enumerate(senders):
            s.bind((f"127.0.1.{k}", 0))
            for _ in range(datagrams // len(senders)):
                s.sendto(b"\x00", ("127.0.0.1", port))
        t0 = time.perf_counter()
        while bridge.counters["refused_unknown_peer"] < datagrams:
            bridge.poll()
        return (time.perf_counter() - t0) / datagrams * 1e6
    finally:
        bridge.close()
        for s in senders:
            s.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--intruders", type=int, default=3)
    ap.add_argument("--steps", type=int, default=120, help="decisions per run")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many")
    args = ap.parse_args()
    sc = default_scenario(
        "bench-link-flood",
        intruders={"count": args.intruders},
        ownship={"goal": [1900, 1900, 120]},  # far: every run flies all its decisions
        avoidance={"max_steps": args.steps},
        bridge={"ground_stations": [{"system_id": GCS_SYSTEM, "address": "127.0.0.1"}]},
        log={"rerun": False},
    )
    best: dict[str, tuple[float, float, dict, int, float | None]] = {}
    least_cpu: dict[str, float] = {}
    for _ in range(args.repeats):
        for label, flooded in (("clean", False), ("flooded", True)):
            run = one_run(sc, flooded)
            if label not in best or run[0] > best[label][0]:
                best[label] = run
            least_cpu[label] = min(least_cpu.get(label, float("inf")), run[1])
    print(
        f"{args.intruders} intruders, {args.steps} decisions in JSBSim over a udpin link, "
        f"best of {args.repeats}"
    )
    for label, (rtf, _, counters, received, flood_s) in best.items():
        extra = ""
        if label == "flooded":
            extra = (
                f"\n           {FLOOD_DATAGRAMS} one-byte datagrams from {FLOOD_ADDRESSES} "
                f"addresses sent in {flood_s or float('nan'):.2f} s; the bridge refused "
                f"{counters['refused_unknown_peer']} unread "
                f"({FLOOD_DATAGRAMS - counters['refused_unknown_peer']} overflowed its socket)"
            )
        print(
            f"  {label:<8} {rtf:6.2f}x real time, {least_cpu[label]:5.2f} CPU s (user + system, "
            f"the simulator's process); the station received {received} datagrams, "
            f"messages_out {counters['messages_out']}{extra}"
        )
    ratio = best["flooded"][0] / best["clean"][0]
    extra_cpu = least_cpu["flooded"] - least_cpu["clean"]
    cpu_ratio = least_cpu["clean"] / least_cpu["flooded"]
    print(
        f"  simulated seconds per CPU second, flooded / clean {cpu_ratio:.3f} (the same ratio "
        f"without the\n      machine's other load: the flood's cost to the simulator alone)"
    )
    print(
        f"  ratio flooded / clean {ratio:.3f} (goal >= 0.90; on a shared 2-core machine the\n"
        f"      attacker's own sending competes for the cores); the flood's extra CPU in the\n"
        f"      simulator's process {extra_cpu:+.2f} s; one refused datagram, measured alone: "
        f"{refusal_cost_us():.2f} us"
    )


if __name__ == "__main__":
    main()
