"""The service stage's training commands (`uavxai train --stage service`).

``uavxai train SCENARIO --stage service --algo d3qn|dqn`` calls :func:`train_command`: it
trains the requested algorithm on the scenario's user layout, and — for the comparison figure
of the paper — the other one and the random baseline with the same budget, then writes

- ``model.pt``: the requested model (load it with ``service.checkpoint``) — the policy, among
  those evaluated after each episode, whose greedy flight found the best service point;
- ``learning_curve.csv``: one row per algorithm and episode;
- ``learning_curve.png``: left, the objective R/2^lambda of the service point each method
  would pick after every episode (the greedy policy for D3QN/DQN, the best of ``steps``
  random draws for random) against the exact grid optimum and the naive placement; right,
  the mean reward per step while training (epsilon-greedy), the paper's convergence plot.

"Episodes to converge" is the first episode from which the running mean (10 episodes) stays
within 5 % of the final level (the mean of the last 10 % of episodes); it is reported for the
greedy objective (``episodes_to_converge``) and for the training reward (``..._return``).

``uavxai train SCENARIO --stage service --algo d3qn|dqn --finetune`` calls
:func:`finetune_command` instead: it continues the universal model's training (the shipped
one, or a universal ``service.checkpoint``) on the scenario's layout alone and writes
``model.pt`` in the universal format; ``service.checkpoint: .../model.pt`` then flies it as
the zero-shot model is flown (network, refinement, power step). The report gives the
network alone and the planner before and after, against the exact optimum.

``uavxai train SCENARIO --stage universal --algo d3qn|dqn`` trains the universal model of
:mod:`uavxai.learning.universal` (any K from 2 to 20, both access modes, all four
environments), the model ``service.planner: d3qn|dqn`` flies zero-shot; the shipped ones in
``uavxai/service/checkpoints`` are its ``model.pt`` and ``model.json``.
"""

from __future__ import annotations

import copy
import csv
import io
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from uavxai.learning import branching
from uavxai.outputs import write_figure, write_output
from uavxai.scenario import Scenario
from uavxai.service import d3qn
from uavxai.service.grid import solve_grid
from uavxai.service.random_search import random_search
from uavxai.service.service_env import ServiceEnv

DEFAULT_EPISODES = 300
CONVERGENCE_TOLERANCE = 0.05
SMOOTHING_EPISODES = 10


