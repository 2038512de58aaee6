"""Speed of the whole co-simulation against the bare JSBSim world it flies.

In one process, alternating so both see the same machine load:
- `uavxai run` of a scenario with N intruders (default 20), MAVLink telemetry to a loopback
  UDP port and the rerun recording on, as the CLI flies it (service point given);
- plain JSBSim (issue 31's baseline): the same aircraft (a JSBSimWorld's executives, same
  seed, loaded and trimmed as the run loads them) stepped for the same simulated time by a
  loop of ``FGFDMExec.run()`` calls, nothing else;
- our bare world: that JSBSimWorld stepped (its intruders' pilots, its checks), no planner,
  no surveillance, no files.
Runs are interleaved (run, run with latency, plain, world; again) so all see the same machine
load; each figure is the median of ``--repeats`` (5). Prints the real-time factors (the run's
as it reports it: the episode loop, set-up not counted), the ratio run / plain JSBSim (goal
>= 0.8) and run / bare world, and the time spent in the planner's search. `uavxai run`
always plans on a companion process (its own core). The run is measured twice: without a
decision latency (`avoidance.decision_latency_s: 0`, the default and the paper's instant
decision: the ownship waits for every search, while the world flies the intruders through
the period meanwhile) and with one (`--latency`, default 0.5 s: the search overlaps
everyone's flight, as on a UAV whose companion computer plans beside the
autopilot). `--profile FILE` writes a cProfile of one run for `python -m pstats FILE`;
`--phases` times the episode loop's phases in one more run (CPU seconds of the simulation
process, and the companion's and the recorder's CPU over the loop: figures that a loaded
machine leaves readable, unlike its wall seconds), and the bare loops' CPU is printed beside
their wall time.

Measured again (issue 31, branch speed33, docs/results/README.md "Issue 31's co-simulation
speed, again"): 60 s simulated, median of 5, the base tree's and the branch's benchmark one
after the other at load 4.6-5.9 on 2 CPUs (three campaign processes at normal priority), twice:
run / plain JSBSim 0.75 and 0.66 without latency, 0.72 and 0.65 with 0.5 s (before: 0.63 and
0.56, 0.67 and 0.67), the run's loop 5.51 and 7.22 s against 7.01 and 10.53 s; not met on that
machine, expected about 0.85 on a quiet one (to be measured there). What changed: the
companion warms its planner up as it starts (its first search loaded the compiled kernel,
0.3-0.6 s, inside the loop: the ownship waited for it at its first decision, with or without a
latency, which is why the 0.5 s latency did not help), and the ADS-B frames go to it a
decision period at a time. ``--phases`` after it, load 4.6-5.4:

| the simulation process's CPU over the episode loop (2.06 s; 5.60 s wall) | |
|---|---|
| the intruders' JSBSim flight (lookahead, 20 x 120 ticks a decision) | 65 % |
| the ownship's JSBSim flight, the pilots, 11 newcomers loaded and trimmed (world.step) | 13 % |
| MAVLink telemetry (bridge) | 4.6 % |
| ADS-B: surveillance, frames packed and posted to the companion (picture) | 4.1 % |
| the judge (closest approach between samples) | 2.9 % |
| states read (world.state) | 2.1 % |
| decisions.jsonl, trajectory.csv, rerun posts | 1.9, 1.6, 1.5 % |
| the rest (battery, commands, throughput, trust, the companion's answers) | 4 % |

The companion used 0.48 s of CPU over the loop (0.97 s before: its first search's kernel
load), the recorder 0.24 s; the simulation waited 0.12 s wall for decisions (0.92 s before).

Measured (issue 31): 20 intruders, 30 s simulated, no latency, median of 5 at load 6 on 2
CPUs (two campaigns running): run / plain JSBSim 1.00, run / bare world 0.94 (plain JSBSim
itself at 0.6x real time: the machine was oversubscribed; measure again on a quiet one).

Where the time goes (issue 31, cProfile of `uavxai run`, 20 intruders, no latency, 12
decisions, machine at load 12-15 on 2 CPUs, so the shares, not the seconds, are the
finding; set-up, the rerun import and the quick-look plot are outside the loop and not
counted):

| share of the episode loop (after the change below) | |
|---|---|
| the intruders' JSBSim flight (lookahead, 20 x 120 ticks a decision) | 34 % |
| waiting for the companion's search (beyond the lookahead's overlap) | 30 % |
| ADS-B frames to the companion (picture) | 14 % |
| the ownship's JSBSim flight and its state reads (world.step) | 6 % |
| MAVLink telemetry (bridge publish) | 5 % |
| the rest (recording, judge, observers) | 11 % |

Before it (main 9d54afb, 60 s simulated, quiet machine, --repeats 3): plain lockstep loop
6.20 s, bare world 8.80 s, run without latency 10.55 s (run / plain JSBSim 0.59), with 0.5 s
latency 8.62 s (0.72). After it, 30 s simulated, two single repeats alternating with the old
code's at load 8-11 (the seconds swing 2x between repeats): bare world 3.11 / 3.00 s against
plain lockstep 12.09 / 14.11 s and plain 1 s at a time 2.90 / 3.35 s; run / plain JSBSim
1.03 / 1.36 (before: 0.55 / 1.05), run / plain 1 s at a time 0.25 / 0.32, run / bare world
0.27 / 0.29 (docs/results/README.md, "Issue 31's co-simulation speed").

(*) The bare world was nothing but ``FGFDMExec.run()`` calls, yet one call cost 3-5x as
much with the 21 executives taking turns each tick (lockstep) as with one executive flying
on: 166-336 us against 36-72 us a call at that load, and 60-84 us in turns of 12 ticks,
36-54 us in turns of 120 (the caches: each executive's working set evicted the others').
The world now flies each aircraft its whole chunk in turn (JSBSimWorld._integrate, the
lookahead row by row), the same flight to the bit. Hence the second plain baseline
(:data:`PLAIN_CHUNKED`): the plain lockstep loop is no longer the fastest loop of
``FGFDMExec.run()`` calls, and the run is compared with both.

    .venv/bin/python benchmarks/performance/bench_run.py [--intruders 20] [--steps 60] \
        [--repeats 5] [--latency 0.5]
"""

