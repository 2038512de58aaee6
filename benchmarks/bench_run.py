"""Cost of MAVLink and rerun in a full `uavxai run`.

Runs the same scenario (20 intruders by default) three ways in one process — bare, with MAVLink
telemetry to a loopback UDP port, and with MAVLink plus the rerun recording — and prints the
real-time factor of each and the overhead against the bare run (goal: <= 15 %).

    .venv/bin/python benchmarks/bench_run.py [--intruders 20] [--steps 60] [--repeats 2]
"""

from __future__ import annotations

import argparse
import json
import socket
import tempfile
import time
from pathlib import Path

from uavxai.pipeline import run_episode
from uavxai.scenario import default_scenario
from uavxai.service.stage import plan_service


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--steps", type=int, default=60, help="decisions per run")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()

    sc = default_scenario(
        "bench",
        intruders={"count": args.intruders},
        avoidance={"max_steps": args.steps},
    )
    service = plan_service(sc)
    # A listener socket so the UDP telemetry has somewhere to go (and is really sent).
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setblocking(False)
    port = sink.getsockname()[1]
    variants = {
        "bare": {"record": False, "mavlink": None},
        "mavlink": {"record": False, "mavlink": f"udpout:127.0.0.1:{port}"},
        "mavlink+rerun": {"record": True, "mavlink": f"udpout:127.0.0.1:{port}"},
    }
    best: dict[str, float] = {}
    sim_s: dict[str, float] = {}
    for _ in range(args.repeats):
        for name, kw in variants.items():
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                summary = run_episode(sc, Path(tmp), service=service, **kw)
                wall = time.perf_counter() - t0
                while True:  # drain
                    try:
                        sink.recv(65536)
                    except BlockingIOError:
                        break
            best[name] = min(best.get(name, float("inf")), wall)
            sim_s[name] = summary["flight_time_s"]
    print(
        f"uavxai run, {args.intruders} intruders, {args.steps} decisions "
        f"({sim_s['bare']:.0f} s simulated), best of {args.repeats}"
    )
    print(f"{'variant':<16}{'wall s':>9}{'x real time':>13}{'overhead':>10}")
    for name in variants:
        rtf = sim_s[name] / best[name]
        over = best[name] / best["bare"] - 1.0
        print(f"{name:<16}{best[name]:>9.2f}{rtf:>13.1f}{over:>+10.1%}")
    print(json.dumps({k: round(v, 3) for k, v in best.items()}))


if __name__ == "__main__":
    main()
