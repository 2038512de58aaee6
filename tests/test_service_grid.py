"""The reference optimum: exact power DP and the lattice branch-and-bound, against brute force."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from uavxai.comms.channel import Channel
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.service.grid import optimal_levels, optimal_objective, solve_grid
from uavxai.service.service_env import SearchSpace, levels_to_power


def brute_force(channel: Channel, gain: np.ndarray, L: int) -> float:
    levels = np.array(list(itertools.product(range(L), repeat=channel.k)))
    power = levels_to_power(levels, channel.p_max_w, L)
    return float(channel.objective(channel.rate(gain[None, :], power)).max())


@pytest.mark.parametrize("access", ["shared", "ofdma"])
@pytest.mark.parametrize(("k", "L", "qos"), [(3, 4, 1e5), (4, 3, 3e5), (5, 3, 2e5), (3, 6, 6e5)])
def test_power_dp_equals_brute_force(access, k, L, qos):
    sc = default_scenario(
        seed=k * 10 + L,
        comms={"users": {"count": k}, "access": access, "power_levels": L, "qos_rate_bps": qos},
    )
    ch = Channel.from_scenario(sc)
    rng = np.random.default_rng(k + L)
    positions = np.column_stack(
        [rng.uniform(750, 1250, 6), rng.uniform(750, 1250, 6), rng.uniform(50, 300, 6)]
    )
    gains = ch.mean_gain(positions)
    batch = optimal_objective(ch, gains, L)
    for g, value in zip(gains, batch, strict=True):
        truth = brute_force(ch, g, L)
        levels, objective = optimal_levels(ch, g, L)
        assert value == pytest.approx(truth, rel=1e-12)
        assert objective == pytest.approx(truth, rel=1e-12)
        # the levels it returns really achieve it
        achieved = ch.objective(ch.rate(g, levels_to_power(levels, ch.p_max_w, L)))
        assert float(achieved) == pytest.approx(truth, rel=1e-12)


@pytest.mark.parametrize("access", ["shared", "ofdma"])
def test_branch_and_bound_finds_the_lattice_optimum(access):
    sc = default_scenario(
        seed=4,
        comms={
            "users": {"count": 3, "region": {"x": [800, 1200], "y": [850, 1150]}},
            "access": access,
            "power_levels": 3,
            "environment": "dense_urban",
        },
        service={"step_m": 25},
    )
    ch, space = Channel.from_scenario(sc), SearchSpace.from_scenario(sc)
    result = solve_grid(ch, space, 3)
    xs, ys, hs = space.axes()
    mesh = np.stack(np.meshgrid(xs, ys, hs, indexing="ij"), axis=-1).reshape(-1, 3)
    values = optimal_objective(ch, ch.mean_gain(mesh), 3)
    assert result.lattice_points == len(mesh) == 17 * 13 * 11
    assert result.objective == pytest.approx(values.max(), rel=1e-12)
    achieved = ch.evaluate(result.position, result.power_w).objective
    assert float(achieved) == pytest.approx(values.max(), rel=1e-12)
    # it pruned: fewer solves than lattice points
    assert result.evaluations < len(mesh)


def test_shared_band_optimum_puts_the_rest_on_one_user():
    # Interference-limited: every other user sits exactly at the QoS edge, one takes the rest.
    sc = default_scenario(comms={"access": "shared", "fading": "none"})
    ch = Channel.from_scenario(sc)
    gain = ch.mean_gain(np.array([1000.0, 1000.0, 150.0]))
    levels, objective = optimal_levels(ch, gain, 6)
    assert sorted(levels.tolist()) == [1] * 9 + [5]
    equal = ch.evaluate(np.array([1000.0, 1000.0, 150.0]), ch.equal_power()).objective
    assert objective > 1.04 * float(equal)


def test_grid_refuses_sizes_it_cannot_solve_in_time():
    sc = default_scenario(comms={"users": {"count": 40}, "power_levels": 8})
    with pytest.raises(UserError, match="takes up to K = 1[0-9] users"):
        solve_grid(Channel.from_scenario(sc), SearchSpace.from_scenario(sc), 8)


@pytest.mark.parametrize("access", ["shared", "ofdma"])
def test_capped_power_dp_is_the_best_allocation_below_the_cap(access):
    # The branch-and-bound's DP keeps only allocations with fewer than `cap` failures.
    k, L = 5, 4
    sc = default_scenario(
        seed=7, comms={"users": {"count": k}, "access": access, "power_levels": L,
                       "qos_rate_bps": 2e5}
    )
    ch = Channel.from_scenario(sc)
    rng = np.random.default_rng(3)
    positions = np.column_stack(
        [rng.uniform(750, 1250, 8), rng.uniform(750, 1250, 8), rng.uniform(50, 300, 8)]
    )
    gains = ch.mean_gain(positions)
    levels = np.array(list(itertools.product(range(L), repeat=k)))
    rates = ch.rate(gains[:, None, :], levels_to_power(levels, ch.p_max_w, L)[None])
    failures = (rates < ch.qos_rate_bps).sum(-1)  # (positions, allocations)
    objective = rates.sum(-1) / 2.0**failures
    for cap in range(1, k + 2):
        below = np.where(failures < cap, objective, -np.inf).max(axis=1)
        np.testing.assert_allclose(optimal_objective(ch, gains, L, cap), below, rtol=1e-12)


@pytest.mark.parametrize(("access", "k"), [("shared", 4), ("ofdma", 4), ("shared", 6)])
def test_hinted_branch_and_bound_is_still_the_lattice_optimum(access, k):
    # A hint only seeds the incumbent: good, bad or none, the answer is the exhaustive maximum.
    sc = default_scenario(
        seed=11,
        comms={
            "users": {"count": k, "region": {"x": [800, 1200], "y": [850, 1150]}},
            "access": access,
            "power_levels": 4,
            "environment": "highrise_urban",
        },
        service={"step_m": 40},
    )
    ch, space = Channel.from_scenario(sc), SearchSpace.from_scenario(sc)
    xs, ys, hs = space.axes()
    mesh = np.stack(np.meshgrid(xs, ys, hs, indexing="ij"), axis=-1).reshape(-1, 3)
    values = optimal_objective(ch, ch.mean_gain(mesh), 4)
    best, worst = mesh[values.argmax()], mesh[values.argmin()]
    for hint in (None, best, worst, best + 13.0):
        result = solve_grid(ch, space, 4, hint=hint)
        assert result.objective == pytest.approx(values.max(), rel=1e-12)
        achieved = ch.evaluate(result.position, result.power_w).objective
        assert float(achieved) == pytest.approx(values.max(), rel=1e-12)


def test_ofdma_water_filling_ceiling_is_above_every_allocation():
    # The cheap first filter of the branch-and-bound: no split of P_max, continuous or on the
    # levels, beats the water-filling sum rate.
    from uavxai.service.grid import rate_ceiling

    sc = default_scenario(seed=5, comms={"users": {"count": 4}, "access": "ofdma"})
    ch = Channel.from_scenario(sc)
    rng = np.random.default_rng(2)
    positions = np.column_stack(
        [rng.uniform(750, 1250, 30), rng.uniform(750, 1250, 30), rng.uniform(50, 300, 30)]
    )
    gains = ch.mean_gain(positions)
    ceiling = rate_ceiling(ch, gains)
    split = rng.dirichlet(np.ones(4), size=5000) * ch.p_max_w
    rates = ch.user_bandwidth_hz() * np.log2(1 + gains[:, None] * split[None] * 4 / ch.noise_w)
    assert np.all(ceiling >= rates.sum(-1).max(axis=1))
    assert np.all(ceiling >= optimal_objective(ch, gains, 6))
    assert np.all(optimal_objective(ch, gains, 6) > 0.999 * ceiling)  # and it is tight
