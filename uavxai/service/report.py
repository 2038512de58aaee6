"""What `uavxai service` prints: the service stage's figures in words and units (the JSON
keys and raw numbers are in summary.json)."""

from __future__ import annotations

import math
from typing import Any


def bit_rate(bps: float | None) -> str:
    """A rate with its unit: ``13.35 Mbit/s``, ``273.0 kbit/s``, ``0 bit/s``."""
    if bps is None or not math.isfinite(bps):
        return "-"
    for scale, unit in ((1e9, "Gbit/s"), (1e6, "Mbit/s"), (1e3, "kbit/s")):
        if abs(bps) >= scale:
            return f"{bps / scale:.2f} {unit}"
    return f"{bps:.0f} bit/s"


def _range(values: list, fmt: str) -> str:
    """``min .. max`` of the finite values of a per-user list (``-`` when there are none)."""
    finite = [v for v in values if isinstance(v, int | float) and math.isfinite(v)]
    if not finite:
        return "-"
    return f"{format(min(finite), fmt)} .. {format(max(finite), fmt)}"


def service_lines(summary: dict[str, Any]) -> list[str]:
    """Labelled lines with units for a service-stage summary (``run_service_stage``)."""
    x, y, h = summary["service_point"]
    rates, power = summary.get("rate_bps") or [], summary.get("power_w") or []
    k = len(rates)
    served = sum(1 for p in power if p > 0)
    lines = [
        f"planner            {summary['planner']}",
        f"service point      x {x:.0f} m, y {y:.0f} m, height {h:.0f} m",
        f"sum rate           {bit_rate(summary.get('sum_rate_bps'))} "
        f"(fading averaged: {bit_rate(summary.get('ergodic_sum_rate_bps'))})",
        f"users at QoS       {summary.get('qos_satisfied')} of {k}",
        f"users served       {served} of {k}; power {sum(power):.3f} W in all, "
        f"{_range([p for p in power if p > 0], '.3f')} W each",
        f"rate per user      {bit_rate(min(rates, default=None))} .. "
        f"{bit_rate(max(rates, default=None))}",
        f"SINR per user      {_range(summary.get('sinr_db') or [], '.1f')} dB (served users)",
        f"objective          {bit_rate(summary.get('objective'))} (sum rate / 2^users below QoS)",
    ]
    if summary.get("orbit_radius_m") is not None:
        lines.append(
            f"on the orbit       radius {summary['orbit_radius_m']:.0f} m: sum rate "
            f"{bit_rate(summary.get('orbit_sum_rate_bps'))}, "
            f"{summary.get('orbit_qos_satisfied')} of {k} users at QoS"
        )
    # comms.environment is Al-Hourani's parameter set: said only where it is used
    keys = ["channel", "access", "fading"]
    if summary.get("channel", "al_hourani") == "al_hourani":
        keys.insert(2, "environment")
    words = [f"{summary[key]}" for key in keys if key in summary]
    channel = ", ".join(words + (["shadowing"] if summary.get("shadowing") else []))
    if channel:
        lines.append(f"channel            {channel}")
    if summary.get("lattice_points") is not None:
        lines.append(
            f"grid search        {summary['lattice_points']} lattice points, "
            f"{summary.get('grid_evaluations')} bounds and values evaluated"
        )
    lines.append(f"planning time      {summary.get('service_wall_s', 0):.2f} s")
    return lines
