"""Long training runs behind the claims of docs/service/README.md (`make test-slow`)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from uavxai.comms.service_env import ServiceEnv
from uavxai.paths import scenarios_dir
from uavxai.scenario import default_scenario, load_scenario
from uavxai.service import d3qn
from uavxai.service.grid import solve_grid
from uavxai.service.train import train_command

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
        result = d3qn.train(env, d3qn.D3QNConfig(seed=seed))
        result.net.load_state_dict(result.best_state)
        greedy = d3qn.rollout(result.net, d3qn.fading_free(env))
        assert greedy.objective == pytest.approx(result.best_greedy)
        assert greedy.objective <= optimum * (1 + 1e-12)
        ratios.append(greedy.objective / optimum)
    assert np.mean(ratios) >= 0.95
