"""Orbit-aware against hover-point service placement, flown in JSBSim (issue 12).

For each of ``--layouts`` seeded user layouts (K users uniform in the region, scenario seeds
``SEED0 + i``: never seen in training, which draws its layouts from
``uavxai.service.layouts.random_problem``), the scenario's service planner places the service
point twice, ``service.platform: orbit`` (the orbit objective) and ``hover`` (the paper's), and
each plan is flown once in JSBSim by the mission engine (``uavxai.sim.build.fly``, the engine
behind ``uavxai run``): transit from the ownship's start, ``--service-s`` seconds on station
in the loiter orbit the autopilot flies about the point, no intruders, static users, the
same seed (so the same fading draws) for both. What differs is the point and the power.

Printed per layout, then a table per setting: delivered Mbit (mean, 95 % t-interval over the
layouts), the paired difference orbit - hover with its interval, the share of user-seconds
meeting QoS, the planner's predicted orbit-mean sum rate (fading-free) beside the delivered
mean sum rate (with fading), and how many layouts each wins.

Settings: ``edge`` — OFDMA near the QoS edge (QoS 1.2 Mbit/s: the hover placement leaves some
user below it on the orbit on many layouts), where placement matters; ``demo`` — the demo's
comms (``scenarios/demo.yaml``: OFDMA, QoS 100 kbit/s), users static.

    nice -n 10 .venv/bin/python benchmarks/studies/bench_orbit_placement.py [--layouts 20]
        [--service-s 240] [--settings edge demo] [--planner d3qn|grid|random]
        [--json out.json] [--optimum N]
"""

from __future__ import annotations

import argparse
import json
import math
import time
from typing import Any

import numpy as np

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.comms.channel import Channel
from uavxai.scenario import Scenario, load_scenario
from uavxai.service.stage import plan_service
from uavxai.sim.build import fly
from uavxai.sim.spec import episode_spec
from uavxai.sim.steps import Service

SEED0 = 9_100
SETTINGS: dict[str, dict[str, Any]] = {
    "edge": {"access": "ofdma", "qos_rate_bps": 1.2e6},
    "demo": {},  # the demo's comms as they are
}
T_975 = {  # two-sided 95 % Student t quantiles by degrees of freedom
    1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306,
    9: 2.262, 10: 2.228, 11: 2.201, 12: 2.179, 13: 2.160, 14: 2.145, 15: 2.131, 16: 2.120,
    17: 2.110, 18: 2.101, 19: 2.093, 20: 2.086, 24: 2.064, 29: 2.045, 39: 2.023, 49: 2.010,
}


def scenario_for(
    setting: str, seed: int, service_s: float, platform: str, planner: str = "d3qn"
) -> Scenario:
    base = load_scenario("scenarios/demo.yaml").model_dump(mode="json")
    base["name"] = f"orbit-placement-{setting}"
    base["seed"] = seed
    base["comms"].update(SETTINGS[setting])
    base["comms"]["users"]["mobility"] = {"model": "static"}
    base["service"].update({"platform": platform, "replan_s": None, "planner": planner})
    base["intruders"].update({"count": 0, "flow": "none"})
    base["avoidance"]["planner"] = "none"  # no traffic: fly straight to the point
    base["mission"].update({"service_s": service_s, "return_home": False})
    base["log"]["rerun"] = False
    return Scenario.model_validate(base)


def fly_plan(sc: Scenario) -> dict[str, Any]:
    """Plan the service point of ``sc`` and fly the mission in JSBSim; the row of numbers."""
    plan = plan_service(sc)
    channel = Channel.from_scenario(sc, users=plan.users)
    goal = tuple(float(v) for v in plan.service_point)
    service = Service(sc, channel, plan.power_w, None)
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    t0 = time.perf_counter()
    spec = episode_spec(sc, goal=goal, dynamics="jsbsim", intruders=[], mission=True)
    result = fly(spec, planner, engine_steps=[service])
    m = result.summary.get("mission", {})
    return {
        "outcome": result.outcome.value,
        "service_point": list(goal),
        "planned_orbit_objective": plan.extras["orbit_objective"],
        "planned_orbit_qos_users": plan.extras["orbit_qos_satisfied"],
        "predicted_bps": m.get("predicted_orbit_sum_rate_bps", math.nan),
        "delivered_bps": m.get("mean_sum_rate_bps", math.nan),
        "delivered_bits": m.get("delivered_bits", 0.0),
        "qos_share": m.get("qos_user_seconds_share", 0.0),
        "on_station_s": m.get("on_station_s", 0.0),
        "fly_wall_s": time.perf_counter() - t0,
    }


def interval(x: np.ndarray) -> tuple[float, float, float]:
    """Mean and 95 % t-interval half width (mean, lo, hi)."""
    n = len(x)
    mean = float(np.mean(x))
    if n < 2:
        return mean, math.nan, math.nan
    t = T_975[max(k for k in T_975 if k <= n - 1)]
    half = t * float(np.std(x, ddof=1)) / math.sqrt(n)
    return mean, mean - half, mean + half


