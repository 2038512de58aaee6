"""Orbit-aware service placement (``service.platform: orbit``): score a candidate service
point by what the users get from the orbit the aircraft will actually fly around it.

A fixed wing cannot hover: on station it flies a loiter orbit of radius R about the service
point (``uavxai.dynamics.orbit.scenario_orbit_radius``, the same radius the mission flies,
wind included) at the point's height, with the power allocation fixed over the orbit. The
objective of a centre c with integer levels l is ``OrbitAverage.objective``
(``uavxai.service.orbit_rate``):

    rbar_k(c, l) = mean_j R_k(c + o_j, l)           the orbit-mean rate of user k
    J(c, l)      = sum_k rbar_k / 2^lambda,   lambda = #{k : rbar_k < qos}

over ``ORBIT_POINTS`` equally spaced points o_j of the circle, fading-free like the hover
objective. QoS is judged on the orbit-mean rate (the bits a user gets over an orbit), and the
sum rate is the orbit-mean sum rate, i.e. the throughput (7) over whole laps. ``platform:
hover`` (the paper) is R = 0, but the planners then take their original hover code paths,
unchanged.

Exact power per centre. Once the total of the levels S is fixed, user k's rate at every
orbit point depends on its own level only (``grid.level_rates``), and so does its orbit mean:
the knapsack DP of ``grid`` runs unchanged on the orbit-averaged rate tables, so the exact
optimum over levels at one centre costs one DP plus ``ORBIT_POINTS`` rate tables.

Exact branch-and-bound over the lattice (``solve_grid_orbit``). The bound must hold for every
centre of a box and every allocation. For fixed levels and total S, the rate of user k is a
concave, increasing function f of its gain g (OFDMA: ``B log2(1 + a g)``; shared band: the SINR
``g p / (g I + N)`` is concave increasing in g, and log2(1 + .) of it stays concave), so by
Jensen ``rbar_k(c) = mean_j f(g_k(c + o_j)) <= f(gbar_k(c))`` with ``gbar_k(c)`` the
orbit-mean gain, and ``<= f(max_{c in box} gbar_k(c))``. The objective grows with every user's
rate (the sum grows, lambda can only drop), so the hover DP (``grid.optimal_objective``) at
the per-user maximum orbit-mean gain over the box bounds the orbit objective of every centre
in it. Jensen's gap is what the user's gain varies over the orbit: about 1 % of the rate in
OFDMA, more than the objective varies near the optimum, so a second bound, nearly exact at
high SNR, is taken where it is smaller (``bound_tables``: in OFDMA from the geometric and
harmonic means of the gain over the orbit, 4e-9 of the rate against Jensen's 1.3 % on a
suburban layout; in the shared band it does not improve on Jensen's). The DP then runs on the
bounding rate tables. Single centres are then evaluated exactly (their bound is not). The search
is best-first: boxes are opened in the order of their bounds and it stops when the best
remaining bound cannot beat the best exact value found, so ``grid`` stays exact for the orbit
objective (on the lattice and the discrete levels, like the hover grid).
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass, field

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.dynamics.orbit import scenario_orbit_radius
from uavxai.errors import UserError
from uavxai.scenario import Scenario
from uavxai.service import grid
from uavxai.service.orbit_rate import CHUNK_CENTRES, orbit_gains
from uavxai.service.service_env import SearchSpace, levels_to_power

ORBIT_POINTS = 36  # every 10 degrees, as orbit_rate's default
TABLE_BYTES = 16_000_000  # orbit rate tables per chunk: ORBIT_POINTS x (S, K, L) per centre
CACHE_POINTS = 20_000  # orbit gains kept per objective (~3 kB each for K = 10)
OPEN_BATCH = 64  # boxes opened per vectorised bound call
BOUND_BATCH = 128  # boxes per DP call of the bounds (a few MB of DP states)
BOX = tuple[slice, slice, slice]


@dataclass
class OrbitObjective:
    """The orbit objective of one layout: ``value`` for given levels, ``optimal`` and
    ``optimal_levels`` for the exact best levels (see the module doc)."""

    channel: Channel
    power_levels: int
    radius_m: float
    n_points: int = ORBIT_POINTS
    _gains: dict[tuple[float, ...], np.ndarray] = field(default_factory=dict, repr=False)

    @classmethod
    def from_scenario(
        cls, scenario: Scenario, channel: Channel, power_levels: int
    ) -> OrbitObjective | None:
        """The scenario's orbit objective, or None for ``service.platform: hover``."""
        if scenario.service.platform == "hover":
            return None
        return cls(channel, int(power_levels), scenario_orbit_radius(scenario))

    def gains(self, positions: np.ndarray) -> np.ndarray:
        """Mean gains ``(M, n_points, K)`` around the orbits about ``positions (M, 3)``,
        cached per centre (a local search comes back to the same lattice points)."""
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        keys = [tuple(np.round(p, 6)) for p in pos]
        missing = [i for i, key in enumerate(keys) if key not in self._gains]
        if missing:
            if len(self._gains) + len(missing) > CACHE_POINTS:
                self._gains.clear()
            fresh = orbit_gains(self.channel, pos[missing], self.radius_m, self.n_points)
            for i, g in zip(missing, fresh, strict=True):
                self._gains[keys[i]] = g
        return np.stack([self._gains[key] for key in keys])

    def value(self, positions: np.ndarray, levels: np.ndarray) -> np.ndarray:
        """``J(c, l)`` for centres ``(M, 3)`` or ``(3,)`` and levels ``(M, K)`` or ``(K,)``
        (broadcast against each other): ``(M,)``."""
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        lev = np.atleast_2d(np.asarray(levels))
        m = max(len(pos), len(lev))
        pos = np.broadcast_to(pos, (m, 3))
        power = levels_to_power(np.broadcast_to(lev, (m, self.channel.k)),
                                self.channel.p_max_w, self.power_levels)
        one_centre = bool((pos == pos[0]).all())  # many allocations at one centre: one orbit
        g = self.gains(pos[:1] if one_centre else pos)
        rate = self.channel.rate(g, power[:, None, :]).mean(axis=1)  # (M, K)
        return self.channel.objective(rate)

    def tables(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Orbit-mean ``grid.level_rates`` tables ``(N, S_max, K, L)`` and QoS failures."""
        g = self.gains(positions)  # (N, n, K)
        n, k = g.shape[1:]
        rates, _ = grid.level_rates(self.channel, g.reshape(-1, k), self.power_levels)
        rates = rates.reshape(len(g), n, *rates.shape[1:]).mean(axis=1)
        return rates, rates < self.channel.qos_rate_bps

    def optimal(self, positions: np.ndarray) -> np.ndarray:
        """The exact best ``J`` over all discrete levels at each centre ``(N, 3)``: ``(N,)``."""
        pos = np.atleast_2d(np.asarray(positions, dtype=float))
        s_max = self.channel.k * (self.power_levels - 1)
        per_centre = 8 * self.n_points * s_max * self.channel.k * self.power_levels
        batch = max(1, TABLE_BYTES // per_centre)
        out = np.empty(len(pos))
        for i in range(0, len(pos), batch):
            rates, fails = self.tables(pos[i : i + batch])
            out[i : i + batch] = grid._knapsack(rates, fails)[0]  # uncapped: exact
        return out

    def optimal_levels(self, position: np.ndarray) -> tuple[np.ndarray, float]:
        """The exact best levels ``(K,)`` at one centre and their ``J``."""
        rates, fails = self.tables(np.asarray(position, dtype=float)[None])
        # grid's DP (first: the best objective; last two: where it is and the choices)
        solved = grid._knapsack(rates, fails, keep_choices=True)
        best, (s_index, lam), choices = solved[0], solved[-2], solved[-1]
        levels = np.zeros(self.channel.k, dtype=np.int64)
        s = s_index + 1
        for user in range(self.channel.k - 1, -1, -1):  # walk the DP's choices back
            levels[user] = int(choices[user][0, s_index, s, lam])
            s, lam = s - levels[user], lam - int(fails[0, s_index, user, levels[user]])
        return levels, float(best[0])


def orbit_gain_means(objective: OrbitObjective, mesh: np.ndarray) -> np.ndarray:
    """The arithmetic, geometric and harmonic means over the orbit of each user's gain at every
    centre of ``mesh (..., 3)``: ``(3, ..., K)``, streamed in chunks (the lattice is visited
    once, so nothing is cached)."""
    flat = mesh.reshape(-1, 3)
    out = np.empty((3, len(flat), objective.channel.k))
    for i in range(0, len(flat), CHUNK_CENTRES):
        sl = slice(i, i + CHUNK_CENTRES)
        g = orbit_gains(objective.channel, flat[sl], objective.radius_m, objective.n_points)
        out[0, sl] = g.mean(axis=1)
        out[1, sl] = np.exp(np.log(g).mean(axis=1))
        out[2, sl] = 1.0 / (1.0 / g).mean(axis=1)
    return out.reshape((3,) + mesh.shape[:-1] + (objective.channel.k,))


def bound_tables(
    channel: Channel, power_levels: int, means: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rate tables ``(N, S_max, K, L)`` (as ``grid.level_rates``) that bound the orbit-mean
    rate of every centre whose gain means are within ``means (4, N, K)``: the maxima of the
    arithmetic mean A and geometric mean G, the minimum of G, and the maximum of G / H (H the
    harmonic mean). Each rate is the smaller of two valid bounds (module doc): Jensen's,
    ``f(A_max)``, and a second one that is nearly exact at high SNR —

    - OFDMA, ``f(g) = B log2(1 + a g)``: ``mean log2(1 + a g_j) = log2(a G) + mean log2(1 +
      1/(a g_j)) <= log2(a G + G / H)`` (Jensen on the concave ``log2(1 + x)`` at x = 1/(a g));
    - shared band, ``f(g) = log2(g (p + I) + N) - log2(g I + N)``: the first term's mean is at
      most its value at A (concave), the second's at least its value at G (``log(I e^x + N)``
      is convex in ``x = ln g``).
    """
    a_max, g_max, g_min, gh_max = (m[:, None, :, None] for m in means)  # (N, 1, K, 1)
    L = power_levels
    s_total = np.arange(1, channel.k * (L - 1) + 1, dtype=float)
    unit = channel.p_max_w / np.maximum(s_total, L - 1)
    p = (unit[:, None] * np.arange(L))[None, :, None, :]  # (1, S, 1, L)
    with np.errstate(divide="ignore"):
        if channel.access == "shared":
            other = np.maximum((s_total * unit)[None, :, None, None] - p, 0.0)
            n = channel.noise_w
            jensen = np.log2(1.0 + a_max * p / (a_max * other + n))
            second = np.log2(a_max * (p + other) + n) - np.log2(g_min * other + n)
        else:
            a = p / (channel.noise_w / channel.k)
            jensen = np.log2(1.0 + a * a_max)
            second = np.log2(a * g_max + gh_max)
    rates = channel.user_bandwidth_hz() * np.minimum(jensen, second)
    return rates, rates < channel.qos_rate_bps


def solve_grid_orbit(
    objective: OrbitObjective, space: SearchSpace, progress: grid.Progress | None = None
) -> grid.GridResult:
    """The exact optimum of ``objective`` over the lattice and the discrete levels (module
    doc: best-first branch-and-bound with the Jensen bound). ``progress(settled, total)``
    hears now and then how many lattice points are settled (evaluated, or in a box whose
    bound cannot beat the best found)."""
    channel, levels_n = objective.channel, objective.power_levels
    cost = grid.dp_cost(channel.k, levels_n)
    if cost > grid.MAX_DP_COST:
        raise UserError(
            f"service.planner grid: the exact power search for K = {channel.k} users and "
            f"power_levels = {levels_n} is too slow for thousands of positions (cost {cost:.0f} "
            "times the default); use planner random or d3qn."
        )
    axes = space.axes()
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)  # (nx, ny, nh, 3)
    arith, geo, harm = orbit_gain_means(objective, mesh)
    ratio = geo / harm
    shape = arith.shape[:3]

    def bounds(boxes: list[BOX]) -> np.ndarray:
        means = np.array([
            [arith[b].max(axis=(0, 1, 2)) for b in boxes],
            [geo[b].max(axis=(0, 1, 2)) for b in boxes],
            [geo[b].min(axis=(0, 1, 2)) for b in boxes],
            [ratio[b].max(axis=(0, 1, 2)) for b in boxes],
        ])  # fmt: skip
        out = np.empty(len(boxes))
        for i in range(0, len(boxes), BOUND_BATCH):
            rates, fails = bound_tables(channel, levels_n, means[:, i : i + BOUND_BATCH])
            out[i : i + BOUND_BATCH] = grid._knapsack(rates, fails)[0]
        return out

    tiles = [
        tuple(slice(a, min(a + grid.INITIAL_BOX, n)) for a, n in zip(corner, shape, strict=True))
        for corner in itertools.product(*(range(0, n, grid.INITIAL_BOX) for n in shape))
    ]
    counter = itertools.count()
    heap = [(-b, next(counter), box) for b, box in zip(bounds(tiles), tiles, strict=True)]
    heapq.heapify(heap)
    evaluations = len(tiles)
    best_value, best_index = -np.inf, tuple(s.start for s in tiles[0])
    total, told = int(np.prod(shape)), grid.Told(progress)
    while heap and -heap[0][0] > best_value * (1.0 + 1e-12):
        if told.due():
            still = sum(grid._box_size(b) for nb, _, b in heap if -nb > best_value * (1.0 + 1e-12))
            told(total - still, total)
        opened: list[BOX] = []
        while heap and len(opened) < OPEN_BATCH and -heap[0][0] > best_value * (1.0 + 1e-12):
            opened.append(heapq.heappop(heap)[2])
        single = [b for b in opened if grid._box_size(b) == 1]
        if single:  # exact values of single centres
            index = np.array([[s.start for s in b] for b in single])
            exact = objective.optimal(mesh[tuple(index.T)])
            evaluations += len(single)
            i = int(exact.argmax())
            if exact[i] > best_value:
                best_value, best_index = float(exact[i]), tuple(int(v) for v in index[i])
        children = [c for b in opened if grid._box_size(b) > 1 for c in grid._split(b)]
        if children:
            evaluations += len(children)
            for b, box in zip(bounds(children), children, strict=True):
                heapq.heappush(heap, (-float(b), next(counter), box))
    told(total, total, force=True)
    position = mesh[best_index].copy()
    levels, value = objective.optimal_levels(position)
    return grid.GridResult(
        position=position,
        levels=levels,
        power_w=levels_to_power(levels, channel.p_max_w, levels_n),
        objective=value,
        lattice_points=int(np.prod(shape)),
        evaluations=evaluations,
    )
