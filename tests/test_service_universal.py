"""The universal D3QN (issue 13): shipped models for every K, structure, refinement, channel
equations at the returned point, seeded training."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from uavxai.learning import checkpoint
from uavxai.learning import universal as universal_training
from uavxai.scenario import default_scenario
from uavxai.service import universal
from uavxai.service.grid import solve_grid
from uavxai.service.layouts import draw_layout, problem_scenario, random_problem
from uavxai.service.service_env import ServiceEnv, levels_to_power
from uavxai.service.stage import plan_service

ENV_PARAMS = {  # Al-Hourani (a, b, eta_LoS, eta_NLoS), written out again on purpose
    "suburban": (4.88, 0.43, 0.1, 21.0),
    "urban": (9.61, 0.16, 1.0, 20.0),
    "dense_urban": (12.08, 0.11, 1.6, 23.0),
    "highrise_urban": (27.23, 0.08, 2.3, 34.0),
}


@pytest.mark.parametrize("algo", ["d3qn", "dqn"])
def test_shipped_model_loads_and_plans_for_every_k(algo):
    path = universal.shipped_path(algo)
    assert path.stat().st_size < 300_000
    data = torch.load(path, map_location="cpu", weights_only=True)  # plain tensors and values
    assert data["format"] == checkpoint.FORMATS["universal"][0] and data["algo"] == algo
    meta = json.loads(path.with_suffix(".json").read_text())
    assert meta["k_range"] == [2, universal.K_MAX] and meta["config"]["dueling"] == (algo == "d3qn")
    net, info = universal.load(path)
    assert info["k_max"] >= 20 and net.dueling == (algo == "d3qn")
    for k in range(2, info["k_max"] + 1):
        sc = default_scenario(seed=k, comms={"users": {"count": k}, "fading": "none"})
        result = plan_service(sc, algo)
        assert result.extras["checkpoint"] == f"shipped:{path.name}"
        assert len(result.power_w) == k and result.power_w.sum() <= 1.0 + 1e-12
        assert result.objective >= result.extras["d3qn_alone_objective"] > 0


def test_power_branches_are_permutation_equivariant_and_moves_invariant():
    torch.manual_seed(0)
    net = universal.SetQNetwork(6, hidden=16)
    env = random_problem(np.random.default_rng(5), (7, 7))
    obs = universal.observe(env)
    perm = np.random.default_rng(1).permutation(7)
    ones = torch.ones(1, 7, dtype=torch.bool)
    with torch.no_grad():
        m1, p1 = net(torch.tensor(obs.glob)[None], torch.tensor(obs.users)[None], ones)
        m2, p2 = net(torch.tensor(obs.glob)[None], torch.tensor(obs.users[perm])[None], ones)
        # padding a user that the mask hides changes nothing
        padded = torch.cat([torch.tensor(obs.users), torch.full((3, obs.users.shape[1]), 9.0)])
        mask = torch.tensor([[True] * 7 + [False] * 3])
        m3, p3 = net(torch.tensor(obs.glob)[None], padded[None], mask)
    torch.testing.assert_close(m1, m2)
    torch.testing.assert_close(p1[0, perm], p2[0])
    torch.testing.assert_close(m1, m3)
    torch.testing.assert_close(p1, p3[:, :7])


def test_numpy_policy_matches_the_torch_network():
    torch.manual_seed(1)
    net = universal.SetQNetwork(6, hidden=32, dueling=True)
    policy = universal.NumpyPolicy(net)
    for i in range(5):
        env = random_problem(np.random.default_rng([3, i]), (2, 20))
        obs = universal.observe(env)
        np.testing.assert_array_equal(policy(obs), universal.greedy_action(net, obs))


def test_planner_rates_are_the_channel_equations_at_its_point():
    for access, environment in (("shared", "urban"), ("ofdma", "highrise_urban")):
        users = draw_layout(np.random.default_rng(4), 8, "clustered")
        sc = problem_scenario(users, access, environment)
        r = plan_service(sc, "d3qn")
        a, b, eta_los, eta_nlos = ENV_PARAMS[environment]
        x, y, h = r.service_point
        d = np.sqrt((users[:, 0] - x) ** 2 + (users[:, 1] - y) ** 2 + h**2)  # eq 1
        theta = np.degrees(np.arcsin(h / d))
        p_los = 1.0 / (1.0 + a * np.exp(-b * (theta - a)))
        fspl = 20 * np.log10(4 * np.pi * 2e9 * d / 299_792_458.0)
        g = 10 ** (-(fspl + p_los * eta_los + (1 - p_los) * eta_nlos) / 10)  # eqs 2-3
        p = r.power_w
        noise = 10 ** ((-100 - 30) / 10)
        if access == "shared":
            sinr = g * p / (g * (p.sum() - p) + noise)  # eq 5
            rate = 1e6 * np.log2(1 + sinr)  # eq 4
        else:
            sinr = g * p / (noise / 8)
            rate = 1e6 / 8 * np.log2(1 + sinr)
        np.testing.assert_allclose(r.rate_bps, rate, rtol=1e-9)
        lam = int((rate < 1e5).sum())
        assert r.objective == pytest.approx(rate.sum() / 2**lam, rel=1e-9)
        np.testing.assert_allclose(p, levels_to_power(r.levels, 1.0, 6))
        assert r.qos_satisfied == 8 - lam


def test_refine_never_leaves_the_lattice_and_never_loses():
    users = draw_layout(np.random.default_rng(2), 3, "uniform")
    sc = problem_scenario(users, "ofdma", "dense_urban")
    sc = sc.model_copy(update={"service": sc.service.model_copy(update={"step_m": 50.0})})
    env = ServiceEnv.from_scenario(sc)
    opt = solve_grid(env.channel, env.space, env.power_levels).objective
    rng = np.random.default_rng(0)
    axes = env.space.axes()
    for _ in range(5):
        start = np.array([rng.choice(a) for a in axes])
        levels = rng.integers(0, 6, size=3)
        levels[0] = max(levels[0], 1)
        before = universal.objective_at(env, start, levels)
        pos, lev, value, _ = universal.refine(env.channel, env.space, 6, start, levels)
        assert before <= value <= opt * (1 + 1e-12)
        assert value == pytest.approx(universal.objective_at(env, pos, lev))
        for axis, v in zip(axes, pos, strict=True):
            assert np.min(np.abs(axis - v)) < 1e-9  # a lattice point


def test_training_is_seeded_and_reproducible():
    cfg = universal_training.UniversalConfig(
        episodes=3, train_steps=12, learning_starts=8, batch_size=8, eval_every=3,
        eval_problems=2, hidden=16, k_range=(2, 5), seed=3,
    )
    a, b = universal_training.train(cfg), universal_training.train(cfg)
    other = {**universal_training.config_dict(cfg), "seed": 4}
    c = universal_training.train(universal_training.UniversalConfig(**other))
    sa, sb, sc = a.net.state_dict(), b.net.state_dict(), c.net.state_dict()
    assert all(torch.equal(sa[n], sb[n]) for n in sa)
    assert not all(torch.equal(sa[n], sc[n]) for n in sa)
    assert a.rows == [{**row, "wall_s": a.rows[i]["wall_s"]} for i, row in enumerate(b.rows)]


def test_dqn_ablation_has_no_value_head(tmp_path):
    net = universal.SetQNetwork(6, hidden=16, dueling=False)
    assert net.value is None
    universal_training.save(tmp_path / "m.pt", net, "dqn", {"note": "test"})
    loaded, info = universal.load(tmp_path / "m.pt")
    assert info["algo"] == "dqn" and not info["dueling"]
    assert json.loads((tmp_path / "m.json").read_text()) == {"note": "test"}


def test_plan_levels_are_the_exact_power_optimum_at_its_point_for_small_k():
    from uavxai.service.grid import optimal_levels

    torch.manual_seed(2)
    policy = universal.NumpyPolicy(universal.SetQNetwork(6, hidden=16))
    for access in ("shared", "ofdma"):
        users = draw_layout(np.random.default_rng(6), 9, "uniform")
        env = ServiceEnv.from_scenario(problem_scenario(users, access, "urban"))
        result = universal.plan(policy, env)
        _, exact = optimal_levels(env.channel, env.channel.mean_gain(result.position), 6)
        assert result.objective == pytest.approx(exact, rel=1e-12)
        assert result.objective >= result.flight.objective
        assert result.objective == pytest.approx(
            universal.objective_at(env, result.position, result.levels)
        )


def test_validate_refuses_a_k_the_shipped_model_does_not_serve(tmp_path, capsys) -> None:
    from uavxai.cli import main

    path = tmp_path / "k30.yaml"
    path.write_text("name: k30\ncomms: {users: {count: 30}}\n")
    assert main(["validate", str(path)]) == 2
    assert "serves 2 to 20" in capsys.readouterr().err
    path.write_text("name: k30\ncomms: {users: {count: 30}}\nservice: {planner: grid}\n")
    assert main(["validate", str(path)]) == 0


def test_finetune_continues_the_shipped_model_on_one_layout(tmp_path, capsys) -> None:
    """`uavxai train --stage service --finetune` starts from the shipped universal model,
    trains on the scenario's layout alone (seeded: twice the same weights), never returns a
    network worse on that layout than the one it started from, and writes a model that
    `service.checkpoint` flies as the zero-shot one is flown."""
    import yaml

    from uavxai.cli import main

    users = [[800, 820], [810, 830], [1150, 1190], [1000, 900], [1190, 810]]
    spec = {
        "name": "ft", "seed": 3,
        "comms": {"access": "ofdma", "environment": "highrise_urban",
                  "users": {"positions": users}},
        "service": {"planner": "d3qn", "platform": "hover"},
    }  # fmt: skip
    path = tmp_path / "ft.yaml"
    path.write_text(yaml.safe_dump(spec))
    reports = []
    for run in ("a", "b"):
        out = tmp_path / run
        argv = ["train", str(path), "--stage", "service", "--algo", "d3qn", "--finetune"]
        assert main([*argv, "--episodes", "12", "--out", str(out)]) == 0
        reports.append(json.loads((out / "train_report.json").read_text()))
    a, b = reports
    alone = a["network_alone_over_optimum"]
    assert alone["after"] >= alone["before"] > 0
    assert a["planner_over_optimum"]["after"] >= 0.99
    wa = torch.load(tmp_path / "a" / "model.pt", weights_only=True)["state_dict"]
    wb = torch.load(tmp_path / "b" / "model.pt", weights_only=True)["state_dict"]
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    if a["best_episode"] > 0:  # it moved: the weights are not the shipped ones
        shipped, _ = universal.load(universal.shipped_path("d3qn"))
        assert not all(torch.equal(wa[k], v) for k, v in shipped.state_dict().items())

    model = str(tmp_path / "a" / "model.pt")
    scenario = default_scenario(
        "ft", seed=3, comms=spec["comms"], service={**spec["service"], "checkpoint": model}
    )
    result = plan_service(scenario).to_summary()
    assert result["checkpoint"] == model
    optimum = a["grid_objective"]
    assert result["d3qn_alone_objective"] / optimum == pytest.approx(alone["after"], rel=1e-9)

    assert main(["train", str(path), "--stage", "avoidance", "--algo", "dqn", "--finetune",
                 "--out", str(tmp_path / "c")]) == 2  # fmt: skip
    assert "--finetune is for --stage service" in capsys.readouterr().err