def table(setting: str, rows: list[dict[str, Any]]) -> str:
    orbit = {k: np.array([r["orbit"][k] for r in rows]) for k in rows[0]["orbit"] if k not in
             ("outcome", "service_point")}
    hover = {k: np.array([r["hover"][k] for r in rows]) for k in orbit}
    diff = orbit["delivered_bits"] - hover["delivered_bits"]
    lines = [f"\n{setting}: {len(rows)} layouts", "| | orbit-aware | hover-point | orbit - hover |",
             "|---|---|---|---|"]

    def fmt(x: np.ndarray, scale: float, digits: int = 1) -> str:
        m, lo, hi = interval(x / scale)
        return f"{m:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"

    lines.append(f"| delivered Mbit, mean [95 % CI] | {fmt(orbit['delivered_bits'], 1e6)} | "
                 f"{fmt(hover['delivered_bits'], 1e6)} | {fmt(diff, 1e6, 2)} |")
    rel = diff / hover["delivered_bits"]
    lines.append(f"| paired difference, % of hover | | | {fmt(rel, 0.01, 2)} |")
    lines.append(f"| QoS user-second share, % | {fmt(orbit['qos_share'], 0.01)} | "
                 f"{fmt(hover['qos_share'], 0.01)} | "
                 f"{fmt(orbit['qos_share'] - hover['qos_share'], 0.01, 2)} |")
    po, ph = orbit["planned_orbit_objective"], hover["planned_orbit_objective"]
    lines.append(f"| planned orbit objective R/2^lambda, Mbit/s | {fmt(po, 1e6, 2)} | "
                 f"{fmt(ph, 1e6, 2)} | {fmt(po - ph, 1e6, 3)} |")
    lines.append(f"| users meeting QoS on the planned orbit (of K) | "
                 f"{orbit['planned_orbit_qos_users'].mean():.2f} | "
                 f"{hover['planned_orbit_qos_users'].mean():.2f} | |")
    for name, d in (("orbit-aware", orbit), ("hover-point", hover)):
        ratio = d["delivered_bps"] / d["predicted_bps"]
        predicted, delivered = d["predicted_bps"].mean() / 1e6, d["delivered_bps"].mean() / 1e6
        lines.append(f"| {name}: predicted orbit sum rate -> delivered, Mbit/s | "
                     f"{predicted:.2f} -> {delivered:.2f} (ratio {ratio.mean():.3f}, "
                     f"min {ratio.min():.3f}) | | |")
    wins = int((diff > 0).sum())
    ties = int((diff == 0).sum())
    worst = float(rel.min()) * 100
    lines.append(f"| layouts orbit-aware delivers more / same point / less | {wins} / {ties} / "
                 f"{len(rows) - wins - ties} | | worst {worst:.2f} % |")
    return "\n".join(lines)


def optimum_check(setting: str, layouts: int, service_s: float) -> None:
    """How far the d3qn placements are from the exact orbit optimum (``grid``, 1-2 min each):
    orbit objective of d3qn orbit-aware and of d3qn hover-point over that of grid orbit."""
    ratios = []
    for i in range(layouts):
        sc = {p: scenario_for(setting, SEED0 + i, service_s, p) for p in ("orbit", "hover")}
        t0 = time.perf_counter()
        best = plan_service(sc["orbit"], "grid").extras["orbit_objective"]
        wall = time.perf_counter() - t0
        row = [plan_service(sc[p], "d3qn").extras["orbit_objective"] / best for p in sc]
        ratios.append(row)
        print(f"{setting} seed {SEED0 + i}: d3qn orbit-aware {row[0]:.4f}, d3qn hover-point "
              f"{row[1]:.4f} of the grid orbit optimum ({wall:.0f} s)", flush=True)
    r = np.array(ratios)
    print(f"{setting}: of the exact orbit optimum, mean (min): orbit-aware {r[:, 0].mean():.4f} "
          f"({r[:, 0].min():.4f}), hover-point {r[:, 1].mean():.4f} ({r[:, 1].min():.4f})")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--layouts", type=int, default=20)
    p.add_argument("--service-s", type=float, default=240.0)
    p.add_argument("--settings", nargs="+", default=list(SETTINGS), choices=list(SETTINGS))
    p.add_argument("--json", default=None)
    p.add_argument("--planner", choices=("d3qn", "grid", "random"), default="d3qn",
                   help="the service planner placing both (grid: the exact optimum of each)")
    p.add_argument("--optimum", type=int, default=0,
                   help="also compare d3qn with the exact grid orbit optimum on N layouts")
    args = p.parse_args()
    for setting in args.settings if args.optimum else []:
        optimum_check(setting, args.optimum, args.service_s)
    if args.optimum:
        return
    out: dict[str, list] = {}
    t0 = time.perf_counter()
    for setting in args.settings:
        rows = []
        for i in range(args.layouts):
            seed = SEED0 + i
            row = {"seed": seed}
            for platform in ("orbit", "hover"):
                sc = scenario_for(setting, seed, args.service_s, platform, args.planner)
                row[platform] = fly_plan(sc)
            o, h = row["orbit"], row["hover"]
            same = o["service_point"] == h["service_point"]
            print(f"{setting} seed {seed}: orbit {o['delivered_bits'] / 1e6:8.1f} Mbit "
                  f"(QoS {100 * o['qos_share']:5.1f} %, {o['outcome']}, "
                  f"{o['on_station_s']:.0f} s) | hover {h['delivered_bits'] / 1e6:8.1f} Mbit "
                  f"(QoS {100 * h['qos_share']:5.1f} %, {h['outcome']}) | diff "
                  f"{(o['delivered_bits'] - h['delivered_bits']) / 1e6:+7.2f} Mbit"
                  f"{' (same point)' if same else ''} | {time.perf_counter() - t0:.0f} s",
                  flush=True)
            rows.append(row)
        out[setting] = rows
        print(table(f"{setting} ({args.planner})", rows), flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
