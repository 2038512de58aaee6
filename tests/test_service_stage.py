"""The service-point stage: planners, summary fields, checkpoints, determinism, the CLI."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from uavxai.cli import main as cli_main
from uavxai.errors import CheckpointError, ScenarioError, UserError
from uavxai.learning import branching
from uavxai.learning.service import CURVE_COLUMNS, train_command
from uavxai.paths import scenarios_dir
from uavxai.scenario import default_scenario, load_scenario
from uavxai.service import d3qn
from uavxai.service.service_env import ServiceEnv
from uavxai.service.stage import plan_service, run_service_stage

SERVICE_FIELDS = (
    "service_point", "power_w", "sinr_db", "rate_bps", "sum_rate_bps", "qos_satisfied"
)


def small(seed: int = 0, **service):
    return default_scenario(
        seed=seed,
        comms={"users": {"count": 3}, "power_levels": 3, "access": "ofdma", "fading": "none"},
        service={"steps": 20, "step_m": 25, **service},
    )


def test_random_planner_summary_is_plain_json_and_consistent():
    s = run_service_stage(small(), "random")
    assert json.loads(json.dumps(s)) == s
    for key in SERVICE_FIELDS:
        assert key in s
    assert len(s["power_w"]) == len(s["rate_bps"]) == len(s["sinr_db"]) == 3
    assert sum(s["power_w"]) <= 1.0 + 1e-12
    assert s["sum_rate_bps"] == pytest.approx(sum(s["rate_bps"]))
    assert s["qos_satisfied"] == sum(r >= 1e5 for r in s["rate_bps"])
    lam = 3 - s["qos_satisfied"]
    assert s["objective"] == pytest.approx(s["sum_rate_bps"] / 2**lam)
    x, y, h = s["service_point"]
    assert 750 <= x <= 1250 and 750 <= y <= 1250 and 50 <= h <= 300
    assert s["planner"] == "random" and s["search_points"] == 20


def test_same_seed_same_service_point_other_seed_other_users():
    a, b = run_service_stage(small(3), "random"), run_service_stage(small(3), "random")
    c = run_service_stage(small(4), "random")
    assert a["service_point"] == b["service_point"] and a["power_w"] == b["power_w"]
    assert a["users"] == b["users"] != c["users"]


def test_grid_planner_is_the_best_of_all():
    sc = small(1, platform="hover")  # the paper's objective, of which grid is the exact optimum
    grid = plan_service(sc, "grid")
    rnd = plan_service(sc, "random")
    assert grid.objective >= rnd.objective
    assert grid.objective >= grid.naive_objective
    assert grid.extras["lattice_points"] == 21 * 21 * 11
    # the path drawn for the grid planner: from the start to the optimum
    np.testing.assert_allclose(grid.visited[-1], grid.service_point)


def test_unserved_user_has_null_sinr():
    sc = small()
    result = plan_service(sc, "random")
    result.levels[:] = 0
    result.sinr_db[:] = -np.inf
    assert result.to_summary()["sinr_db"] == [None, None, None]


def test_trained_checkpoint_is_flown_greedily_and_repeatably(tmp_path):
    sc = small(2)
    env = ServiceEnv.from_scenario(sc)
    cfg = branching.D3QNConfig(episodes=6, learning_starts=50, seed=2)
    net = branching.train(env, cfg).net
    path = tmp_path / "model.pt"
    branching.save_checkpoint(path, net, "d3qn", cfg, {})
    sc = sc.model_copy(update={"service": sc.service.model_copy(update={"checkpoint": str(path)})})
    first, second = plan_service(sc), plan_service(sc)
    np.testing.assert_array_equal(first.service_point, second.service_point)
    np.testing.assert_array_equal(first.power_w, second.power_w)
    assert first.extras["checkpoint"] == str(path)
    assert "finetune_episodes" not in first.extras
    assert len(first.visited) == 21  # start + 20 steps
    # the greedy flight is the same search the env would replay
    replay = d3qn.rollout(net, d3qn.fading_free(env))
    assert first.objective == pytest.approx(replay.objective)
    # a DQN planner refuses a D3QN model
    with pytest.raises(CheckpointError, match="it is a d3qn model but the planner is dqn"):
        plan_service(sc, "dqn")


def test_checkpoint_problems_are_user_errors(tmp_path):
    # the scenario itself refuses a checkpoint that does not exist
    with pytest.raises(ScenarioError, match=r"missing\.pt: no such file"):
        small(checkpoint=str(tmp_path / "missing.pt"))
    (tmp_path / "text.pt").write_text("hello")
    with pytest.raises(CheckpointError, match=r"text\.pt: not a readable torch checkpoint"):
        plan_service(small(checkpoint=str(tmp_path / "text.pt")), "d3qn")
    # the shipped universal models serve K = 2..20 with power_levels = 6
    with pytest.raises(CheckpointError, match="no shipped d3qn model for power_levels = 3"):
        plan_service(small(), "d3qn")
    many = default_scenario(comms={"users": {"count": 21}})
    with pytest.raises(CheckpointError, match="serves K = 2..20 users, the scenario has 21"):
        plan_service(many, "dqn")
    # a model for another K
    net = d3qn.BranchingQNetwork(3 + 4, 4, 3, 40, 3, dueling=True)
    branching.save_checkpoint(tmp_path / "k4.pt", net, "d3qn", branching.D3QNConfig(), {})
    with pytest.raises(CheckpointError, match="trained for K = 4 users, the scenario has 3"):
        plan_service(small(checkpoint=str(tmp_path / "k4.pt")), "d3qn")
    with pytest.raises(UserError, match="unknown"):
        plan_service(small(), "simulated_annealing")


def test_demo_scenario_out_of_the_box():
    """`service.checkpoint: null`: the shipped universal model, zero-shot."""
    sc = load_scenario(scenarios_dir() / "demo.yaml")
    result = plan_service(sc)
    assert result.planner == "d3qn"
    assert result.extras["checkpoint"] == "shipped:universal_d3qn_l6.pt"
    assert result.objective >= result.extras["d3qn_alone_objective"]
    assert result.qos_satisfied == 10
    # every user served and the search beats the naive placement (centroid, 100 m, equal power)
    assert result.objective > result.naive_objective


def test_cli_service_writes_the_summary(tmp_path, capsys):
    sc_file = tmp_path / "s.yaml"
    sc_file.write_text(
        "name: tiny\nseed: 5\ncomms: {users: {count: 3}, power_levels: 3, fading: none}\n"
        "service: {steps: 15, step_m: 25}\n"
    )
    out = tmp_path / "out"
    assert cli_main(["service", str(sc_file), "--planner", "random", "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert all(key in summary for key in SERVICE_FIELDS)
    capsys.readouterr()
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"name: tiny\nservice: {{checkpoint: {tmp_path / 'nothing.pt'}}}\n")
    assert cli_main(["service", str(bad), "--out", str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err
    assert "nothing.pt: no such file" in err and "Traceback" not in err


def test_train_command_writes_the_model_and_the_curves(tmp_path):
    sc = small(6)
    report = train_command(sc, "d3qn", 30, tmp_path)
    assert {p.name for p in tmp_path.iterdir()} == {
        "model.pt",
        "learning_curve.csv",
        "learning_curve.png",
    }
    with (tmp_path / "learning_curve.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 3 * 30 and {r["algo"] for r in rows} == {"d3qn", "dqn", "random"}
    assert tuple(rows[0]) == CURVE_COLUMNS
    assert (tmp_path / "learning_curve.png").stat().st_size > 10_000
    assert json.loads(json.dumps(report)) == report
    assert 1 <= report["episodes_to_converge"] <= 30
    assert report["grid_objective"] >= report["model_objective"]
    # model.pt is the best evaluated policy: flown by the stage it finds that same point
    service = sc.service.model_copy(update={"checkpoint": str(tmp_path / "model.pt")})
    flown = plan_service(sc.model_copy(update={"service": service}))
    assert flown.objective == pytest.approx(report["model_objective"], rel=1e-12)
    d3qn_rows = [float(r["greedy_objective"]) for r in rows if r["algo"] == "d3qn"]
    assert report["model_objective"] == pytest.approx(max(d3qn_rows), rel=1e-5)
