"""Orbit-aware rates: what the users get, on average, from an aircraft circling a point.

A fixed wing cannot hover at the service point; it flies a loiter orbit of radius R about it at
the point's height, at a constant ground speed in calm air, so each point of the circle is
occupied for the same share of the time and the time-average of any rate over the orbit is its
average over the circle. It is taken over ``n_points`` equally spaced points (36: every 10
degrees; the path loss varies smoothly along the circle, so the midpoint-rule error is far
below the fading's spread):

    rate_k(c)      = mean_j R_k(c + R (sin b_j, cos b_j, 0))       per user
    sum_rate(c)    = sum_k rate_k(c)
    objective(c)   = sum_rate(c) / 2^lambda,  lambda = #{k : rate_k(c) < qos}
    mean_objective = mean_j R(p_j) / 2^lambda(p_j)                 (the instantaneous reward)

Fading-free (H = 1) like the planners' ranking (fading averages out over a 30-60 s orbit).
``objective`` judges QoS on the orbit-mean rate (what a user's delivered bits over an orbit
reflect); ``mean_objective`` on the instantaneous rate (the paper's reward, averaged).
Bearings ``b_j`` are clockwise from north, as headings are (uavxai.geometry).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.errors import UserError

# Candidates per vectorised chunk: 36 points x 10 users x 2048 centres keeps every temporary
# below ~6 MB, so a grid of 10^5 centres streams through the cache instead of allocating GBs.
CHUNK_CENTRES = 2048


@dataclass(frozen=True)
class OrbitAverage:
    """Orbit averages for one or many centres: ``rate_bps (..., K)``, the rest ``(...)``."""

    rate_bps: np.ndarray
    sum_rate_bps: np.ndarray
    objective: np.ndarray
    mean_objective: np.ndarray
    min_sum_rate_bps: np.ndarray  # the worst point of the orbit


def orbit_points(
    centre: np.ndarray, radius_m: float, n_points: int = 36, bearing0_rad: float = 0.0
) -> np.ndarray:
    """``(..., n_points, 3)``: the orbit about ``centre (..., 3)`` at the centre's height,
    starting at bearing ``bearing0_rad`` (clockwise from north), equally spaced."""
    radius_m, n_points = _check(radius_m, n_points)
    b = bearing0_rad + 2.0 * np.pi * np.arange(n_points) / n_points
    offset = np.column_stack([radius_m * np.sin(b), radius_m * np.cos(b), np.zeros(n_points)])
    return np.asarray(centre, dtype=float)[..., None, :] + offset


def orbit_position(
    centre: np.ndarray,
    radius_m: float,
    bearing0_rad: float,
    elapsed_s: float | np.ndarray,
    ground_speed_mps: float,
    clockwise: bool = True,
) -> np.ndarray:
    """Where the planned orbit is ``elapsed_s`` after passing bearing ``bearing0_rad``,
    flown at ``ground_speed_mps`` (clockwise: the bearing from the centre grows).
    ``(3,)``, or ``(N, 3)`` for an array of times: the ``planned_pos`` of an avoiding sample."""
    radius_m, _ = _check(radius_m, 1)
    c = np.asarray(centre, dtype=float)
    turn = ground_speed_mps * np.asarray(elapsed_s, dtype=float) / max(radius_m, 1e-9)
    b = bearing0_rad + (turn if clockwise else -turn)
    out = np.stack(
        [
            c[0] + radius_m * np.sin(b),
            c[1] + radius_m * np.cos(b),
            np.broadcast_to(c[2], np.shape(b)),
        ],
        axis=-1,
    )
    return out


def orbit_bearing(centre: np.ndarray, pos: np.ndarray) -> float:
    """Bearing of ``pos`` seen from ``centre`` (clockwise from north): the orbit's phase."""
    d = np.asarray(pos, dtype=float)[:2] - np.asarray(centre, dtype=float)[:2]
    return float(np.arctan2(d[0], d[1]))


def orbit_gains(
    channel: Channel, centre: np.ndarray, radius_m: float, n_points: int = 36
) -> np.ndarray:
    """Mean gains ``(..., n_points, K)`` around the orbit (for planners that optimise power
    per candidate, e.g. averaging ``grid.level_rates`` over the points)."""
    return channel.mean_gain(orbit_points(centre, radius_m, n_points))


def orbit_average(
    channel: Channel,
    centre: np.ndarray,
    radius_m: float,
    power_w: np.ndarray,
    n_points: int = 36,
) -> OrbitAverage:
    """Rates averaged over the orbit of ``radius_m`` about ``centre`` ``(3,)`` or ``(M, 3)``
    (any leading shape), with power ``(K,)`` or one allocation per centre ``(..., K)``.
    ``radius_m = 0`` gives the hover point's values."""
    radius_m, n_points = _check(radius_m, n_points)
    c = np.asarray(centre, dtype=float)
    if c.shape[-1:] != (3,):
        raise UserError(f"orbit centre must be (3,) or (M, 3), got shape {c.shape}")
    lead = c.shape[:-1]
    k = channel.k
    flat = c.reshape(-1, 3)
    m = len(flat)
    power = np.asarray(power_w, dtype=float)
    if power.shape[-1:] != (k,):
        raise UserError(f"power_w must be (K,) or (M, K) with K = {k}, got shape {power.shape}")
    power = np.broadcast_to(power, lead + (k,)).reshape(m, k)
    rate = np.empty((m, k))
    mean_obj = np.empty(m)
    min_sum = np.empty(m)
    for i in range(0, m, CHUNK_CENTRES):
        sl = slice(i, i + CHUNK_CENTRES)
        g = channel.mean_gain(orbit_points(flat[sl], radius_m, n_points))  # (m', n, K)
        r = channel.rate(g, power[sl, None, :])
        rate[sl] = r.mean(axis=1)
        mean_obj[sl] = channel.objective(r).mean(axis=1)
        min_sum[sl] = r.sum(axis=-1).min(axis=1)
    total = rate.sum(axis=-1)
    return OrbitAverage(
        rate_bps=rate.reshape(lead + (k,)),
        sum_rate_bps=total.reshape(lead),
        objective=channel.objective(rate).reshape(lead),
        mean_objective=mean_obj.reshape(lead),
        min_sum_rate_bps=min_sum.reshape(lead),
    )


def _check(radius_m: float, n_points: int) -> tuple[float, int]:
    r = float(radius_m)
    if not (np.isfinite(r) and r >= 0):
        raise UserError(f"orbit radius_m must be a finite number >= 0 m, got {radius_m}")
    if int(n_points) != n_points or n_points < 1:
        raise UserError(f"orbit n_points must be an integer >= 1, got {n_points}")
    return r, int(n_points)
