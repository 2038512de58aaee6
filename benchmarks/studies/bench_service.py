"""Service-point benchmark: D3QN against the exact grid optimum and the naive placement.

For each access mode and each of ``--layouts`` random user layouts (K = 10, users uniform in
the default region, scenario seed ``--seed + i``, ``fading: none``, environments cycling
through the four Al-Hourani sets) it

1. solves the exact optimum over the search lattice and the discrete power levels (grid),
2. trains a D3QN from scratch on the layout for ``--episodes`` episodes (as `uavxai train`),
3. runs the `uavxai service` planner (the shipped universal D3QN, zero-shot, refined),

and prints the objective R/2^lambda of each over the optimum and over the naive placement
(users' centroid at 100 m, equal power). "model" is the policy `uavxai train` saves (the
best of those evaluated after each episode) flown greedily from the start; "final" is the last
policy; "search" is the best point visited while training (the service point is the best
position visited); "service" is what `uavxai service` returns for the layout.
Episodes to converge: first episode from which the 10-episode running mean of the greedy
objective stays within 5 % of its final level.

    python benchmarks/studies/bench_service.py                       # 20 layouts x 2 modes, ~40 min
    python benchmarks/studies/bench_service.py --layouts 2 --episodes 100   # about 2 minutes
    python benchmarks/studies/bench_service.py --dqn                 # also DQN on every layout
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from uavxai.comms.channel import ENVIRONMENTS
from uavxai.learning import branching
from uavxai.learning.service import episodes_to_converge
from uavxai.scenario import default_scenario
from uavxai.service import d3qn
from uavxai.service.grid import solve_grid
from uavxai.service.service_env import ServiceEnv
from uavxai.service.stage import plan_service


def bench_layout(access: str, seed: int, episodes: int, with_dqn: bool) -> dict[str, float]:
    environment = list(ENVIRONMENTS)[seed % len(ENVIRONMENTS)]
    sc = default_scenario(
        "bench", seed=seed, comms={"access": access, "fading": "none", "environment": environment}
    )
    env = ServiceEnv.from_scenario(sc)
    t0 = time.perf_counter()
    grid = solve_grid(env.channel, env.space, env.power_levels)
    grid_s = time.perf_counter() - t0
    result = branching.train(env, branching.D3QNConfig(episodes=episodes, seed=seed))
    greedy = d3qn.rollout(result.net, d3qn.fading_free(env))
    converge, _ = episodes_to_converge([row["greedy_objective"] for row in result.curve])
    model = result.best_greedy
    search = max(greedy.objective, result.best.objective)
    shipped = plan_service(sc, "d3qn")
    opt, naive = grid.objective, env.naive_objective
    extra = {}
    if with_dqn:
        base = branching.train(env, branching.DQNConfig(episodes=episodes, seed=seed))
        greedy_dqn = d3qn.rollout(base.net, d3qn.fading_free(env))
        extra = {
            "dqn_over_opt": greedy_dqn.objective / opt,
            "dqn_model_over_opt": base.best_greedy / opt,
            "dqn_converge": episodes_to_converge([row["greedy_objective"] for row in base.curve])[
                0
            ],
            "d3qn_final_return_over_dqn": _final(result.curve) / _final(base.curve),
        }
    return {
        "seed": seed,
        "environment": environment,
        "model_over_opt": model / opt,
        "greedy_over_opt": greedy.objective / opt,
        "search_over_opt": search / opt,
        "model_over_naive": model / naive,
        "naive_over_opt": naive / opt,
        "episodes_to_converge": converge,
        "train_s": result.wall_s,
        "shipped_over_opt": shipped.objective / opt,
        "shipped_s": shipped.wall_s,
        "grid_s": grid_s,
        **extra,
    }


def _final(curve: list[dict[str, float]]) -> float:
    """Mean reward per step over the last 10 % of training episodes (the paper's level)."""
    return float(np.mean([row["return"] for row in curve[-max(1, len(curve) // 10) :]]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--layouts", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=300)
    parser.add_argument("--access", default="shared,ofdma")
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--dqn", action="store_true", help="also train DQN on every layout")
    parser.add_argument("--json", type=Path, help="also write every number here")
    args = parser.parse_args()
    torch.set_num_threads(1)

    rows: dict[str, list[dict[str, float]]] = {}
    for access in args.access.split(","):
        rows[access] = []
        print(f"== access {access}: {args.layouts} layouts, {args.episodes} episodes each")
        print(
            "seed  environment      model/opt final/opt search/opt model/naive naive/opt "
            "converge  train_s  service/opt service_s grid_s"
        )
        for i in range(args.layouts):
            r = bench_layout(access, args.seed + i, args.episodes, args.dqn)
            rows[access].append(r)
            print(
                f"{r['seed']:<5} {r['environment']:<16} {r['model_over_opt']:9.4f} "
                f"{r['greedy_over_opt']:9.4f} {r['search_over_opt']:10.4f} "
                f"{r['model_over_naive']:11.4f} "
                f"{r['naive_over_opt']:9.4f} {r['episodes_to_converge']:8d} "
                f"{r['train_s']:8.1f} {r['shipped_over_opt']:12.4f} {r['shipped_s']:9.1f} "
                f"{r['grid_s']:6.1f}"
                + (
                    f"  dqn model/opt {r['dqn_model_over_opt']:.4f} final/opt "
                    f"{r['dqn_over_opt']:.4f} converge {r['dqn_converge']}"
                    if args.dqn
                    else ""
                ),
                flush=True,
            )
    print("\n== summary (mean [min, max] over layouts)")
    for access, rs in rows.items():

        def stat(key: str, rs=rs) -> str:
            v = np.array([r[key] for r in rs], dtype=float)
            return f"{v.mean():.4f} [{v.min():.4f}, {v.max():.4f}]"

        print(f"{access}:")
        print(f"  D3QN model / grid optimum       {stat('model_over_opt')}   (goal >= 0.95)")
        print(f"  D3QN final policy / optimum     {stat('greedy_over_opt')}")
        print(f"  D3QN search / grid optimum      {stat('search_over_opt')}")
        print(f"  D3QN model / naive placement    {stat('model_over_naive')}")
        print(f"  naive / grid optimum            {stat('naive_over_opt')}")
        print(f"  episodes to converge            {stat('episodes_to_converge')}   (goal <= 300)")
        print(f"  training wall time, s           {stat('train_s')}")
        print(f"  `uavxai service` d3qn / optimum {stat('shipped_over_opt')}")
        print(f"  `uavxai service` d3qn wall, s   {stat('shipped_s')}")
        print(f"  grid optimum wall, s            {stat('grid_s')}")
        if args.dqn:
            print(f"  DQN model / grid optimum        {stat('dqn_model_over_opt')}")
            print(f"  DQN final policy / optimum      {stat('dqn_over_opt')}")
            print(f"  DQN episodes to converge        {stat('dqn_converge')}")
            print(f"  D3QN / DQN final train reward   {stat('d3qn_final_return_over_dqn')}")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")


if __name__ == "__main__":
    main()