def episodes_to_converge(
    values: np.ndarray, tol: float = CONVERGENCE_TOLERANCE, window: int = SMOOTHING_EPISODES
) -> tuple[int, float]:
    """(first episode, 1-based, from which the running mean stays within ``tol`` of the final
    level; the final level = mean of the last 10 % of episodes, at least ``window``)."""
    values = np.asarray(values, dtype=float)
    final = float(values[-max(window, len(values) // 10) :].mean())
    smooth = running_mean(values, window)
    outside = np.flatnonzero(np.abs(smooth - final) > tol * abs(final))
    return (int(outside[-1]) + 2 if outside.size else 1), final


def running_mean(values: np.ndarray, window: int) -> np.ndarray:
    c = np.cumsum(np.insert(np.asarray(values, dtype=float), 0, 0.0))
    n = np.minimum(np.arange(1, len(values) + 1), window)
    return (c[1:] - c[np.arange(1, len(values) + 1) - n]) / n


def train_command(scenario: Scenario, algo: str, episodes: int | None, out: Path) -> dict[str, Any]:
    """Train ``algo`` on the scenario's layout; write model.pt and the learning curves."""
    torch.set_num_threads(1)
    episodes = episodes or DEFAULT_EPISODES
    env = ServiceEnv.from_scenario(scenario)
    configs = {
        "d3qn": branching.D3QNConfig(episodes=episodes, seed=scenario.seed),
        "dqn": branching.DQNConfig(episodes=episodes, seed=scenario.seed),
    }
    runs, grid = _train_all(env, algo, configs, episodes, scenario.seed)
    chosen, episode = _save_best(out, runs[algo]["result"], algo, configs[algo], scenario)
    _write_csv(out / "learning_curve.csv", runs)
    summary = {name: _run_summary(run, grid.objective) for name, run in runs.items()}
    _plot(out / "learning_curve.png", runs, grid.objective, env.naive_objective, scenario)
    mine = summary[algo]
    return {
        "algo": algo,
        "episodes": episodes,
        "model": str(out / "model.pt"),
        "model_episode": episode,
        "model_objective": chosen.best_greedy,
        "model_over_optimum": chosen.best_greedy / grid.objective,
        **mine,
        "grid_objective": grid.objective,
        "naive_objective": env.naive_objective,
        "beats": {
            name: {
                "service_point": mine["final_objective"] > s["final_objective"],
                "training_reward": mine["final_return_bps"] > s["final_return_bps"],
            }
            for name, s in summary.items()
            if name != algo
        },
        "comparison": summary,
        "learning_curve": str(out / "learning_curve.png"),
    }


def finetune_command(
    scenario: Scenario, algo: str, episodes: int | None, out: Path
) -> dict[str, Any]:
    """Fine-tune the universal ``algo`` model on the scenario's layout; write model.pt."""
    from dataclasses import replace

    from rich.console import Console

    from uavxai.learning import universal as trainer
    from uavxai.service import universal
    from uavxai.service.stage import universal_model_path, universal_policy

    universal_policy(scenario, algo)  # the model fits this scenario (K, levels, algo)
    start_path = universal_model_path(scenario, algo)
    net, _ = universal.load(start_path)
    env = d3qn.fading_free(ServiceEnv.from_scenario(scenario))
    cfg = replace(
        trainer.FINETUNE, episodes=episodes or trainer.FINETUNE.episodes, seed=scenario.seed
    )
    before = universal.plan(universal.NumpyPolicy(net), env)
    with Console(stderr=True).status(f"fine-tuning {algo} on {scenario.name} ..."):
        log = trainer.finetune(net, env, cfg)
        after = universal.plan(universal.NumpyPolicy(log.net), env)
        optimum = solve_grid(env.channel, env.space, env.power_levels).objective
    trainer.save(out / "model.pt", log.net, algo, {
        "fine_tuned_on": scenario.name, "seed": scenario.seed, "from": str(start_path),
        "episodes": log.episodes, "best_episode": log.best_episode,
        "config": trainer.config_dict(log.config),
    })  # fmt: skip
    return {
        "algo": algo,
        "model": str(out / "model.pt"),
        "use_with": f"service.checkpoint: {out / 'model.pt'}",
        "started_from": str(start_path),
        "episodes": log.episodes,
        "best_episode": log.best_episode,
        "wall_s": round(log.wall_s, 1),
        "network_alone_over_optimum": {
            "before": before.flight.objective / optimum,
            "after": after.flight.objective / optimum,
        },
        "planner_over_optimum": {
            "before": before.objective / optimum,
            "after": after.objective / optimum,
        },
        "grid_objective": optimum,
    }


def _train_all(env, algo: str, configs: dict, episodes: int, seed: int):
    """Train ``algo`` and the other learner, run random search and solve the exact grid, with
    one progress bar each; returns (runs by name, the grid optimum)."""
    from rich.progress import BarColumn, MofNCompleteColumn, TextColumn

    from uavxai.progress import progress_bar

    other = "dqn" if algo == "d3qn" else "d3qn"
    columns = (
        TextColumn("{task.description:<8}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[status]}"),
    )
    runs: dict[str, dict[str, Any]] = {}
    with progress_bar(columns=columns) as progress:
        for name in (algo, other):
            task = progress.add_task(name, total=episodes, status="")
            result = branching.train(
                env, configs[name], on_episode=_progress(progress, task, env.naive_objective)
            )
            runs[name] = {"curve": result.curve, "wall_s": result.wall_s, "result": result}
        task = progress.add_task("random", total=episodes, status="")
        runs["random"] = _random_curve(env, episodes, seed, progress, task)
        task = progress.add_task("grid", total=1, status="exact optimum ...")
        t0 = time.perf_counter()
        grid = solve_grid(d3qn.fading_free(env).channel, env.space, env.power_levels)
        progress.update(task, advance=1, status=f"{time.perf_counter() - t0:.1f} s")
    return runs, grid


def _save_best(out: Path, chosen, algo: str, config, scenario: Scenario):
    """model.pt is the evaluated policy whose greedy flight found the best service point (the
    last one can be a little worse: learning goes on at epsilon = 0.1)."""
    net = copy.deepcopy(chosen.net)
    net.load_state_dict(chosen.best_state)
    episode = 1 + int(np.argmax([row["greedy_objective"] for row in chosen.curve]))
    branching.save_checkpoint(
        out / "model.pt",
        net,
        algo,
        config,
        {
            "scenario": scenario.name,
            "seed": scenario.seed,
            "access": scenario.comms.access,
            "episode": episode,
            "greedy_objective": chosen.best_greedy,
        },
    )
    return chosen, episode


def _run_summary(run: dict[str, Any], optimum: float) -> dict[str, Any]:
    greedy = np.array([row["greedy_objective"] for row in run["curve"]])
    ret = np.array([row["return"] for row in run["curve"]])
    converge, final = episodes_to_converge(greedy)
    converge_ret, final_ret = episodes_to_converge(ret)
    return {
        "final_objective": final,
        "final_over_optimum": final / optimum,
        "episodes_to_converge": converge,
        "final_return_bps": final_ret,
        "episodes_to_converge_return": converge_ret,
        "wall_s": round(run["wall_s"], 2),
    }


def _progress(progress, task, naive: float) -> Callable[[int, dict[str, float]], None]:
    def update(_episode: int, row: dict[str, float]) -> None:
        status = f"greedy/naive {row['greedy_objective'] / naive:.3f}  eps {row['epsilon']:.2f}"
        progress.update(task, advance=1, status=status)

    return update


def _random_curve(env: ServiceEnv, episodes: int, seed: int, progress, task) -> dict[str, Any]:
    t0 = time.perf_counter()
    rng = np.random.default_rng(seed)
    curve = []
    for episode in range(episodes):
        ep = random_search(env, env.steps, rng)
        curve.append(
            {
                "episode": episode + 1,
                "epsilon": 1.0,
                "return": ep.ret / env.steps,
                "train_objective": ep.objective,
                "greedy_objective": ep.objective,
            }
        )
        progress.update(task, advance=1)
    return {"curve": curve, "wall_s": time.perf_counter() - t0}


# learning_curve.csv of the service stage, one row per algorithm and episode
CURVE_COLUMNS = ("algo", "episode", "epsilon", "return_bps", "train_objective", "greedy_objective")


def _write_csv(path: Path, runs: dict[str, dict[str, Any]]) -> None:
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(CURVE_COLUMNS)
    for name, run in runs.items():
        for row in run["curve"]:
            writer.writerow(
                [
                    name,
                    row["episode"],
                    f"{row['epsilon']:.4f}",
                    f"{row['return']:.6g}",
                    f"{row['train_objective']:.6g}",
                    f"{row['greedy_objective']:.6g}",
                ]
            )
    write_output(path, buf.getvalue())  # whole or not at all


def _plot(
    path: Path, runs: dict[str, dict[str, Any]], optimum: float, naive: float, sc: Scenario
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colours = {"d3qn": "tab:red", "dqn": "tab:blue", "random": "tab:gray"}
    labels = {"d3qn": "D3QN", "dqn": "DQN", "random": "Random"}
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5), constrained_layout=True)
    for name in ("d3qn", "dqn", "random"):
        curve = runs[name]["curve"]
        ep = [row["episode"] for row in curve]
        greedy = np.array([row["greedy_objective"] for row in curve]) / 1e6
        ret = np.array([row["return"] for row in curve]) / 1e6
        left.plot(ep, greedy, color=colours[name], alpha=0.2, lw=0.8)
        left.plot(
            ep,
            running_mean(greedy, SMOOTHING_EPISODES),
            color=colours[name],
            lw=2,
            label=labels[name],
        )
        right.plot(
            ep, running_mean(ret, SMOOTHING_EPISODES), color=colours[name], lw=2, label=labels[name]
        )
    left.axhline(optimum / 1e6, color="k", ls="--", lw=1, label="grid optimum")
    left.axhline(naive / 1e6, color="tab:green", ls=":", lw=1.5, label="naive placement")
    left.set(
        xlabel="episode",
        ylabel="R / 2^λ of the service point [Mbit/s]",
        title="Service point of the greedy policy (fading-free)",
    )
    right.set(
        xlabel="episode",
        ylabel="mean reward per step [Mbit/s]",
        title="Reward while training (ε-greedy)",
    )
    for ax in (left, right):
        ax.grid(alpha=0.3)
        ax.legend(loc="lower right")
    c = sc.comms
    fig.suptitle(
        f"{sc.name}: K = {c.users.k}, {c.access}, {c.environment}, fading {c.fading}, "
        f"seed {sc.seed}"
    )
    write_figure(path, fig, dpi=110)
    plt.close(fig)
