"""Three additions to the planner's documented refinement (``universal.plan``), hover objective.

**Screened starts.** The greedy flight and a lattice hill-climb from its best point find one
basin. Where the optimum is a needle in another one (OFDMA high-rise with few users: hovering
at the lowest altitude right above one or two users, whose rates then dominate, while the
flight climbs to the safe line-of-sight altitude), no local move reaches it. So the planner
also refines from the best points of a coarse screen at equal power: every
``SCREEN_STRIDE``-th lattice point horizontally at every second altitude, plus the column
above every user (snapped to the lattice) — about 4,000 points, one vectorised evaluation.

**Exact climb.** Where the exact power DP is cheap (K <= 12 at L = 6), the final point is
hill-climbed over its 6 lattice neighbours scoring each with the exact power optimum for that
point; the local search over levels stops where a different level pattern would let the
position move on (shared band, high-rise: one or two steps from the optimum).

**Kicks.** In the shared band with many users the objective is a plateau broken by QoS
steps: from a point where one user misses QoS (the objective halved), no single move or
level change crosses the step, while a point a few steps away does. So the planner kicks its
best point ``KICKS`` times by a fixed, seeded pattern of horizontal offsets (up to
``KICK_STEPS`` lattice steps) and refines from each with the best levels, keeping any
improvement (an iterated local search; 1 of 2,400 benchmark layouts needed it, at half the
optimum before).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.service.grid import optimal_levels, optimal_objective, useful_totals
from uavxai.service.service_env import MOVES, SearchSpace, levels_to_power

KICKS = 6
KICK_STEPS = 5
KICK_SEED = 0  # the same kicks every time: the planner stays deterministic
SCREEN_STRIDE = 3  # lattice points between screened ones, horizontally
SCREEN_STARTS = 2  # refinements from the screen's best points
SEPARATION_STEPS = 2.5  # a start closer than this (Chebyshev, in steps) to another is skipped
CLIMB_ROUNDS = 12


def screened_starts(
    channel: Channel, space: SearchSpace, avoid: np.ndarray, count: int = SCREEN_STARTS
) -> list[np.ndarray]:
    """The ``count`` best screened lattice points at equal power, apart from ``avoid`` and
    from each other."""
    xs, ys, hs = space.axes()
    coarse = np.stack(
        np.meshgrid(xs[::SCREEN_STRIDE], ys[::SCREEN_STRIDE], hs[::2], indexing="ij"), axis=-1
    ).reshape(-1, 3)
    ux = xs[np.abs(xs[None, :] - channel.users[:, :1]).argmin(axis=1)]
    uy = ys[np.abs(ys[None, :] - channel.users[:, 1:2]).argmin(axis=1)]
    above = np.column_stack([np.repeat(ux, len(hs)), np.repeat(uy, len(hs)), np.tile(hs, len(ux))])
    candidates = np.vstack([coarse, above])
    values = channel.evaluate(candidates, channel.equal_power()).objective
    taken, chosen = [np.asarray(avoid, float)], []
    for i in np.argsort(-values, kind="stable"):
        if len(chosen) == count:
            break
        if all(np.abs(candidates[i] - t).max() > SEPARATION_STEPS * space.step_m for t in taken):
            chosen.append(candidates[i])
            taken.append(candidates[i])
    return chosen


def exact_climb(
    channel: Channel, space: SearchSpace, power_levels: int, position: np.ndarray, failures: int
) -> np.ndarray:
    """Best-improvement climb over the 6 lattice neighbours, each scored by the exact power
    optimum among allocations with at most ``failures`` users below QoS (what the start has:
    an objective some allocation achieves, at a fraction of the full DP's cost)."""
    pos, cap = np.asarray(position, float), failures + 1
    best = float(optimal_objective(channel, channel.mean_gain(pos), power_levels, cap)[0])
    for _ in range(CLIMB_ROUNDS):
        neighbours = pos + MOVES[:6] * space.step_m
        neighbours = neighbours[space.contains(neighbours)]
        gains = channel.mean_gain(neighbours)
        # only the level totals that can beat the current point at the neighbours' peak gains
        totals = useful_totals(channel, gains.max(axis=0), power_levels, best, cap)
        if not len(totals):
            break
        values = optimal_objective(channel, gains, power_levels, cap, totals)
        i = int(values.argmax())
        if values[i] <= best * (1.0 + 1e-12):
            break
        pos, best = neighbours[i], float(values[i])
    return pos


def climb_exact(
    channel: Channel,
    space: SearchSpace,
    power_levels: int,
    best: tuple[np.ndarray, np.ndarray, float],
) -> tuple[np.ndarray, np.ndarray, float]:
    """``exact_climb`` from ``best`` (position, levels, objective, after the exact power step);
    the exact levels at the point it ends on, if that beats ``best``."""
    position, levels, value = best
    rate = channel.rate(
        channel.mean_gain(position), levels_to_power(levels, channel.p_max_w, power_levels)
    )
    failures = int((rate < channel.qos_rate_bps).sum())
    end = exact_climb(channel, space, power_levels, position, failures)
    if np.array_equal(end, position):
        return best
    end_levels, end_value = optimal_levels(channel, channel.mean_gain(end), power_levels)
    return (end, end_levels, end_value) if end_value > value else best


def kicked(
    space: SearchSpace,
    best: tuple[np.ndarray, np.ndarray, float],
    refine: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, float, int]],
) -> tuple[tuple[np.ndarray, np.ndarray, float], int]:
    """Iterated local search: ``refine(start, levels)`` from ``KICKS`` horizontal kicks of
    the best point so far (snapped into the box), keeping improvements; returns the best and
    the refinement rounds spent."""
    rng = np.random.default_rng(KICK_SEED)
    lo, hi = (np.array([a[0] for a in space.axes()]), np.array([a[-1] for a in space.axes()]))
    rounds = 0
    for _ in range(KICKS):
        offset = np.append(rng.integers(-KICK_STEPS, KICK_STEPS + 1, 2) * space.step_m, 0.0)
        start = np.clip(best[0] + offset, lo, hi)
        pos, lev, value, r = refine(start, best[1])
        rounds += r
        if value > best[2]:
            best = (pos, lev, value)
    return best, rounds
