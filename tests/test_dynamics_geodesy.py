"""The local ENU frame: round trips, and one point converted as the arrays are, to the bit."""

from __future__ import annotations

import numpy as np

from uavxai.dynamics.geodesy import LocalFrame

FRAME = LocalFrame(47.3977, 8.5456, 488.0)


def test_one_point_converts_to_the_same_bits_as_an_array_of_them() -> None:
    # Telemetry and ADS-B reports convert one point at a time (a faster path); the ADS-B
    # frames the planner decodes must not depend on which path packed them.
    pts = np.random.default_rng(3).uniform(-5000.0, 5000.0, (2000, 3))
    lat, lon, alt = FRAME.to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2])
    for i, (x, y, h) in enumerate(pts):
        one = FRAME.to_geodetic(x, y, h)
        assert one == (lat[i], lon[i], alt[i])
        assert all(isinstance(v, float) for v in one)
    plain = FRAME.to_geodetic(float(pts[0, 0]), float(pts[0, 1]), float(pts[0, 2]))
    assert plain == (lat[0], lon[0], alt[0])


def test_geodetic_and_back_is_the_identity_to_a_micrometre() -> None:
    pts = np.random.default_rng(4).uniform(-5000.0, 5000.0, (100, 3))
    x, y, h = FRAME.to_local(*FRAME.to_geodetic(pts[:, 0], pts[:, 1], pts[:, 2]))
    np.testing.assert_allclose(np.column_stack([x, y, h]), pts, atol=1e-6)
    assert FRAME.to_geodetic(0.0, 0.0, 0.0) == (47.3977, 8.5456, 488.0)
