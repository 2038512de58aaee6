"""Local ENU frame <-> geodetic coordinates, anchored at the scenario's `world.origin`.

A tangent-plane approximation with WGS-84 radii of curvature at the origin: over a few
kilometres its error is centimetres, far below anything the simulation resolves.
"""

from __future__ import annotations

import math

import numpy as np

WGS84_A = 6378137.0
WGS84_E2 = 6.69437999014e-3


class LocalFrame:
    def __init__(self, lat_deg: float, lon_deg: float, alt_m: float) -> None:
        self.lat0, self.lon0, self.alt0 = lat_deg, lon_deg, alt_m
        s = math.sin(math.radians(lat_deg))
        w = math.sqrt(1.0 - WGS84_E2 * s * s)
        self.r_north = WGS84_A * (1.0 - WGS84_E2) / w**3  # meridian radius
        self.r_east = WGS84_A / w * math.cos(math.radians(lat_deg))  # parallel radius

    @classmethod
    def from_origin(cls, origin) -> LocalFrame:  # a scenario `world.origin`
        return cls(origin.lat_deg, origin.lon_deg, origin.alt_m)

    def to_geodetic(self, x, y, h):
        """ENU metres -> (lat_deg, lon_deg, alt_m above mean sea level); arrays or scalars."""
        if isinstance(x, float) and isinstance(y, float) and isinstance(h, float):
            # One point (the ownship's telemetry, an ADS-B report, ten or more times a
            # second): math is several times faster than numpy on scalars, with the same
            # 180 / pi constant, so the same bits.
            deg, arr = math.degrees, float
        else:
            deg, arr = np.degrees, np.asarray
        lat = self.lat0 + deg(arr(y) / self.r_north)
        lon = self.lon0 + deg(arr(x) / self.r_east)
        return lat, lon, self.alt0 + arr(h)

    def to_local(self, lat_deg, lon_deg, alt_m):
        """(lat_deg, lon_deg, alt_m) -> ENU metres (x east, y north, h up)."""
        x = np.radians(np.asarray(lon_deg) - self.lon0) * self.r_east
        y = np.radians(np.asarray(lat_deg) - self.lat0) * self.r_north
        return x, y, np.asarray(alt_m) - self.alt0
