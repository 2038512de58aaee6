"""Campaign throughput: seconds per kinematic episode for each method at 20 intruders (one
process), and the wall time of the same small campaign on 1 and 2 local workers.

    .venv/bin/python benchmarks/performance/bench_campaign.py [--episodes 4]

Prints numbers only; nothing is asserted.
"""

from __future__ import annotations

import argparse
import time

import torch

from uavxai.campaign import run_campaign, run_campaign_episode
from uavxai.scenario import default_scenario
from uavxai.vocabulary import avoidance_planners


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=4)
    ap.add_argument("--intruders", type=int, default=20)
    args = ap.parse_args()
    torch.set_num_threads(1)
    sc = default_scenario("bench-campaign")
    print(f"kinematic episodes at {args.intruders} intruders, seeds 0..{args.episodes - 1}")
    print(f"{'method':>11} {'s/episode':>10} {'steps':>7} {'ms/decision p50':>16}")
    for method in avoidance_planners():
        run_campaign_episode(sc, method, args.intruders, 0)  # load and warm up
        t0 = time.perf_counter()
        rows = [run_campaign_episode(sc, method, args.intruders, s) for s in range(args.episodes)]
        per = (time.perf_counter() - t0) / args.episodes
        steps = sum(r["steps"] for r in rows) / len(rows)
        ms = sorted(m for r in rows for m in r["decision_ms"])
        print(f"{method:>11} {per:10.3f} {steps:7.1f} {ms[len(ms) // 2]:16.2f}")

    methods, counts = ["mcts_fast", "dqn"], [5, 20]
    for workers in (1, 2):
        t0 = time.perf_counter()
        run_campaign(sc, methods, counts, args.episodes, workers=workers)
        wall = time.perf_counter() - t0
        n = len(methods) * len(counts) * args.episodes
        print(f"campaign of {n} episodes on {workers} worker(s): {wall:.2f} s wall")


if __name__ == "__main__":
    main()
