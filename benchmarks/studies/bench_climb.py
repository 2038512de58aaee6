"""How far a lone uav_fw climbs (sinks) after the vertical set's climb (descend) command,
against what the planner's model predicts (avoidance.model.climb_rate).

From level flight, or a 30 deg bank held for 6 s, at a speed target, the autopilot is given
the climb's height target (the ceiling less the margin) or the descent's; the height gained
1, 2, 4 and 8 s later is the median over turbulence seeds (with the smallest), in calm air
and moderate turbulence, at speed targets 12-22 m/s. The speed priority of the autopilot
(no climb near the minimum speed) is what the model's climb rate follows.

    .venv/bin/python benchmarks/studies/bench_climb.py [--seeds 8]
"""

from __future__ import annotations

import argparse

import numpy as np

from uavxai.avoidance.model import climb_rate
from uavxai.avoidance.types import PlannerConfig
from uavxai.sim.manoeuvres import CLIMB_TIMES, climb_scenario, height_gained

SPEEDS = (12.0, 13.0, 15.0, 18.0, 22.0)


def flown(speed: float, turbulence: str, bank_deg: float, vertical: int, seeds: int) -> np.ndarray:
    """(seeds, len(CLIMB_TIMES)) heights gained."""
    n = seeds if turbulence != "none" else 1
    return np.array(
        [height_gained(climb_scenario(speed, turbulence, s), bank_deg, vertical) for s in range(n)]
    )


def predicted(speed: float, turbulence: str, vertical: int) -> list[float]:
    cfg = PlannerConfig.from_scenario(climb_scenario(speed, turbulence, 0))
    rate = float(climb_rate(speed, cfg)) if vertical > 0 else -cfg.climb_rate_mps
    return [rate * t for t in CLIMB_TIMES]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    args = ap.parse_args()
    heads = "  ".join(f"{t:.0f} s" for t in CLIMB_TIMES)
    print(f"air       cmd      bank  V m/s   flown median (min) [model] at {heads}")
    for turbulence in ("none", "moderate"):
        for vertical in (1, -1):
            for bank in (0.0, 30.0):
                for speed in SPEEDS:
                    h = flown(speed, turbulence, bank, vertical, args.seeds)
                    model = predicted(speed, turbulence, vertical)
                    cells = "  ".join(
                        f"{m:+5.1f} ({lo:+5.1f}) [{p:+5.1f}]"
                        for m, lo, p in zip(np.median(h, axis=0), h.min(axis=0), model, strict=True)
                    )
                    name = "climb  " if vertical > 0 else "descend"
                    print(
                        f"{turbulence:9s} {name}  {bank:4.0f}  {speed:4.0f}   {cells}", flush=True
                    )


if __name__ == "__main__":
    main()
