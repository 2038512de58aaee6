"""Speed of the whole co-simulation against the bare JSBSim world it flies.

In one process, alternating so both see the same machine load:
- `uavxai run` of a scenario with N intruders (default 20), MAVLink telemetry to a loopback
  UDP port and the rerun recording on, as the CLI flies it (service point given);
- the bare world: a JSBSimWorld of the same aircraft (same seed) stepped for the same
  simulated time, nothing else.
Prints both real-time factors (the run's as it reports it: the episode loop, set-up not
counted) and their ratio (goal: run >= 0.8 of the bare world), and the time spent in the
planner's search. `uavxai run` always plans on a companion process (its own core). The run is
measured twice: without a decision latency (`avoidance.decision_latency_s: 0`, the default
and the paper's instant decision: the ownship waits for every search, while the world flies
the intruders through the period meanwhile) and with one (`--latency`, default 0.5 s: the
search overlaps everyone's flight, as on a UAV whose companion computer plans beside the
autopilot). `--profile FILE` writes a cProfile of one run for `python -m pstats FILE`.

    .venv/bin/python benchmarks/performance/bench_run.py [--intruders 20] [--steps 60] \
        [--repeats 3] [--latency 0.5]
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
    ap.add_argument("--latency", type=float, default=0.5, help="the companion run's latency, s")
    ap.add_argument("--profile", type=Path, help="write a cProfile of one run here")
    args = ap.parse_args()

    def scenario(latency: float):
        # Far goal, so that every run flies all its decisions.
        return default_scenario(
            "bench",
            intruders={"count": args.intruders},
            ownship={"goal": [1900, 1900, 120]},
            comms={"fading": "none"},
            service={"planner": "grid", "steps": 5},
            avoidance={"max_steps": args.steps, "decision_latency_s": latency},
        )

    runs = {"no latency (default)": scenario(0.0)}
    if args.latency > 0:
        runs[f"latency {args.latency:g} s"] = scenario(args.latency)
    service = plan_service(runs["no latency (default)"])
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    sink.bind(("127.0.0.1", 0))
    port = sink.getsockname()[1]
    best = dict.fromkeys(runs, (float("inf"), 0.0, 0.0))  # loop s, planner s, set-up s
    best_bare, sim_s = float("inf"), 0.0
    for _ in range(args.repeats):
        for label, sc in runs.items():
            wall, summary = timed_run(sc, service, port)
            sim_s = summary["flight_time_s"]
            loop = sim_s / summary["sim_realtime_factor"]  # the episode loop, set-up excluded
            planner = summary["decision_ms"]["mean"] * summary["steps"] / 1000.0
            best[label] = min(best[label], (loop, planner, wall - loop))
        best_bare = min(best_bare, timed_bare(runs["no latency (default)"], sim_s))
    if args.profile:
        sc = runs["no latency (default)"]
        cProfile.runctx(
            "timed_run(sc, service, port)", globals(), locals(), filename=str(args.profile)
        )
    rtf_bare = sim_s / best_bare
    print(
        f"{args.intruders} intruders, {sim_s:.0f} s simulated, best of {args.repeats}\n"
        f"  bare JSBSim world                      {best_bare:6.2f} s  {rtf_bare:6.1f}x real time"
    )
    for label, (loop, planner, setup) in best.items():
        rtf = sim_s / loop
        print(
            f"  uavxai run, {label:<28}{loop:6.2f} s  {rtf:6.1f}x real time  "
            f"ratio run / bare {rtf / rtf_bare:.2f} (goal >= 0.8)\n"
            f"      planner {planner:.2f} s of search (on the companion's core); "
            f"set-up (aircraft loading, trim, files) {setup:.2f} s, not counted"
        )


if __name__ == "__main__":
    main()
