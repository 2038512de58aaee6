"""Cost and quality of MCTS against the exhaustive search it samples.

On one fixed set of seeded encounters (20 intruders, the default scenario's area, the ownship
at a random place and heading): the decision time of MCTS at 200 simulations, depth 4 (p50,
p95; the goal is p50 <= 10 ms on one core) and of exhaustive search to the same depth, and
their ratio measured on the same encounters in the same process. Then whole kinematic
episodes of both: the MCTS goal rate as a fraction of the exhaustive one.

Times are the process's CPU time per decision (less disturbed by other processes than wall
time, which is printed too).

    .venv/bin/python benchmarks/bench_mcts.py [--quick] [--encounters 40] [--episodes 20]
        [--intruders 20] [--simulations 200] [--depth 4] [--repeats 5]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from uavxai.avoidance import PlannerConfig, make_planner
from uavxai.avoidance.types import Ownship
from uavxai.scenario import default_scenario
from uavxai.sim.build import open_world
from uavxai.sim.build import run_kinematic as run_episode
from uavxai.sim.spec import episode_spec
from uavxai.surveillance.tracker import truth_beliefs


def encounters(scenario, count: int, n_intruders: int) -> list[tuple[Ownship, list, tuple]]:
    """Seeded encounters: (ownship, intruders, goal)."""
    out = []
    for seed in range(count):
        rng = np.random.default_rng(1000 + seed)
        own = Ownship(
            x=float(rng.uniform(200, 1800)),
            y=float(rng.uniform(200, 1800)),
            h=float(rng.uniform(100, 140)),
            speed=float(rng.uniform(15, 28)),
            heading=float(rng.uniform(0, 2 * math.pi)),
            bank=math.radians(float(rng.choice([-20, -10, 0, 10, 20]))),
        )
        spec = episode_spec(scenario, seed, n_intruders=n_intruders)
        with open_world(spec) as world:
            out.append((own, truth_beliefs(world.state()), spec.goal))
    return out


def time_decisions(planner, cases, repeats: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-case CPU ms and wall ms (best of ``repeats``)."""
    cpu = np.full(len(cases), np.inf)
    wall = np.full(len(cases), np.inf)
    for _ in range(repeats):
        for i, (own, intruders, goal) in enumerate(cases):
            planner.reset(i)
            t_cpu, t_wall = time.process_time(), time.perf_counter()
            planner.plan(own, intruders, goal)
            cpu[i] = min(cpu[i], 1000 * (time.process_time() - t_cpu))
            wall[i] = min(wall[i], 1000 * (time.perf_counter() - t_wall))
    return cpu, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="10 encounters, 4 episodes")
    ap.add_argument("--encounters", type=int, default=40)
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--simulations", type=int, default=200)
    ap.add_argument("--depth", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=5, help="timing repeats (best is kept)")
    args = ap.parse_args()
    if args.quick:
        args.encounters, args.episodes, args.repeats = 10, 4, 1

    scenario = default_scenario(
        "bench-mcts",
        intruders={"count": args.intruders},
        avoidance={"mcts": {"simulations": args.simulations, "depth": args.depth}},
    )
    cfg = PlannerConfig.from_scenario(scenario)
    cases = encounters(scenario, args.encounters, args.intruders)
    mcts, exhaustive = make_planner("mcts", cfg), make_planner("exhaustive", cfg)
    for planner in (mcts, exhaustive):  # warm caches and imports
        planner.plan(*cases[0])

    print(
        f"{len(cases)} encounters, {args.intruders} intruders, MCTS {args.simulations} "
        f"simulations, depth {args.depth} (exhaustive: {9**args.depth} sequences)"
    )
    m_cpu, m_wall = time_decisions(mcts, cases, args.repeats)
    e_cpu, e_wall = time_decisions(exhaustive, cases, args.repeats)
    for name, cpu, wall in (("mcts", m_cpu, m_wall), ("exhaustive", e_cpu, e_wall)):
        p50, p95 = np.percentile(cpu, [50, 95])
        w50, w95 = np.percentile(wall, [50, 95])
        print(
            f"  {name:<11} decision ms  cpu p50 {p50:7.2f}  p95 {p95:7.2f}   "
            f"(wall p50 {w50:7.2f}  p95 {w95:7.2f})"
        )
    print(f"  cost ratio mcts / exhaustive (cpu, same encounters): {m_cpu.sum() / e_cpu.sum():.3f}")
    # MCTS's choice scored by exhaustive search: the best value reachable after it.
    agree, unsafe, regret = 0, 0, []
    for case in cases:
        chosen = mcts.plan(*case).action
        best = exhaustive.plan(*case)
        q = {c.action: c.q for c in best.children}
        agree += chosen == best.action
        unsafe += q[chosen] == 0.0 and max(q.values()) > 0.0
        regret.append(max(q.values()) - q[chosen])
    print(
        f"  mcts against the optimum: same action {agree}/{len(cases)}, value regret mean "
        f"{np.mean(regret):.4f} max {np.max(regret):.4f}, colliding choices with a safe one "
        f"available {unsafe}"
    )
    print(f"{args.episodes} kinematic episodes each (seeds 0..{args.episodes - 1}):")
    goals = {}
    for name in ("mcts", "exhaustive"):
        results = [
            run_episode(name, scenario, seed, args.intruders) for seed in range(args.episodes)
        ]
        outcomes = [r.outcome for r in results]
        goals[name] = outcomes.count("goal") / len(outcomes)
        print(
            f"  {name:<11} goal {goals[name]:.2f}  collision "
            f"{outcomes.count('collision') / len(outcomes):.2f}  timeout "
            f"{outcomes.count('timeout') / len(outcomes):.2f}  mean steps "
            f"{np.mean([r.steps for r in results]):.1f}"
        )
    if goals["exhaustive"] > 0:
        print(f"  goal rate mcts / exhaustive: {goals['mcts'] / goals['exhaustive']:.3f}")


if __name__ == "__main__":
    main()
