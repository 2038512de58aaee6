"""Speed of the whole co-simulation against the bare JSBSim world it flies.

In one process, alternating so both see the same machine load:
- `uavxai run` of a scenario with N intruders (default 20), MAVLink telemetry to a loopback
  UDP port and the rerun recording on, as the CLI flies it (service point given);
- the bare world: a JSBSimWorld of the same aircraft (same seed) stepped for the same
  simulated time, nothing else.
Prints both real-time factors (the run's as it reports it: the episode loop, set-up not
counted) and their ratio (goal: run >= 0.8 of the bare world), and the
share of the run's wall time spent in the planner. `--profile FILE` writes a cProfile of one
run for `python -m pstats FILE`.

    .venv/bin/python benchmarks/bench_run.py [--intruders 20] [--steps 60] [--repeats 3]
"""

from __future__ import annotations

import argparse
import cProfile
import socket
import tempfile
import time
from pathlib import Path

from uavxai.dynamics.world import JSBSimWorld
from uavxai.scenario import default_scenario
from uavxai.service.stage import plan_service
from uavxai.sim.run import run_episode


def timed_run(sc, service, port: int) -> tuple[float, dict]:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        summary = run_episode(
            sc, Path(tmp), service=service, mavlink=f"udpout:127.0.0.1:{port}", record=True
        )
        return time.perf_counter() - t0, summary


def timed_bare(sc, sim_s: float) -> float:
    world = JSBSimWorld(sc, seed=sc.seed)
    try:
        n = round(sim_s / world.dt)
        t0 = time.perf_counter()
        world.step(n)
        return time.perf_counter() - t0
    finally:
        world.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--steps", type=int, default=60, help="decisions per run")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many")
    ap.add_argument("--profile", type=Path, help="write a cProfile of one run here")
    args = ap.parse_args()

    # Far goal, so that every run flies all its decisions.
    sc = default_scenario(
        "bench",
        intruders={"count": args.intruders},
        ownship={"goal": [1900, 1900, 120]},
        comms={"fading": "none"},
        service={"planner": "grid", "steps": 5},
        avoidance={"max_steps": args.steps},
    )
    service = plan_service(sc)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    sink.bind(("127.0.0.1", 0))
    port = sink.getsockname()[1]
    best_run = best_bare = float("inf")
    planner_s = sim_s = setup_s = 0.0
    for _ in range(args.repeats):
        wall, summary = timed_run(sc, service, port)
        sim_s = summary["flight_time_s"]
        loop = sim_s / summary["sim_realtime_factor"]  # the episode loop, set-up excluded
        if loop < best_run:
            best_run, setup_s = loop, wall - loop
            planner_s = summary["decision_ms"]["mean"] * summary["steps"] / 1000.0
        best_bare = min(best_bare, timed_bare(sc, sim_s))
    if args.profile:
        cProfile.runctx(
            "timed_run(sc, service, port)", globals(), locals(), filename=str(args.profile)
        )
    rtf_run, rtf_bare = sim_s / best_run, sim_s / best_bare
    print(
        f"{args.intruders} intruders, {sim_s:.0f} s simulated, best of {args.repeats}\n"
        f"  uavxai run (MAVLink + rerun)  {best_run:6.2f} s  {rtf_run:6.1f}x real time\n"
        f"  bare JSBSim world             {best_bare:6.2f} s  {rtf_bare:6.1f}x real time\n"
        f"  ratio run / bare: {rtf_run / rtf_bare:.2f}  (goal >= 0.8); planner "
        f"{planner_s:.2f} s = {planner_s / best_run:.0%} of the run; without it the ratio "
        f"would be {sim_s / (best_run - planner_s) / rtf_bare:.2f}; set-up (aircraft "
        f"loading, trim, files) {setup_s:.2f} s, not counted"
    )


if __name__ == "__main__":
    main()