from __future__ import annotations

import argparse
import cProfile
import os
import socket
import statistics
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


PLAIN = "plain JSBSim (FGFDMExec.run loop)"
PLAIN_CHUNKED = "plain JSBSim, each 1 s at a time"
WORLD = "our bare world"


def timed_bare(sc, sim_s: float, how: str) -> tuple[float, float]:
    """Seconds to fly ``sim_s`` of the scenario's aircraft: :data:`PLAIN`, a loop of their
    executives' ``FGFDMExec.run()`` in lockstep (each one tick in turn) and nothing else;
    :data:`PLAIN_CHUNKED`, the same calls with each executive flying a second at a time (its
    working set stays in the caches); :data:`WORLD`, our world's ``step``. (wall s, CPU s)"""
    world = JSBSimWorld(sc, seed=sc.seed)
    try:
        n = round(sim_s / world.dt)
        runs = [a.fdm.run for a in world.aircraft]
        chunk = round(1.0 / world.dt)
        t0, c0 = time.perf_counter(), time.process_time()
        if how == PLAIN:
            for _ in range(n):
                for run in runs:
                    run()
        elif how == PLAIN_CHUNKED:
            for begin in range(0, n, chunk):
                for run in runs:
                    for _ in range(min(chunk, n - begin)):
                        run()
        else:
            world.step(n)
        return time.perf_counter() - t0, time.process_time() - c0
    finally:
        world.close()


