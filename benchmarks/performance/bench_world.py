"""Cost of the JSBSim world against bare FGFDMExec.run() stepping of the same aircraft.

For 1 + {0, 5, 20, 40} aircraft: the world advanced the way the pipeline drives it (state
read at 10 Hz, intruder pilots at 1 Hz), and the same trimmed aircraft stepped by a bare
`for fdm in fdms: fdm.run()` loop. Prints the real-time factor of both and their ratio
(goal: world <= 1.3x bare; >= 20x real time with 21 aircraft on one core).

    python benchmarks/performance/bench_world.py [--seconds 30] [--repeats 3]
"""

from __future__ import annotations

import argparse
import time

from uavxai.dynamics.world import JSBSimWorld
from uavxai.scenario import default_scenario


def time_world_chunk(world: JSBSimWorld) -> float:
    """One simulated second the way the pipeline drives the world."""
    t0 = time.perf_counter()
    for _ in range(10):
        world.advance(0.1)
        world.state()
    return time.perf_counter() - t0


def time_bare_chunk(fdms: list, steps: int) -> float:
    t0 = time.perf_counter()
    for _ in range(steps):
        for fdm in fdms:
            fdm.run()
    return time.perf_counter() - t0


def measure(intruders: int, seconds: int) -> tuple[float, float, float]:
    """(build s, world s, bare s) for `seconds` of simulated time. World and bare stepping
    alternate second by second so that both see the same background load."""
    scenario = default_scenario("bench", intruders={"count": intruders})
    t0 = time.perf_counter()
    world = JSBSimWorld(scenario)
    build = time.perf_counter() - t0
    twin = JSBSimWorld(scenario)  # the same aircraft, stepped bare
    fdms = [a.fdm for a in twin.aircraft]
    steps = round(1.0 / twin.dt)
    world_s = bare_s = 0.0
    for _ in range(seconds):
        world_s += time_world_chunk(world)
        bare_s += time_bare_chunk(fdms, steps)
    world.close()
    twin.close()
    return build, world_s, bare_s


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=int, default=30, help="simulated time per run")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many runs")
    args = ap.parse_args()

    print(f"simulated {args.seconds:g} s per run, best of {args.repeats}")
    print(f"{'aircraft':>8} {'build s':>8} {'world xRT':>10} {'bare xRT':>9} {'ratio':>6}")
    for intruders in (0, 5, 20, 40):
        runs = [measure(intruders, args.seconds) for _ in range(args.repeats)]
        build = min(r[0] for r in runs)
        w = min(r[1] for r in runs)
        b = min(r[2] for r in runs)
        print(
            f"{1 + intruders:>8} {build:>8.2f} {args.seconds / w:>10.1f} "
            f"{args.seconds / b:>9.1f} {w / b:>6.2f}"
        )


if __name__ == "__main__":
    main()
