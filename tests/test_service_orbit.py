"""Orbit-aware placement (``service.platform: orbit``): the orbit objective, its exact power
DP, the exact lattice branch-and-bound, the planners and the schema key."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from uavxai.cli import main
from uavxai.comms.channel import Channel
from uavxai.dynamics.orbit import scenario_orbit_radius
from uavxai.scenario import default_scenario
from uavxai.service import grid
from uavxai.service.orbit import (
    OrbitObjective,
    bound_tables,
    orbit_gain_means,
    solve_grid_orbit,
)
from uavxai.service.orbit_rate import orbit_average
from uavxai.service.service_env import SearchSpace, levels_to_power
from uavxai.service.stage import plan_service
from uavxai.sim.mission import MissionConfig


def small(access: str, seed: int = 4, **comms):
    return default_scenario(
        seed=seed,
        comms={"users": {"count": 3, "region": {"x": [800, 1200], "y": [850, 1150]}},
               "access": access, "power_levels": 3, "environment": "dense_urban", **comms},
        service={"step_m": 25},
    )  # fmt: skip


@pytest.mark.parametrize("access", ["shared", "ofdma"])
@pytest.mark.parametrize(("k", "L", "qos"), [(3, 4, 2e5), (4, 3, 3e5)])
def test_orbit_power_dp_equals_brute_force_and_the_orbit_average(access, k, L, qos):
    sc = default_scenario(seed=k + L, comms={"users": {"count": k}, "access": access,
                                             "power_levels": L, "qos_rate_bps": qos})
    ch = Channel.from_scenario(sc)
    objective = OrbitObjective(ch, L, 106.0)
    every = np.array(list(itertools.product(range(L), repeat=k)))
    rng = np.random.default_rng(k)
    centres = np.column_stack([rng.uniform(750, 1250, 4), rng.uniform(750, 1250, 4),
                               rng.uniform(50, 300, 4)])  # fmt: skip
    exact = objective.optimal(centres)
    for c, value in zip(centres, exact, strict=True):
        brute = objective.value(c, every)
        # the scorer is orbit_rate's orbit average, allocation by allocation
        power = levels_to_power(every, ch.p_max_w, L)
        reference = orbit_average(ch, np.broadcast_to(c, (len(every), 3)), 106.0, power)
        np.testing.assert_allclose(brute, reference.objective, rtol=1e-12)
        levels, best = objective.optimal_levels(c)
        assert value == pytest.approx(brute.max(), rel=1e-12)
        assert best == pytest.approx(brute.max(), rel=1e-12)
        assert float(objective.value(c, levels)[0]) == pytest.approx(brute.max(), rel=1e-12)


@pytest.mark.parametrize("access", ["shared", "ofdma"])
@pytest.mark.parametrize("environment", ["suburban", "highrise_urban"])
def test_bound_tables_bound_the_orbit_rates_and_ofdma_tightly(access, environment):
    sc = default_scenario(seed=3, comms={"access": access, "environment": environment,
                                         "users": {"count": 5}, "qos_rate_bps": 1.2e6})
    ch = Channel.from_scenario(sc)
    objective = OrbitObjective(ch, 6, 106.0)
    rng = np.random.default_rng(0)
    centres = np.column_stack([rng.uniform(750, 1250, 100), rng.uniform(750, 1250, 100),
                               rng.uniform(50, 300, 100)])  # fmt: skip
    arith, geo, harm = orbit_gain_means(objective, centres)
    bound, _ = bound_tables(ch, 6, np.array([arith, geo, geo, geo / harm]))
    exact, _ = objective.tables(centres)
    assert (bound >= exact).all()  # at single centres too, for every level and total
    jensen, _ = grid.level_rates(ch, arith, 6)
    assert (bound <= jensen * (1 + 1e-12)).all()  # never looser than Jensen (to rounding)
    if access == "ofdma":  # the second bound: far tighter than Jensen's
        assert float((bound - exact).sum()) < 0.1 * float((jensen - exact).sum())


@pytest.mark.parametrize("access", ["shared", "ofdma"])
def test_orbit_branch_and_bound_finds_the_lattice_optimum(access):
    sc = small(access, qos_rate_bps=4e5)
    ch, space = Channel.from_scenario(sc), SearchSpace.from_scenario(sc)
    objective = OrbitObjective(ch, 3, 106.0)
    result = solve_grid_orbit(objective, space)
    mesh = np.stack(np.meshgrid(*space.axes(), indexing="ij"), axis=-1).reshape(-1, 3)
    values = objective.optimal(mesh)  # brute force: the exact DP at every lattice point
    assert result.lattice_points == len(mesh) == 17 * 13 * 11
    assert result.objective == pytest.approx(values.max(), rel=1e-12)
    achieved = orbit_average(ch, result.position, 106.0, result.power_w).objective
    assert float(achieved) == pytest.approx(values.max(), rel=1e-12)
    assert result.evaluations < len(mesh)  # it pruned
    # the orbit optimum is not the hover one: the objective really changed
    hover = ch.evaluate(mesh, ch.equal_power()).objective
    assert not np.allclose(mesh[np.argmax(values)], mesh[np.argmax(hover)])


def test_the_planners_score_the_radius_the_mission_flies():
    sc = default_scenario(environment={"wind": {"speed_mps": 6}})
    assert scenario_orbit_radius(sc) == MissionConfig.from_scenario(sc, (0, 0, 100)).radius_m
    calm = default_scenario()
    assert scenario_orbit_radius(sc) > scenario_orbit_radius(calm)  # downwind needs more room
    given = default_scenario(mission={"orbit_radius_m": 250})
    assert scenario_orbit_radius(given) == 250.0
    assert plan_service(given, "random").extras["orbit_radius_m"] == 250.0


@pytest.mark.parametrize("planner", ["grid", "random"])
def test_orbit_platform_reports_its_own_objective(planner):
    sc = small("ofdma", qos_rate_bps=4e5)
    r = plan_service(sc, planner)
    assert r.extras["platform"] == "orbit"
    ch = Channel.from_scenario(sc)
    avg = orbit_average(ch, r.service_point, r.extras["orbit_radius_m"], r.power_w)
    assert r.extras["orbit_objective"] == pytest.approx(float(avg.objective), rel=1e-12)
    assert r.extras["orbit_sum_rate_bps"] == pytest.approx(float(avg.sum_rate_bps), rel=1e-12)
    hover = plan_service(sc.model_copy(update={"service": sc.service.model_copy(
        update={"platform": "hover"})}), planner)  # fmt: skip
    assert r.extras["orbit_objective"] >= hover.extras["orbit_objective"] * (1 - 1e-12)
    if planner == "grid":  # exact both ways: each wins its own objective
        assert hover.objective >= r.objective * (1 - 1e-12)


def test_orbit_aware_d3qn_beats_hover_placement_on_the_orbit_near_the_qos_edge():
    """OFDMA with a QoS rate near what the edge users can get: the hover placement leaves
    users below QoS on the orbit the aircraft actually flies; the orbit-aware one may not."""
    orbit_values, hover_values = [], []
    for seed in range(6):
        values = {}
        for platform in ("orbit", "hover"):
            sc = default_scenario(seed=seed, comms={"access": "ofdma", "qos_rate_bps": 1.2e6},
                                  service={"platform": platform})  # fmt: skip
            values[platform] = plan_service(sc, "d3qn").extras["orbit_objective"]
        orbit_values.append(values["orbit"])
        hover_values.append(values["hover"])
    orbit_values, hover_values = np.array(orbit_values), np.array(hover_values)
    assert (orbit_values >= hover_values * (1 - 1e-12)).all(), (orbit_values, hover_values)
    assert (orbit_values > 1.5 * hover_values).sum() >= 2  # a QoS user kept: 2x the objective


def test_bad_platform_is_refused_naming_the_field_and_the_choices(tmp_path: Path, capsys):
    path = tmp_path / "s.yaml"
    path.write_text("name: s\nservice: {platform: hoover}\n")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "service.platform" in err and "Traceback" not in err
    assert "orbit" in err and "hover" in err


@pytest.mark.parametrize("platform", ["orbit", "hover"])
def test_mission_reports_the_prediction_of_the_placement_it_flew(platform):
    """JSBSim flies the plan's orbit; the summary's prediction is the planner's own orbit
    average of that placement, and with fading none what is delivered on the flown orbit is
    close to it (the aircraft holds the radius; no re-plan, static users)."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.build import fly
    from uavxai.sim.spec import episode_spec
    from uavxai.sim.steps import Service

    sc = default_scenario(
        seed=2, comms={"access": "ofdma", "fading": "none", "qos_rate_bps": 1.2e6},
        service={"platform": platform}, intruders={"count": 0, "flow": "none"},
        avoidance={"planner": "none"}, mission={"service_s": 60, "return_home": False},
        ownship={"start": {"x": 700, "y": 700}}, log={"rerun": False},
    )  # fmt: skip
    plan = plan_service(sc)
    goal = tuple(float(v) for v in plan.service_point)
    service = Service(sc, Channel.from_scenario(sc, users=plan.users), plan.power_w, None)
    spec = episode_spec(sc, goal=goal, intruders=[], mission=True, dynamics="jsbsim")
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    result = fly(spec, planner, engine_steps=[service])
    m = result.summary["mission"]
    assert result.outcome.value == "completed" and m["on_station_s"] >= 60 - 1e-6
    assert m["predicted_orbit_sum_rate_bps"] == pytest.approx(plan.extras["orbit_sum_rate_bps"])
    assert m["mean_sum_rate_bps"] == pytest.approx(m["predicted_orbit_sum_rate_bps"], rel=0.03)
