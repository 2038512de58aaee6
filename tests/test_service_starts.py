"""The planner's screened starts and exact climb (uavxai.service.starts) on the hover objective."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.service import universal
from uavxai.service.grid import solve_grid
from uavxai.service.layouts import problem_scenario
from uavxai.service.service_env import ServiceEnv
from uavxai.service.starts import SEPARATION_STEPS, screened_starts

# An unseen OFDMA high-rise layout where the optimum hovers at 50 m right above two users
# (1098, 790) and (1151, 786); the flight and a local search from it stop at 0.79 of it.
NEEDLE_USERS = np.array(
    [[1053.0, 1115.0], [837.0, 863.0], [1098.0, 790.0], [1151.0, 786.0], [851.0, 1139.0]]
)


def test_screened_starts_are_separate_lattice_points():
    env = ServiceEnv.from_scenario(problem_scenario(NEEDLE_USERS, "ofdma", "highrise_urban"))
    starts = screened_starts(env.channel, env.space, env.space.start, count=4)
    assert len(starts) == 4
    axes = env.space.axes()
    for p in starts:
        assert all(np.isclose(axis, v).any() for axis, v in zip(axes, p, strict=True))
    for i, p in enumerate([env.space.start, *starts]):
        for q in starts[i:]:
            if p is not q:
                assert np.abs(p - q).max() > SEPARATION_STEPS * env.space.step_m


def test_planner_reaches_the_needle_a_local_search_misses():
    env = ServiceEnv.from_scenario(problem_scenario(NEEDLE_USERS, "ofdma", "highrise_urban"))
    optimum = solve_grid(env.channel, env.space, env.power_levels).objective
    net, _ = universal.load(universal.shipped_path("d3qn"))
    flight = universal.fly(net, env)
    full = np.full(env.channel.k, env.power_levels - 1)
    local = max(
        universal.refine(env.channel, env.space, env.power_levels, flight.position, lv)[2]
        for lv in (flight.levels, full)
    )
    assert local < 0.9 * optimum  # the case is a real trap for a search from the flight
    result = universal.plan(net, env)
    assert result.objective == pytest.approx(optimum, rel=1e-9)
    # what it reports is what the channel gives at its point with its levels
    assert universal.objective_at(env, result.position, result.levels) == pytest.approx(
        result.objective, rel=1e-12
    )


# Benchmark layout shared / highrise_urban / K = 20 / uniform / i = 49 (rounded to 0.1 m):
# from the flight's basin one more user stays below QoS than at the optimum.
PLATEAU_USERS = [
    [1229.7, 1208.7], [1204.5, 1210.5], [786.7, 794.7], [1152.4, 983.0], [1005.9, 832.5],
    [891.6, 1030.5], [1181.0, 897.7], [850.6, 1233.0], [1181.4, 878.6], [842.1, 750.6],
    [1068.0, 941.9], [957.3, 1108.2], [860.2, 1142.6], [996.8, 767.3], [1094.2, 875.1],
    [1134.1, 1111.9], [1182.2, 1108.2], [757.4, 1092.9], [801.8, 1162.3], [1220.6, 1095.6],
]  # fmt: skip


def test_kicks_leave_a_qos_plateau(monkeypatch):
    """Shared band, K = 20: without the kicks the planner ends where one more user misses QoS
    than needs to (the objective halved); with them it crosses that step, and the reported
    objective is the channel equations' at the returned point and levels."""
    from uavxai.service import starts
    from uavxai.service.service_env import levels_to_power

    env = ServiceEnv.from_scenario(
        problem_scenario(np.array(PLATEAU_USERS), "shared", "highrise_urban")
    )
    net, _ = universal.load(universal.shipped_path("d3qn"))
    policy = universal.NumpyPolicy(net)

    def missing(plan: universal.Plan) -> int:
        power = levels_to_power(plan.levels, env.channel.p_max_w, env.power_levels)
        rate = env.channel.rate(env.channel.mean_gain(plan.position), power)
        assert env.channel.objective(rate) == pytest.approx(plan.objective, rel=1e-9)
        return int((rate < env.channel.qos_rate_bps).sum())

    kicked = universal.plan(policy, env)
    monkeypatch.setattr(starts, "KICKS", 0)
    unkicked = universal.plan(policy, env)
    assert missing(kicked) < missing(unkicked)
    assert kicked.objective > 1.9 * unkicked.objective
