"""Long training runs behind the claims of docs/service/README.md (`make test-slow`)."""

from __future__ import annotations

import csv
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
import torch
from scipy import stats

from uavxai.learning import branching
from uavxai.learning.service import episodes_to_converge, train_command
from uavxai.paths import scenarios_dir
from uavxai.scenario import default_scenario, load_scenario
from uavxai.service import d3qn
from uavxai.service.grid import solve_grid
from uavxai.service.service_env import ServiceEnv

pytestmark = pytest.mark.slow


def test_demo_training_converges_and_beats_random(tmp_path):
    """`uavxai train scenarios/demo.yaml --algo d3qn` (300 episodes, D3QN + DQN + random)."""
    report = train_command(load_scenario(scenarios_dir() / "demo.yaml"), "d3qn", None, tmp_path)
    assert report["episodes"] == 300
    # the service point settles with at least 50 episodes to spare, within 5 % of the optimum
    assert report["episodes_to_converge"] <= 250
    assert report["final_over_optimum"] >= 0.95
    assert report["model_over_optimum"] >= report["final_over_optimum"] - 0.01
    assert report["beats"]["random"] == {"service_point": True, "training_reward": True}
    with (tmp_path / "learning_curve.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert {r["algo"] for r in rows} == {"d3qn", "dqn", "random"} and len(rows) == 900
    assert (tmp_path / "model.pt").stat().st_size < 1_000_000
    assert (tmp_path / "learning_curve.png").stat().st_size > 10_000


@pytest.mark.parametrize("access", ["shared", "ofdma"])
def test_d3qn_reaches_95_percent_of_the_optimum(access):
    """Five fresh urban layouts per access mode, fading-free, 300 episodes each: the policy
    `uavxai train` saves (the best evaluated one) flown greedily, over the exact optimum."""
    ratios = []
    for seed in range(2000, 2005):
        sc = default_scenario(seed=seed, comms={"access": access, "fading": "none"})
        env = ServiceEnv.from_scenario(sc)
        optimum = solve_grid(env.channel, env.space, env.power_levels).objective
        result = branching.train(env, branching.D3QNConfig(seed=seed))
        result.net.load_state_dict(result.best_state)
        greedy = d3qn.rollout(result.net, d3qn.fading_free(env))
        assert greedy.objective == pytest.approx(result.best_greedy)
        assert greedy.objective <= optimum * (1 + 1e-12)
        ratios.append(greedy.objective / optimum)
    assert np.mean(ratios) >= 0.95


def _greedy_curve(algo: str, seed: int) -> np.ndarray:
    torch.set_num_threads(1)
    env = ServiceEnv.from_scenario(load_scenario(scenarios_dir() / "demo.yaml"))
    cfg = (branching.D3QNConfig if algo == "d3qn" else branching.DQNConfig)(seed=seed)
    result = branching.train(env, cfg)
    return np.array([row["greedy_objective"] for row in result.curve])


def test_d3qn_converges_sooner_than_dqn_on_the_demo():
    """docs/service/README.md "D3QN against DQN": over training seeds 0-7 on demo.yaml (shared
    band) D3QN's greedy curve rises sooner (larger area under it, fewer episodes to converge)
    than DQN's, paired by seed, while both end at the same level."""
    jobs = [(a, s) for s in range(8) for a in ("d3qn", "dqn")]
    with ProcessPoolExecutor(2) as pool:
        algos, seeds = [a for a, _ in jobs], [s for _, s in jobs]
        curves = dict(zip(jobs, pool.map(_greedy_curve, algos, seeds), strict=True))
    auc = {a: np.array([curves[a, s].mean() for s in range(8)]) for a in ("d3qn", "dqn")}
    conv = {
        a: np.array([episodes_to_converge(curves[a, s])[0] for s in range(8)])
        for a in ("d3qn", "dqn")
    }
    final = {a: np.array([curves[a, s][-30:].mean() for s in range(8)]) for a in ("d3qn", "dqn")}
    gain = auc["d3qn"] - auc["dqn"]
    # paired one-sided t interval of the AUC gain: its lower 95 % bound above zero
    lower = gain.mean() - stats.t.ppf(0.95, len(gain) - 1) * stats.sem(gain)
    assert lower > 0, (gain, lower)
    assert conv["d3qn"].mean() < conv["dqn"].mean()
    assert np.sum(conv["d3qn"] < conv["dqn"]) >= 6
    # ... and the same final level: within 1 % of each other
    assert abs(final["d3qn"].mean() / final["dqn"].mean() - 1) < 0.01
