"""Cost of the surveillance picture per simulated second: ADS-B reports sampled from states at
10 Hz, the CT-EKF tracker fed with them, and beliefs read once a second, for N intruders.
Prints numbers; asserts nothing.

    .venv/bin/python benchmarks/performance/bench_surveillance.py [--intruders 40]
        [--sim-seconds 400]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from uavxai.dynamics.state import TrafficState
from uavxai.surveillance.adsb import Surveillance, SurveillanceConfig
from uavxai.surveillance.tracker import Tracker

SAMPLE_S = 0.1


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--intruders", type=int, default=40)
    ap.add_argument("--sim-seconds", type=float, default=400.0)
    args = ap.parse_args()
    n = args.intruders
    rng = np.random.default_rng(0)
    pos = np.column_stack([rng.uniform(0, 2000, n), rng.uniform(0, 2000, n), np.full(n, 120.0)])
    psi = rng.uniform(0, 2 * math.pi, n)
    speed = rng.uniform(15, 30, n)
    omega = rng.uniform(-0.3, 0.3, n)
    ids = ("ownship", *(f"intruder-{k}" for k in range(1, n + 1)))
    surveillance, tracker = Surveillance(SurveillanceConfig(noncooperative=0.1), 0), Tracker()
    steps = round(args.sim_seconds / SAMPLE_S)
    t0 = time.perf_counter()
    beliefs = 0
    for k in range(steps):
        t = round(k * SAMPLE_S, 9)
        psi = psi + omega * SAMPLE_S
        vel = np.column_stack([speed * np.sin(psi), speed * np.cos(psi), np.zeros(n)])
        pos = pos + vel * SAMPLE_S
        state = TrafficState(
            t=t,
            ids=ids,
            pos=np.vstack([[1000.0, 1000.0, 120.0], pos]),
            vel=np.vstack([[0.0, 20.0, 0.0], vel]),
            att=np.zeros((n + 1, 3)),
            airspeed=np.full(n + 1, 20.0),
        )
        tracker.update(surveillance.observe(state))
        if k % round(1 / SAMPLE_S) == 0:
            beliefs += len(tracker.beliefs(t))
    wall = time.perf_counter() - t0
    print(
        f"{n} intruders, {args.sim_seconds:g} s simulated: {wall:.2f} s wall, "
        f"{1000 * wall / args.sim_seconds:.2f} ms per simulated second, "
        f"{beliefs / (args.sim_seconds):.1f} beliefs per decision"
    )


if __name__ == "__main__":
    main()
