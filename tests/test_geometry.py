"""The shared geometry of uavxai/geometry.py: each piece written once and used by every
module that needs it, so each is tested here against an independent statement of it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.geometry import (
    bank_of_turn_rate,
    closest_approach,
    closest_approaches,
    closest_on_pieces,
    closest_point_of_approach,
    turn_rate_of_bank,
    wrap_angle,
)


@pytest.mark.parametrize(
    ("angle", "wrapped"),
    [(0.0, 0.0), (math.pi / 2, math.pi / 2), (3 * math.pi / 2, -math.pi / 2),
     (-3 * math.pi / 2, math.pi / 2), (7.0, 7.0 - 2 * math.pi), (-7.0, -7.0 + 2 * math.pi),
     (101 * math.pi + 0.25, -math.pi + 0.25)],
)
def test_wrap_angle_of_a_float(angle, wrapped):
    out = wrap_angle(angle)
    assert isinstance(out, float)
    assert out == pytest.approx(wrapped, abs=1e-12)


def test_wrap_angle_keeps_a_small_angle_to_the_last_bit():
    # the modulo form (a + pi) % 2pi - pi would round 1e-10 to a multiple of pi's ulp
    assert wrap_angle(1e-10) == 1e-10
    assert wrap_angle(np.array([1e-10]))[0] == 1e-10


def test_wrap_angle_of_an_array_is_the_float_one_element_by_element():
    rng = np.random.default_rng(7)
    a = rng.uniform(-50.0, 50.0, size=(4, 25))
    out = wrap_angle(a)
    assert isinstance(out, np.ndarray) and out.shape == a.shape
    assert np.all(out > -math.pi) and np.all(out <= math.pi)
    # the same direction: a whole number of turns apart
    turns = (a - out) / (2 * math.pi)
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-9)
    # numpy's sin and cos on arrays are its own SIMD kernels (AVX-512 on the CI machine of
    # 2026-11-28), not the C library's that math uses: each is within 1 ulp of the true
    # value, and the two paths met to the bit on the earlier machine but differ in the last
    # bit on 5 of these 100 angles here. The claim that holds everywhere is 1 ulp.
    np.testing.assert_array_max_ulp(out, [[wrap_angle(float(x)) for x in row] for row in a], 1)


def test_closest_point_of_approach_of_straight_lines():
    # (a) head-on, offset 30 m sideways: CPA in 1000 / 40 s at 30 m
    # (b) diverging: CPA now, at the present distance
    # (c) parallel at the same velocity (no relative motion): now, the present distance
    # (d) CPA later than the horizon: measured at the horizon
    rel = np.array([[30.0, 1000.0, 0.0], [100.0, 0.0, 10.0], [50.0, 50.0, 0.0],
                    [0.0, 5000.0, 0.0]])  # fmt: skip
    rv = np.array([[0.0, -40.0, 0.0], [5.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -10.0, 0.0]])
    t, d = closest_point_of_approach(rel, rv, 120.0)
    np.testing.assert_allclose(t, [25.0, 0.0, 0.0, 120.0], atol=1e-9)
    np.testing.assert_allclose(d, [30.0, math.hypot(100, 10), math.hypot(50, 50), 3800.0])


def test_closest_point_of_approach_is_the_minimum_over_time():
    rng = np.random.default_rng(11)
    rel, rv = rng.normal(0, 500, (50, 3)), rng.normal(0, 30, (50, 3))
    t, d = closest_point_of_approach(rel, rv, 60.0)
    grid = np.linspace(0.0, 60.0, 60001)
    dist = np.linalg.norm(rel[None] + grid[:, None, None] * rv[None], axis=2)  # (T, N)
    np.testing.assert_allclose(d, dist.min(axis=0), atol=1e-3)
    assert np.all(np.abs(t - grid[dist.argmin(axis=0)]) <= 2e-3 + 1e-9)
    assert np.all(d <= dist.min(axis=0) + 1e-9)


def test_closest_on_pieces_is_the_minimum_along_each_piece():
    rng = np.random.default_rng(5)
    r0, dr = rng.normal(0, 100, (6, 9, 3)), rng.normal(0, 60, (6, 9, 3))
    dist, s = closest_on_pieces(r0, dr)
    assert dist.shape == s.shape == (6, 9) and np.all((s >= 0) & (s <= 1))
    grid = np.linspace(0.0, 1.0, 20001)
    along = np.linalg.norm(r0[..., None, :] + grid[:, None] * dr[..., None, :], axis=-1)
    np.testing.assert_allclose(dist, along.min(axis=-1), atol=1e-3)
    np.testing.assert_allclose(dist, np.linalg.norm(r0 + s[..., None] * dr, axis=-1))
    # no relative motion: the distance now, at the piece's start
    still, s0 = closest_on_pieces(np.array([[3.0, 4.0, 0.0]]), np.zeros((1, 3)))
    assert still[0] == 5.0 and s0[0] == 0.0


def test_closest_approach_catches_a_pass_between_samples():
    # the intruder crosses the ownship's path between the samples, 2 m above it
    p0, p1 = np.zeros(3), np.array([0.0, 20.0, 0.0])
    q0, q1 = np.array([[-10.0, 10.0, 2.0]]), np.array([[10.0, 10.0, 2.0]])
    assert closest_approach(p0, p1, q0, q1) == pytest.approx(2.0)
    ends = min(np.linalg.norm(q0[0] - p0), np.linalg.norm(q1[0] - p1))
    assert ends > 14.0  # neither sample shows it


def test_coordinated_turn_rate_and_bank_are_inverse_and_element_wise():
    # a 30 deg bank at 20 m/s: the standard radius v^2 / (g tan phi) = 70.7 m, rate v / r
    radius = 20.0**2 / (9.80665 * math.tan(math.radians(30.0)))
    assert turn_rate_of_bank(math.radians(30.0), 20.0) == pytest.approx(20.0 / radius)
    assert turn_rate_of_bank(-0.4, 15.0) == -turn_rate_of_bank(0.4, 15.0)  # left: negative
    banks, speeds = np.linspace(-1.0, 1.0, 9), np.linspace(12.0, 40.0, 9)
    rates = turn_rate_of_bank(banks, speeds)
    assert isinstance(rates, np.ndarray)
    np.testing.assert_array_equal(rates, [turn_rate_of_bank(float(b), float(v))
                                          for b, v in zip(banks, speeds, strict=True)])
    back = [bank_of_turn_rate(float(w), float(v)) for w, v in zip(rates, speeds, strict=True)]
    np.testing.assert_allclose(back, banks, atol=1e-12)


def test_closest_approaches_is_each_rows_and_closest_approach_their_least():
    """Per row, with one point's piece for all rows or one per row (a judge's pair that
    restarts on a replaced row): each row's closest approach alone; the least is
    closest_approach's."""
    rng = np.random.default_rng(5)
    q0, q1 = rng.uniform(-50, 50, (6, 3)), rng.uniform(-50, 50, (6, 3))
    p0, p1 = rng.uniform(-50, 50, 3), rng.uniform(-50, 50, 3)
    each = closest_approaches(p0, p1, q0, q1)
    assert each.shape == (6,)
    for j in range(6):
        assert each[j] == closest_approach(p0, p1, q0[j : j + 1], q1[j : j + 1])
    assert closest_approach(p0, p1, q0, q1) == each.min()
    per_row = closest_approaches(np.tile(p0, (6, 1)), np.tile(p1, (6, 1)), q0, q1)
    np.testing.assert_array_equal(per_row, each)

