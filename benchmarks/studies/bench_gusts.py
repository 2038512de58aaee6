"""How far turbulence moves the aircraft off the path the planner's model predicts.

A JSBSim uav_fw at 20 m/s flies level, turns of +-30 deg and level again, for 60 s, in calm air
and in each MIL-F-8785C severity (5 turbulence seeds). From every half second of the flight a
constant-turn prediction from the aircraft's exact state (position, velocity, the turn rate of
its bank) is compared with where it really was 2 s and 4 s later: the median is what the gusts
add (in calm air the only error is the autopilot's roll transitions, near zero at the median),
the 95th percentile includes those transitions. This is the error the planner's model makes in
turbulence: like this prediction it carries the ownship with the gust of the moment (its
ground velocity less its air velocity) and the intruders on their ground tracks, but it cannot
know the gusts to come (docs/results: a planning margin of this size did not remove the
grazing collisions in JSBSim).

    .venv/bin/python benchmarks/studies/bench_gusts.py [--seeds 5]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from uavxai.geometry import turn_positions
from uavxai.sim.manoeuvres import FRAME, flown
from uavxai.units import FT, G

BANKS = [(10.0, math.radians(30)), (25.0, 0.0), (35.0, math.radians(-30)), (50.0, 0.0)]


def errors(rows: np.ndarray, ahead_s: int) -> list[float]:
    pos = np.array([FRAME.to_local(r[0], r[1], r[2] * FT) for r in rows])
    vel = np.stack([rows[:, 3] * FT, rows[:, 4] * FT, -rows[:, 5] * FT], axis=1)
    turn = G * np.tan(rows[:, 6]) / np.maximum(rows[:, 9] * FT, 1.0)
    k = ahead_s * 10
    out = []
    for i in range(0, len(rows) - k, 5):
        now = slice(i, i + 1)
        p = turn_positions(pos[now], vel[now], np.array([float(ahead_s)]), turn[now])
        out.append(float(np.hypot(*(p[0, 0, :2] - pos[i + k, :2]))))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    args = ap.parse_args()
    print("severity   2 s ahead: median / p95 (m)   4 s ahead: median / p95 (m)")
    for severity in ("none", "light", "moderate", "severe"):
        runs = [
            flown(0.0, (0.0, 0.0), severity, seed, banks=list(BANKS)) for seed in range(args.seeds)
        ]
        cells = []
        for ahead in (2, 4):
            e = [x for rows in runs for x in errors(rows, ahead)]
            cells.append(f"{np.median(e):6.1f} / {np.percentile(e, 95):5.1f}")
        print(f"{severity:<9} {cells[0]:>26} {cells[1]:>29}")


if __name__ == "__main__":
    main()
