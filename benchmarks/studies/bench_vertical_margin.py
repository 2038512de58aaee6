"""How tall the tree's conflict volume stands against what an intruder can do vertically
(issue 31, sep32; docs/results "A vertical margin of its own").

Flies `mcts_sep` on kinematic campaign episodes of a scenario and, at every decision, for
every track within 400 m horizontally, sets what the sphere asks vertically (d_min_m plus the
track's margin, the turn cover and horizontal track error, at 4, 8 and 16 s) beside the
intruder's vertical need: d_min_m plus its climb-rate limit (its aircraft's height loop) over
the turn cover's horizon plus uncertainty_k sigmas of its vertical track error (the tracker's
covariance). Also where the ownship flew (below 90 m, 90-200 m, above 200 m) and how often it
was cornered. Prints a summary; ``--jsonl FILE`` keeps every decision's numbers.

    python benchmarks/studies/bench_vertical_margin.py \\
        docs/results/manoeuvring/sep31/best-backup.yaml --intruders 20 --seeds 6039
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from uavxai.avoidance.mcts import _track_errors, intruder_bank_limits, intruder_turn_rates
from uavxai.avoidance.model import intruder_margin
from uavxai.campaign.episode import campaign_spec, planner_for
from uavxai.scenario import aircraft_height_loop, load_scenario
from uavxai.sim.build import fly

TIMES = (4.0, 8.0, 16.0)
NEAR_M = 400.0


def fly_seed(scenario, planner, n_intruders: int, seed: int) -> dict:
    """One episode, with every decision's tracks near the ownship and their margins."""
    cfg = planner.config
    records: list[dict] = []
    plan = planner.plan

    def recorded(own, intruders, goal, *, step, **kw):
        d = plan(own, intruders, goal, step=step, **kw)
        if intruders:
            pos = np.array([[i.x, i.y, i.h] for i in intruders])
            vel = np.array([[i.vx, i.vy, i.vh] for i in intruders])
            turn = intruder_turn_rates(intruders, cfg)
            m = intruder_margin(cfg, vel, np.zeros(len(intruders)) if turn is None else turn,
                                *_track_errors(intruders),
                                bank_limit_rad=intruder_bank_limits(intruders, cfg))  # fmt: skip
            marg = m(np.array(TIMES)) if m is not None else np.zeros((len(TIMES), len(pos)))
            rel = pos - np.array([own.x, own.y, own.h])
            hd = np.hypot(rel[:, 0], rel[:, 1])
            records.append({"h": own.h, "cornered": d.cornered, "near": [
                {"dz": float(rel[j, 2]), "margin": marg[:, j].tolist(),
                 "sigma_h": intruders[j].sigma_h_m, "sigma_vh": intruders[j].sigma_vh,
                 "sigma_v": intruders[j].sigma_v}
                for j in np.nonzero(hd < NEAR_M)[0]]})  # fmt: skip
        return d

    planner.plan = recorded
    try:
        r = fly(campaign_spec(scenario, n_intruders, seed), planner)
    finally:
        planner.plan = plan
    return {"seed": seed, "outcome": r.outcome.value, "steps": r.steps,
            "min_sep": float(r.min_separation_m), "decisions": records}  # fmt: skip


def summary(runs: list[dict], d_min: float, climb: float, horizon: float, k: float) -> str:
    asked = {t: [] for t in TIMES}
    need = {t: [] for t in TIMES}
    heights, cornered, sv, svh = [], 0, [], []
    for run in runs:
        for rec in run["decisions"]:
            heights.append(rec["h"])
            cornered += rec["cornered"]
            for tr in rec["near"]:
                sv.append(tr["sigma_v"])
                svh.append(tr["sigma_vh"])
                for i, t in enumerate(TIMES):
                    asked[t].append(d_min + tr["margin"][i])
                    err = np.hypot(tr["sigma_h"], tr["sigma_vh"] * t)
                    need[t].append(d_min + climb * min(t, horizon) + k * err)
    h = np.array(heights)
    lines = [f"{len(h)} decisions ({cornered} cornered), {len(sv)} track-decisions within "
             f"{NEAR_M:.0f} m"]  # fmt: skip
    for t in TIMES:
        a, v = np.array(asked[t]), np.array(need[t])
        lines.append(
            f"  {t:4.0f} s: the sphere asks {np.median(a):.0f} m (p10 {np.percentile(a, 10):.0f}, "
            f"p90 {np.percentile(a, 90):.0f}) vertically; the intruder's vertical need "
            f"{np.median(v):.0f} m (p90 {np.percentile(v, 90):.0f})"
        )
    lines.append(f"  velocity error 1 sigma: horizontal {np.median(sv):.2f} m/s, vertical "
                 f"{np.median(svh):.2f} m/s (medians)")  # fmt: skip
    lines.append(f"  ownship below 90 m {np.mean(h < 90):.2f}, 90-200 m "
                 f"{np.mean((h >= 90) & (h <= 200)):.2f}, above 200 m {np.mean(h > 200):.2f}")
    for run in runs:
        lines.append(f"  seed {run['seed']}: {run['outcome']}, {run['steps']} steps, closest "
                     f"{run['min_sep']:.1f} m")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--jsonl", help="write every decision's numbers here")
    args = ap.parse_args()
    scenario = load_scenario(args.scenario)
    planner = planner_for(scenario, "mcts_sep")
    runs = [fly_seed(scenario, planner, args.intruders, s) for s in args.seeds]
    if args.jsonl:
        with open(args.jsonl, "w") as f:
            f.writelines(json.dumps(r) + "\n" for r in runs)
    cfg = planner.config
    climb = aircraft_height_loop(scenario.intruders.aircraft)[1]
    print(summary(runs, cfg.d_min_m, climb, cfg.reach_horizon_s, cfg.uncertainty_k))


if __name__ == "__main__":
    main()
