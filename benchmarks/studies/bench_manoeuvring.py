"""Collision rates among manoeuvring traffic (issue 11), on the engine's kinematic world.

Each episode: the default scenario's ownship start and goal, ``--intruders`` intruders drawn
with the episode's seed, flying ``--behaviour`` (``random_turns``: a bank within +-30 deg held
5-20 s, 30 % level). The planner sees every intruder's exact state and its true turn rate
g tan(phi) / V (the ``truth`` picture; no surveillance errors, no wind, traffic not replaced
when it leaves). Prints, per method, the collision rate with its 95 % Wilson interval, the
risk ratio against ``none`` on the same seeds (paired bootstrap), the goal rate, the worst
and 5th-percentile minimum separation and the p50 decision time. Asserts nothing.

    .venv/bin/python benchmarks/studies/bench_manoeuvring.py --intruders 20 --episodes 100 \\
        --methods mcts,mcts_paper,mvp,none

``mcts_paper`` is ``mcts`` predicting as the paper did (constant velocity, every collision
worth 0).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.learning.env import EncounterEnv
from uavxai.metrics import rate, risk_ratio
from uavxai.scenario import default_scenario

PAPER = {"intruder_model": "cv", "late_collision_value": 0.0}


def episode(method: str, scenario, seed: int, n: int) -> tuple[str, float, list[float]]:
    over = PAPER if method == "mcts_paper" else {}
    cfg = PlannerConfig.from_scenario(scenario, seed=seed, **over)
    planner = make_planner("mcts" if method == "mcts_paper" else method, cfg)
    planner.reset(seed)
    env = EncounterEnv(scenario, n_intruders=n)
    env.reset(seed=seed)
    min_sep, ms = np.inf, []
    while not env.outcome:
        # the truth picture: every intruder's exact state and turn rate g tan(phi) / V
        d = planner.plan(env.ownship, env.intruders, env.goal, step=env.steps)
        *_, info = env.step(d.action)
        ms.append(d.ms)
        min_sep = min(min_sep, info["min_separation_m"])
    return env.outcome, float(min_sep), ms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--behaviour", default="random_turns")
    ap.add_argument("--methods", default="mcts,mcts_paper,mvp,none")
    args = ap.parse_args()
    scenario = default_scenario(intruders={"behaviour": args.behaviour, "flow": "none"})
    seeds = range(args.first_seed, args.first_seed + args.episodes)
    methods = args.methods.split(",")
    results = {}
    for m in methods:
        t0 = time.perf_counter()
        runs = [episode(m, scenario, s, args.intruders) for s in seeds]
        results[m] = runs
        print(f"{m}: {time.perf_counter() - t0:.0f} s", flush=True)
    base = results.get("none")
    print(f"\n{args.behaviour}, {args.intruders} intruders, seeds {seeds.start}..{seeds.stop - 1}")
    print("method | collision [95% Wilson] | risk ratio vs none | goal | worst / p5 min sep"
          " | p50 ms")
    for m, runs in results.items():
        hit = np.array([o == "collision" for o, _, _ in runs])
        seps = np.array([s for _, s, _ in runs])
        rr = "-"
        if base is not None and m != "none":
            rr = str(risk_ratio(hit, np.array([o == "collision" for o, _, _ in base])))
        goal = np.mean([o == "goal" for o, _, _ in runs])
        ms = np.median(np.concatenate([x for _, _, x in runs]))
        print(f"{m} | {rate(hit)} | {rr} | {goal:.2f} | {seps.min():.0f} / "
              f"{np.percentile(seps, 5):.0f} m | {ms:.1f}")  # fmt: skip


if __name__ == "__main__":
    main()