def _cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` has used (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def phases(sc, service, port: int) -> tuple[dict[str, tuple[float, float, int]], dict]:
    """One run with timers around the episode loop's phases: name -> (wall s, CPU s of this
    process, calls), "loop" the whole episode loop, "companion" / "recorder" those processes'
    CPU over it; and the run's summary. Timers, not a profiler: the shares as they are."""
    from uavxai.sim.episode import Episode, Observer

    acc: dict[str, list[float]] = {}

    def timed(obj: object, method: str, name: str) -> None:
        inner = getattr(obj, method)

        def call(*args, **kwargs):
            w, c = time.perf_counter(), time.process_time()
            try:
                return inner(*args, **kwargs)
            finally:
                row = acc.setdefault(name, [0.0, 0.0, 0])
                row[0] += time.perf_counter() - w
                row[1] += time.process_time() - c
                row[2] += 1

        setattr(obj, method, call)

    begin, finish, start = Episode.begin, Episode.finish, {}

    def timed_begin(ep: Episode) -> None:
        for o in ep._subscribers:
            for method in ("on_sample", "on_decision", "on_period"):
                if getattr(type(o), method) is not getattr(Observer, method):
                    timed(o, method, f"{type(o).__name__}.{method}")
        timed(ep.world, "lookahead", "world: the intruders flown ahead")
        timed(ep.world, "step", "world: the ownship (and pilots)")
        timed(ep.world, "state", "world: states read")
        timed(ep.seat, "result", "waiting for the companion's decision")
        timed(ep.seat, "submit_onboard", "submitting to the companion")
        timed(ep.path, "on_sample", "MAVLink telemetry (bridge)")
        timed(ep.path, "send", "MAVLink commands (encode, bridge)")
        timed(ep.judge, "separation", "judge")
        begin(ep)
        rec = next((o.recorder for o in ep.observers if hasattr(o, "recorder")), None)
        start["pids"] = {"companion": ep.seat.pid, "recorder": rec._worker.pid if rec else None}
        start["cpu"] = {k: _cpu_s(p) for k, p in start["pids"].items() if p}
        start["t"] = (time.perf_counter(), time.process_time())

    def timed_finish(ep: Episode, outcome):
        w, c = start["t"]
        acc["loop"] = [time.perf_counter() - w, time.process_time() - c, 1]
        for k, cpu in start["cpu"].items():
            acc[k] = [0.0, _cpu_s(start["pids"][k]) - cpu, 1]
        return finish(ep, outcome)

    Episode.begin, Episode.finish = timed_begin, timed_finish
    try:
        _, summary = timed_run(sc, service, port)
    finally:
        Episode.begin, Episode.finish = begin, finish
    return {k: (w, c, int(n)) for k, (w, c, n) in acc.items()}, summary


def print_phases(rows: dict[str, tuple[float, float, int]]) -> None:
    loop_wall, loop_cpu, _ = rows["loop"]
    print(f"  phases of one run: episode loop {loop_wall:.2f} s wall, {loop_cpu:.2f} s CPU of the "
          "simulation process")  # fmt: skip
    for name, (wall, cpu, n) in sorted(rows.items(), key=lambda kv: -kv[1][1]):
        if name in ("loop", "companion", "recorder"):
            continue
        print(f"    {name:<42} {wall:6.3f} s wall {cpu:6.3f} s CPU "
              f"({100 * cpu / loop_cpu:4.1f} %)  {n} calls")  # fmt: skip
    for name in ("companion", "recorder"):
        if name in rows:
            print(f"    the {name} process: {rows[name][1]:.2f} s CPU over the loop")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--steps", type=int, default=60, help="decisions per run")
    ap.add_argument("--repeats", type=int, default=5, help="median of this many")
    ap.add_argument("--latency", type=float, default=0.5, help="the companion run's latency, s")
    ap.add_argument("--profile", type=Path, help="write a cProfile of one run here")
    ap.add_argument(
        "--phases", action="store_true", help="time the loop's phases in one more run (CPU)"
    )
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
    # per run: (episode loop, planner, set-up) seconds of every repeat
    loops: dict[str, list[tuple[float, float, float]]] = {k: [] for k in runs}
    bare: dict[str, list[tuple[float, float]]] = {PLAIN: [], PLAIN_CHUNKED: [], WORLD: []}
    sim_s = 0.0
    for _ in range(args.repeats):
        for label, sc in runs.items():
            wall, summary = timed_run(sc, service, port)
            sim_s = summary["flight_time_s"]
            loop = sim_s / summary["sim_realtime_factor"]  # the episode loop, set-up excluded
            planner = summary["decision_ms"]["mean"] * summary["steps"] / 1000.0
            loops[label].append((loop, planner, wall - loop))
        for how in bare:
            bare[how].append(timed_bare(runs["no latency (default)"], sim_s, how))
    if args.profile:
        sc = runs["no latency (default)"]
        cProfile.runctx(
            "timed_run(sc, service, port)", globals(), locals(), filename=str(args.profile)
        )
    timers = phases(runs["no latency (default)"], service, port)[0] if args.phases else None
    rtf = {label: sim_s / statistics.median(w for w, _ in t) for label, t in bare.items()}
    plain_rtf, chunked_rtf, world_rtf = rtf.values()
    print(f"{args.intruders} intruders, {sim_s:.0f} s simulated, median of {args.repeats} "
          f"interleaved; load {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")  # fmt: skip
    for label, t in bare.items():
        wall, cpu = (statistics.median(c) for c in zip(*t, strict=True))
        print(f"  {label:<38} {wall:6.2f} s  {rtf[label]:6.1f}x real time  ({cpu:.2f} s CPU)")
    for label, rows in loops.items():
        loop, planner, setup = (statistics.median(c) for c in zip(*rows, strict=True))
        run_rtf = sim_s / loop
        print(
            f"  uavxai run, {label:<26} {loop:6.2f} s  {run_rtf:6.1f}x real time  ratio run / "
            f"plain JSBSim {run_rtf / plain_rtf:.2f} (goal >= 0.8), run / plain JSBSim "
            f"chunked {run_rtf / chunked_rtf:.2f}, run / bare world {run_rtf / world_rtf:.2f}\n"
            f"      planner {planner:.2f} s of search (on the companion's core); "
            f"set-up (aircraft loading, trim, files) {setup:.2f} s, not counted"
        )
    if timers is not None:
        print_phases(timers)


if __name__ == "__main__":
    main()
