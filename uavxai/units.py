"""Physical constants and unit conversions, each written once: uavxai works in SI (m, s, rad)
and converts at its edges (JSBSim's feet, the encounter model's knots and feet, the NMAC
definition in feet)."""

from __future__ import annotations

G = 9.80665  # standard gravity, m/s^2
FT = 0.3048  # m per international foot
KT = 1852.0 / 3600.0  # m/s per knot (1 NM = 1852 m)
