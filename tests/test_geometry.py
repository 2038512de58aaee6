"""The shared geometry of uavxai/geometry.py: each piece written once and used by every
module that needs it, so each is tested here against an independent statement of it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.geometry import wrap_angle


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
    np.testing.assert_array_equal(out, [[wrap_angle(float(x)) for x in row] for row in a])
