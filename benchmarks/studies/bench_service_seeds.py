"""D3QN against DQN on one scenario over several training seeds (the paper's convergence claim).

One learning curve is one draw: network initialisation, exploration and replay sampling all
follow the seed, and two seeds of the same algorithm can differ by more than D3QN and DQN do.
So this script trains both algorithms with the same budget on the same layout and channel
(the scenario's; default ``scenarios/demo.yaml``) for seeds 0..N-1 and prints, per algorithm,
the mean and a 95 % confidence interval over seeds, and the paired difference D3QN - DQN
(same seed, same layout) with its own interval, of:

- ``auc``: the greedy objective R/2^lambda after every episode, averaged over all episodes,
  over the grid optimum (how fast and how high the curve rises: the area under it);
- ``final``: the greedy objective over the last 10 % of episodes, over the optimum;
- ``model``: the policy `uavxai train` saves (best evaluated), over the optimum;
- ``converge``: episodes until the greedy curve stays within 5 % of its final level;
- ``reward``: mean training reward per step over the last 10 % of episodes (the paper's
  convergence plot), over the naive placement's objective.

With ``--plot PNG`` it draws the mean greedy curves with their 95 % bands.

    python benchmarks/studies/bench_service_seeds.py                         # 8 seeds, ~10 min
    python benchmarks/studies/bench_service_seeds.py --seeds 3 --episodes 100  # ~1 min
    python benchmarks/studies/bench_service_seeds.py --access ofdma --plot curves.png
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import torch
from scipy import stats

from uavxai.learning import branching
from uavxai.learning.service import SMOOTHING_EPISODES, episodes_to_converge, running_mean
from uavxai.scenario import Scenario, load_scenario
from uavxai.service import d3qn
from uavxai.service.grid import solve_grid
from uavxai.service.service_env import ServiceEnv

CONFIGS = {"d3qn": branching.D3QNConfig, "dqn": branching.DQNConfig}
METRICS = ("auc", "final", "model", "converge", "reward")


def run(scenario: Scenario, algo: str, seed: int, episodes: int, optimum: float) -> dict:
    torch.set_num_threads(1)
    env = ServiceEnv.from_scenario(scenario)
    result = branching.train(env, CONFIGS[algo](episodes=episodes, seed=seed))
    greedy = np.array([row["greedy_objective"] for row in result.curve]) / optimum
    tail = max(1, episodes // 10)
    returns = np.array([row["return"] for row in result.curve]) / env.naive_objective
    return {
        "algo": algo,
        "seed": seed,
        "curve": greedy,
        "auc": float(greedy.mean()),
        "final": float(greedy[-tail:].mean()),
        "model": result.best_greedy / optimum,
        "converge": episodes_to_converge(greedy)[0],
        "reward": float(returns[-tail:].mean()),
        "wall_s": result.wall_s,
    }


def interval(values: np.ndarray) -> str:
    """mean [95 % t interval] over seeds."""
    m = float(np.mean(values))
    if len(values) < 2:
        return f"{m:8.4f}"
    half = stats.t.ppf(0.975, len(values) - 1) * stats.sem(values)
    return f"{m:8.4f} [{m - half:8.4f}, {m + half:8.4f}]"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("scenario", nargs="?", default="scenarios/demo.yaml")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--episodes", type=int, default=300)
    ap.add_argument("--access", choices=("shared", "ofdma"), help="override comms.access")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plot", type=Path, help="write the mean greedy curves here")
    ap.add_argument("--json", type=Path, help="write every run's numbers and curve here")
    args = ap.parse_args()

    scenario = load_scenario(args.scenario)
    if args.access:
        scenario = scenario.model_copy(
            update={"comms": scenario.comms.model_copy(update={"access": args.access})}
        )
    env = ServiceEnv.from_scenario(scenario)
    grid = solve_grid(d3qn.fading_free(env).channel, env.space, env.power_levels)
    print(
        f"{scenario.name}: access {scenario.comms.access}, {scenario.comms.environment}, "
        f"fading {scenario.comms.fading}, K = {env.channel.k}; grid optimum "
        f"{grid.objective / 1e6:.4f} Mbit/s, naive / optimum "
        f"{env.naive_objective / grid.objective:.4f}; {args.seeds} seeds x "
        f"{args.episodes} episodes per algorithm"
    )
    jobs = [(a, s) for s in range(args.seeds) for a in CONFIGS]
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(run, scenario, a, s, args.episodes, grid.objective) for a, s in jobs]
        rows = []
        for f in futures:
            r = f.result()
            rows.append(r)
            print(
                f"  {r['algo']:<5} seed {r['seed']:<3} auc {r['auc']:.4f} final {r['final']:.4f} "
                f"model {r['model']:.4f} converge {r['converge']:4d} reward {r['reward']:.4f} "
                f"({r['wall_s']:.0f} s)",
                flush=True,
            )
    by = {a: sorted((r for r in rows if r["algo"] == a), key=lambda r: r["seed"]) for a in CONFIGS}
    print("\nmean [95 % CI] over seeds")
    for key in METRICS:
        a = np.array([r[key] for r in by["d3qn"]], dtype=float)
        b = np.array([r[key] for r in by["dqn"]], dtype=float)
        diff = a - b
        wins = int(np.sum(diff < 0) if key == "converge" else np.sum(diff > 0))
        print(
            f"  {key:<9} d3qn {interval(a)}   dqn {interval(b)}   d3qn - dqn {interval(diff)}"
            f"   d3qn better in {wins}/{len(diff)} seeds"
        )
    if args.json:
        runs = [{**r, "curve": r["curve"].tolist()} for r in rows]
        args.json.write_text(json.dumps(runs) + "\n")
    if args.plot:
        plot(by, args.plot, scenario, args.episodes)
        print(f"wrote {args.plot}")


def plot(by: dict, path: Path, scenario: Scenario, episodes: int) -> None:
    """Left: running means (10 episodes) of the greedy curves, mean over seeds and 95 % band.
    Right: each seed's episodes to converge."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(
        1, 2, figsize=(9, 4), gridspec_kw={"width_ratios": [3, 1]}, constrained_layout=True
    )
    x = np.arange(1, episodes + 1)
    for i, (algo, colour) in enumerate((("d3qn", "tab:blue"), ("dqn", "tab:orange"))):
        curves = np.array([running_mean(r["curve"], SMOOTHING_EPISODES) for r in by[algo]])
        m = curves.mean(axis=0)
        half = stats.t.ppf(0.975, len(curves) - 1) * stats.sem(curves, axis=0)
        ax.plot(x, m, color=colour, label=f"{algo.upper()} ({len(curves)} seeds)")
        ax.fill_between(x, m - half, m + half, color=colour, alpha=0.2, linewidth=0)
        conv = [r["converge"] for r in by[algo]]
        bx.scatter(np.full(len(conv), i) + np.linspace(-0.12, 0.12, len(conv)), conv, c=colour)
        bx.hlines(np.mean(conv), i - 0.25, i + 0.25, color=colour)
    ax.axhline(1.0, color="k", linestyle="--", linewidth=1, label="grid optimum")
    ax.set_ylim(0.5, 1.03)
    ax.set_xlabel("episode")
    ax.set_ylabel(f"greedy objective / optimum ({SMOOTHING_EPISODES}-episode mean)")
    ax.set_title(f"{scenario.name}: {scenario.comms.access}, {scenario.comms.environment}")
    ax.legend(loc="lower right")
    ax.grid(alpha=0.3)
    bx.set_xticks([0, 1], ["D3QN", "DQN"])
    bx.set_xlim(-0.5, 1.5)
    bx.set_ylabel("episodes to converge (within 5 %)")
    bx.grid(alpha=0.3, axis="y")
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
