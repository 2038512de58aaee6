"""The channel model (paper eqs 1-7) against values worked out by hand."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from uavxai.comms.channel import (
    ENVIRONMENTS,
    Channel,
    draw_users,
    free_space_loss_db,
    los_probability,
    throughput_bits,
)
from uavxai.scenario import default_scenario

B = 1.0e6
NOISE_W = 1e-13  # -100 dBm


def two_users(access: str, fading: str = "none") -> Channel:
    users = np.array([[0.0, 0.0, 0.0], [100.0, 0.0, 0.0]])
    sc = default_scenario(comms={"access": access, "fading": fading})
    return Channel.from_scenario(sc, users)


def test_free_space_loss_textbook_formula():
    # FSPL = 20 log10(d/km) + 20 log10(f/MHz) + 32.45 dB: 100 m at 2 GHz -> 78.47 dB
    assert free_space_loss_db(np.array(100.0), 2e9) == pytest.approx(78.47, abs=0.01)
    assert free_space_loss_db(np.array(1000.0), 2e9) == pytest.approx(98.47, abs=0.01)


def test_los_probability_takes_degrees():
    # urban a = 9.61, b = 0.16 at 45 deg: 1 / (1 + 9.61 exp(-0.16 * 35.39)) = 0.96769
    assert los_probability(np.array(45.0), "urban") == pytest.approx(0.96769, abs=1e-5)
    # a radian argument (0.785) would give an almost certainly NLoS link instead
    assert los_probability(np.array(math.radians(45.0)), "urban") < 0.05
    # high-rise at 30 deg: 1 / (1 + 27.23 exp(-0.08 * 2.77)) = 1 / (1 + 27.23 * 0.80122)
    assert los_probability(np.array(30.0), "highrise_urban") == pytest.approx(0.043826, abs=1e-5)


def test_environment_table_is_al_hourani():
    assert ENVIRONMENTS == {
        "suburban": (4.88, 0.43, 0.1, 21.0),
        "urban": (9.61, 0.16, 1.0, 20.0),
        "dense_urban": (12.08, 0.11, 1.6, 23.0),
        "highrise_urban": (27.23, 0.08, 2.3, 34.0),
    }


def test_geometry_and_path_loss_by_hand():
    ch = two_users("shared")
    uav = np.array([0.0, 0.0, 100.0])
    distance, elevation = ch.geometry(uav)
    np.testing.assert_allclose(distance, [100.0, 100.0 * math.sqrt(2.0)])
    np.testing.assert_allclose(elevation, [90.0, 45.0])
    # user 2: FSPL(141.42 m) = 81.4787 dB, P_LoS = 0.96769:
    # L = 81.4787 + 0.96769 * 1 + 0.03231 * 20 = 83.0926 dB
    # user 1 (straight below): P_LoS = 0.99998, L = 78.4684 + 1.0005 = 79.4689 dB
    np.testing.assert_allclose(ch.path_loss_db(uav), [79.4689, 83.0926], atol=2e-4)
    np.testing.assert_allclose(ch.mean_gain(uav), [10 ** (-7.94689), 10 ** (-8.30926)], rtol=5e-5)


def test_shared_band_sinr_rate_by_hand():
    ch = two_users("shared")
    g = np.array([1e-9, 2e-10])
    p = np.array([0.6, 0.4])
    # gamma_1 = 1e-9 * 0.6 / (1e-9 * 0.4 + 1e-13) = 1.499625
    # gamma_2 = 2e-10 * 0.4 / (2e-10 * 0.6 + 1e-13) = 0.666112
    np.testing.assert_allclose(ch.sinr(g, p), [1.499625, 0.666112], rtol=1e-6)
    np.testing.assert_allclose(
        ch.rate(g, p), [B * math.log2(2.499625), B * math.log2(1.666112)], rtol=1e-6
    )


def test_ofdma_sinr_rate_by_hand():
    ch = two_users("ofdma")
    g = np.array([1e-9, 2e-10])
    p = np.array([0.6, 0.4])
    # B/K = 0.5 MHz each, noise sigma^2 / 2, no interference:
    # gamma_1 = 1e-9 * 0.6 / 5e-14 = 12000, gamma_2 = 2e-10 * 0.4 / 5e-14 = 1600
    np.testing.assert_allclose(ch.sinr(g, p), [12000.0, 1600.0], rtol=1e-9)
    np.testing.assert_allclose(
        ch.rate(g, p), [0.5e6 * math.log2(12001.0), 0.5e6 * math.log2(1601.0)], rtol=1e-9
    )


def test_unserved_user_and_qos_penalty():
    ch = two_users("shared")
    g = np.array([1e-9, 2e-10])
    rate = ch.rate(g, np.array([1.0, 0.0]))
    # user 2 gets no power: no rate; user 1 has no interference: gamma = 1e-9 / 1e-13
    assert rate[1] == 0.0
    assert rate[0] == pytest.approx(B * math.log2(1.0 + 1e4))
    # one user below the 100 kbit/s QoS: the sum rate is halved
    assert ch.objective(rate) == pytest.approx(rate.sum() / 2.0)
    both = ch.rate(g, np.array([0.5, 0.5]))
    assert (both >= ch.qos_rate_bps).all()
    assert ch.objective(both) == pytest.approx(both.sum())


def test_vectorised_over_a_grid_of_positions():
    sc = default_scenario(comms={"users": {"count": 5}, "fading": "none", "access": "shared"})
    ch = Channel.from_scenario(sc)
    xs, ys, hs = np.linspace(800, 1200, 4), np.linspace(800, 1200, 3), np.array([60.0, 150.0])
    grid = np.stack(np.meshgrid(xs, ys, hs, indexing="ij"), axis=-1)  # (4, 3, 2, 3)
    power = np.array([0.1, 0.2, 0.3, 0.2, 0.2])
    report = ch.evaluate(grid, power)
    assert report.rate_bps.shape == (4, 3, 2, 5)
    assert report.objective.shape == (4, 3, 2)
    for idx in np.ndindex(4, 3, 2):
        one = ch.evaluate(grid[idx], power)
        np.testing.assert_allclose(report.rate_bps[idx], one.rate_bps, rtol=1e-12)
        assert report.objective[idx] == pytest.approx(float(one.objective), rel=1e-12)


def test_fading_none_is_deterministic_and_others_have_unit_mean():
    ch = two_users("ofdma")
    uav = np.array([10.0, 0.0, 120.0])
    rng = np.random.default_rng(0)
    np.testing.assert_array_equal(ch.gain(uav, rng), ch.mean_gain(uav))
    for fading in ("rayleigh", "rician"):
        faded = replace(ch, fading=fading)
        h = faded.draw_fading(np.random.default_rng(1), (200_000,))
        assert h.mean() == pytest.approx(1.0, abs=0.01)  # 4.5 standard errors
        assert h.min() >= 0.0
    # Rayleigh power is exponential: variance 1; Rician with K = 10 dB: much less
    ray = replace(ch, fading="rayleigh").draw_fading(np.random.default_rng(2), (200_000,))
    ric = replace(ch, fading="rician").draw_fading(np.random.default_rng(2), (200_000,))
    assert ray.var() == pytest.approx(1.0, abs=0.05)
    assert ric.var() < 0.25


def test_users_from_seed_or_positions():
    sc = default_scenario(seed=7)
    a, b = draw_users(sc), draw_users(default_scenario(seed=7))
    np.testing.assert_array_equal(a, b)
    assert a.shape == (10, 3) and (a[:, 2] == 0).all()
    assert ((a[:, :2] >= 750) & (a[:, :2] <= 1250)).all()
    assert not np.array_equal(a, draw_users(default_scenario(seed=8)))
    users = {"positions": [[1.0, 2.0], [3.0, 4.0]], "region": {"x": [0, 10], "y": [0, 10]}}
    fixed = default_scenario(comms={"users": users})
    np.testing.assert_array_equal(draw_users(fixed), [[1, 2, 0], [3, 4, 0]])


def test_throughput_integrates_the_sum_rate():
    rates = np.array([[1e5, 2e5], [3e5, 0.0]])
    assert throughput_bits(rates, dt_s=2.0) == pytest.approx(1.2e6)
