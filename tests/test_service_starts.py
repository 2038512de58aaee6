"""The planner's screened starts and exact climb (uavxai.service.starts) on the hover objective."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.comms.service_env import ServiceEnv
from uavxai.service import universal
from uavxai.service.grid import solve_grid
from uavxai.service.layouts import problem_scenario
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
