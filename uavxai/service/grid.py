"""The reference optimum: every lattice position, each with its exactly optimal power levels.

Power. For one position the levels ``l`` in ``{0..L-1}^K`` map to watts by ``levels_to_power``:
``p_k = P_max l_k / max(S, L-1)`` with ``S = sum_k l_k``. Once S is fixed, every ``p_k`` depends
on ``l_k`` alone and so does the interference of the shared band (it sees the fixed total
``P_max S / max(S, L-1)``): user k's rate and QoS failure are a table ``r_k(l)``. The best
allocation with total S is then a knapsack over users solved exactly by dynamic programming
on (levels used so far, users below QoS so far); the objective ``sum r / 2^lambda`` is read
off at the end and maximised over S. That is the true optimum of the discrete problem, at
``O(K^2 L^2 · K L)`` per position instead of ``L^K`` (6^10 = 60 million) allocations.

Positions. The lattice of ``SearchSpace.axes`` (the points the moves of the environment can
reach; 51 x 51 x 26 = 67,626 for the defaults). Evaluating the DP everywhere would take
minutes, so the search is a branch-and-bound that is still exact: for any fixed levels the
objective never decreases when a user's gain increases (the SINR of both access modes grows
with g_k, so rates grow and QoS failures drop). The optimum over a box of positions is hence
at most the optimum for the per-user *maximum* gains over the box. Boxes whose bound cannot
beat the best position found are dropped; the others are split in 8 until single positions.

What keeps it fast without giving up exactness: the DP runs over blocks of totals S and only
on the level sums that can still end in the block (a third of the table for K = 20); the
incumbent can be seeded by a ``hint`` (a planner's answer), so boxes are pruned from the
start; and the DP drops allocations with so many users below QoS that, even at the lattice's
per-user peak gains, ``sum rate / 2^lambda`` cannot reach the incumbent (``_failure_cap``:
7 of 21 failure counts kept in the shared band with K = 20, 1 in OFDMA), and the level totals
S whose best at those peak gains cannot reach it either (``useful_totals``: in the shared
band, where the position hardly matters, a few of the hundred). One core: K = 5 under 1 s,
K = 10 1-3 s, K = 20 about 2 s, against 1-6.5 min for K = 20 before. In OFDMA a water-filling
ceiling (``rate_ceiling``, no DP) drops most boxes before the DP is run.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.errors import UserError
from uavxai.service.service_env import SearchSpace, levels_to_power

DP_BYTES_PER_CALL = 16_000_000  # memory per vectorised DP call: a batch of positions
MAX_DP_COST = 20.0  # relative to K = 10, L = 6 (5 ms a position, 5-20 s a grid); beyond: hours
INITIAL_BOX = 8  # lattice points per side of the first boxes
S_BLOCK = 5  # level totals per DP block (one level range: few sums wasted, few calls)


def level_rates(
    channel: Channel, gain: np.ndarray, power_levels: int, totals: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Rate of user k at level l when the levels add up to S, and whether it misses QoS.

    ``gain`` is ``(N, K)``; returns ``rates, fails`` of shape ``(N, S_max, K, L)`` where index
    ``i`` along axis 1 is the total ``S = i + 1``.
    """
    L = power_levels
    every = np.arange(1, channel.k * (L - 1) + 1)
    s_total = (every if totals is None else np.asarray(totals)).astype(float)  # (nS,)
    unit = channel.p_max_w / np.maximum(s_total, L - 1)
    p = unit[:, None] * np.arange(L)  # (nS, L)
    g = gain[:, None, :, None]  # (N, 1, K, 1)
    if channel.access == "shared":
        # Total power minus the user's own; negative only for levels above S (unreachable).
        other = np.maximum((s_total * unit)[:, None] - p, 0.0)
        sinr = g * p[None, :, None, :] / (g * other[None, :, None, :] + channel.noise_w)
    else:
        sinr = g * p[None, :, None, :] / (channel.noise_w / channel.k)
    rates = channel.user_bandwidth_hz() * np.log2(1.0 + sinr)
    return rates, rates < channel.qos_rate_bps


def _knapsack(
    rates: np.ndarray,
    fails: np.ndarray,
    keep_choices: bool = False,
    cap: int | None = None,
    totals: np.ndarray | None = None,
) -> tuple[np.ndarray, tuple[int, int] | None, list[np.ndarray]]:
    """Exact DP over users: the best objective per position ``(N,)``; with ``keep_choices``
    (N = 1) also the best ``(S index, lambda)`` and the per-user choice tables to backtrack.

    With ``cap`` only allocations with fewer than ``cap`` users below QoS are considered (the
    branch-and-bound caps where no allocation with more failures can matter, ``_failure_cap``):
    the DP's work is proportional to the number of failure counts it keeps. ``totals`` (the
    level totals S the tables were made for, ``level_rates(totals=...)``) restricts it to those.
    """
    N, nS, K, L = rates.shape
    cap = K + 1 if cap is None else min(cap, K + 1)
    final = np.empty((N, nS, cap))  # best sum rate per (S, lambda)
    choices: list[np.ndarray] = []
    totals = np.arange(1, nS + 1) if totals is None else np.asarray(totals)
    # Totals S in blocks of consecutive ones: a block only needs the level sums that can
    # still end inside it.
    size = nS if keep_choices else S_BLOCK
    first = 0
    while first < nS:
        last = first + 1
        while last < min(first + size, nS) and totals[last] == totals[last - 1] + 1:
            last += 1
        final[:, first:last], choices = _knapsack_block(
            rates[:, first:last], fails[:, first:last], int(totals[first]), cap, keep_choices
        )
        first = last
    objective = (final / 2.0 ** np.arange(cap)).reshape(N, -1)
    flat = objective.argmax(axis=1)
    best = objective[np.arange(N), flat]
    where = divmod(int(flat[0]), cap) if keep_choices else None
    return best, where, choices


def _knapsack_block(
    rates: np.ndarray,
    fails: np.ndarray,
    s_first: int,
    cap: int,
    keep_choices: bool,
    fail_rates: np.ndarray | None = None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The DP for totals ``S = s_first .. s_first + nB - 1``: best sum rate ``(N, nB, cap)``.

    With ``fail_rates`` a user may count as failing at any level, adding ``fail_rates``.
    """
    N, nB, K, L = rates.shape
    s_last = s_first + nB - 1
    width = min(s_last, K * (L - 1)) + 1
    # value[n, S, s, lam]: the best sum rate of the users so far, with levels adding up to s
    # and lam of them below QoS, knowing that all K users will add up to S.
    value = np.full((N, nB, width, cap), -np.inf)
    value[:, :, 0, 0] = 0.0
    choices: list[np.ndarray] = []
    for j in range(K):
        # Sums below lo cannot reach s_first with the K - j users left; above hi are unused.
        lo, hi = max(0, s_first - (K - j) * (L - 1)), min(j * (L - 1), s_last)
        lams = min(j + 1, cap)  # after j users, lam < lams
        new = np.full_like(value, -np.inf)
        choice = np.zeros(value.shape, dtype=np.int8) if keep_choices else None
        for level in range(L):
            n = min(hi + level, width - 1) - (lo + level) + 1
            if n <= 0:
                continue
            src = value[:, :, lo : lo + n, :lams]
            rate, fail = rates[:, :, j, level], fails[:, :, j, level]
            missed = (
                np.where(fail, rate, -np.inf) if fail_rates is None else fail_rates[:, :, j, level]
            )
            # A user that meets QoS keeps lam, one that misses it moves to lam + 1.
            for shift, bias in enumerate((np.where(fail, -np.inf, rate), missed)):
                moved = min(lams, cap - shift)  # source lams whose lam + shift is kept
                cand = src[..., :moved] + bias[:, :, None, None]
                dst = new[:, :, lo + level : lo + level + n, shift : shift + moved]
                if choice is not None:
                    view = choice[:, :, lo + level : lo + level + n, shift : shift + moved]
                    view[cand > dst] = level
                np.maximum(dst, cand, out=dst)
        value = new
        if choice is not None:
            choices.append(choice)
    return value[:, np.arange(nB), np.arange(s_first, s_last + 1), :], choices


def optimal_objective(
    channel: Channel,
    gain: np.ndarray,
    power_levels: int,
    cap: int | None = None,
    totals: np.ndarray | None = None,
) -> np.ndarray:
    """The best objective over all discrete power levels for each row of ``gain (N, K)``
    (over the allocations with fewer than ``cap`` users below QoS and level totals in
    ``totals``, if given)."""
    gain = np.atleast_2d(gain)
    s_max = channel.k * (power_levels - 1)
    lams = channel.k + 1 if cap is None else min(cap, channel.k + 1)
    # rates and fails (N, S, K, L), a block's states (N, S_BLOCK, s, lambda), in float64
    n_totals = s_max if totals is None else len(totals)
    per_row = 8 * (2 * n_totals * channel.k * power_levels + 3 * S_BLOCK * (s_max + 1) * lams)
    batch = max(1, DP_BYTES_PER_CALL // per_row)
    out = np.empty(len(gain))
    for i in range(0, len(gain), batch):
        rates, fails = level_rates(channel, gain[i : i + batch], power_levels, totals)
        out[i : i + batch] = _knapsack(rates, fails, cap=cap, totals=totals)[0]
    return out


def dp_cost(k: int, power_levels: int) -> float:
    """Work of one position's DP relative to K = 10, L = 6: (K (L-1))^2 K^2 L."""
    return (k * (power_levels - 1)) ** 2 * k**2 * power_levels / (50**2 * 10**2 * 6)


def optimal_levels(
    channel: Channel, gain: np.ndarray, power_levels: int, cap: int | None = None
) -> tuple[np.ndarray, float]:
    """The optimal integer levels ``(K,)`` for one position's gains ``(K,)`` and the objective
    (over the allocations with fewer than ``cap`` users below QoS, if given: exact whenever
    no allocation with ``cap`` or more failures can win, as ``_failure_cap`` ensures)."""
    rates, fails = level_rates(channel, np.asarray(gain, float)[None, :], power_levels)
    cap = channel.k + 1 if cap is None else min(cap, channel.k + 1)
    # The best (S, lambda) from the DP over every total in one block without choice tables,
    # then the choice tables of the DP for that S alone (2-3x less work than keeping the
    # tables for every S; for one position one block beats _knapsack's blocks of S_BLOCK).
    final, _ = _knapsack_block(rates, fails, 1, cap, False)
    objective = final[0] / 2.0 ** np.arange(cap)
    s_index, lam = (int(i) for i in np.unravel_index(int(objective.argmax()), objective.shape))
    best = float(objective[s_index, lam])
    part = slice(s_index, s_index + 1)
    _, choices = _knapsack_block(rates[:, part], fails[:, part], s_index + 1, cap, True)
    levels = np.zeros(channel.k, dtype=np.int64)
    s = s_index + 1
    for j in reversed(range(channel.k)):
        level = int(choices[j][0, 0, s, lam])
        levels[j] = level
        s -= level
        lam -= int(fails[0, s_index, j, level])
    return levels, best


@dataclass(frozen=True)
class GridResult:
    position: np.ndarray  # (3,) m
    levels: np.ndarray  # (K,)
    power_w: np.ndarray  # (K,)
    objective: float
    lattice_points: int
    evaluations: int  # DP solves (boxes and single positions)


Progress = Callable[[int, int], None]  # (lattice points settled, lattice points in all)


class Told:
    """Calls a :data:`Progress` callback at most every ``every_s`` (the search's loops are
    tight; a bar needs a few updates a second, not thousands)."""

    def __init__(self, progress: Progress | None, every_s: float = 0.25) -> None:
        self.progress, self.every_s = progress, every_s
        self.last = -math.inf

    def due(self) -> bool:
        return self.progress is not None and time.monotonic() - self.last >= self.every_s

    def __call__(self, settled: int, total: int, force: bool = False) -> None:
        if self.progress is not None and (force or self.due()):
            self.last = time.monotonic()
            self.progress(settled, total)


def solve_grid(
    channel: Channel,
    space: SearchSpace,
    power_levels: int,
    hint: np.ndarray | None = None,
    progress: Progress | None = None,
) -> GridResult:
    """The exact optimum of position (on the lattice) and power levels, fading-free.

    ``hint`` (a position, e.g. a planner's answer) only seeds the incumbent: the lattice point
    nearest to it is evaluated exactly, so a good hint prunes more but never changes the result.
    ``progress(settled, total)`` hears now and then how many lattice points are settled.
    """
    cost = dp_cost(channel.k, power_levels)
    if cost > MAX_DP_COST:
        k_max = max(k for k in range(1, 65) if dp_cost(k, power_levels) <= MAX_DP_COST)
        raise UserError(
            f"service.planner grid: the exact power search for K = {channel.k} users and "
            f"power_levels = {power_levels} costs {cost:.0f} times the default (K = 10, L = 6) "
            f"per position, too slow for thousands of positions; with power_levels = "
            f"{power_levels} the grid planner takes up to K = {k_max} users. Use planner "
            "random or d3qn (after `uavxai train`) instead."
        )
    axes = space.axes()
    mesh = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)  # (nx, ny, nh, 3)
    gains = channel.mean_gain(mesh)  # (nx, ny, nh, K)
    shape = gains.shape[:3]
    boxes = [
        tuple(slice(a, min(a + INITIAL_BOX, n)) for a, n in zip(corner, shape, strict=True))
        for corner in itertools.product(*(range(0, n, INITIAL_BOX) for n in shape))
    ]
    if hint is None:  # a first incumbent: the centre of every initial box, evaluated exactly
        seeds = np.array([[(s.start + s.stop - 1) // 2 for s in box] for box in boxes])
    else:
        seeds = np.array([[int(np.abs(ax - v).argmin()) for ax, v in zip(axes, hint, strict=True)]])
    values = optimal_objective(channel, gains[tuple(seeds.T)], power_levels)
    best_index = tuple(int(v) for v in seeds[int(values.argmax())])
    best_levels, best_value = optimal_levels(channel, gains[best_index], power_levels)
    best_index, evaluations = _branch_and_bound(
        channel, gains, power_levels, boxes, (best_value, best_index), _failures(
            channel, gains[best_index], best_levels, power_levels), Told(progress)
    )
    levels, objective = optimal_levels(channel, gains[best_index], power_levels)
    return GridResult(
        position=mesh[best_index].copy(),
        levels=levels,
        power_w=levels_to_power(levels, channel.p_max_w, power_levels),
        objective=objective,
        lattice_points=int(np.prod(shape)),
        evaluations=evaluations + len(seeds),
    )


def _failures(channel: Channel, gain: np.ndarray, levels: np.ndarray, power_levels: int) -> int:
    rate = channel.rate(gain, levels_to_power(levels, channel.p_max_w, power_levels))
    return int((rate < channel.qos_rate_bps).sum())


Box = tuple[slice, slice, slice]


def _failure_cap(
    channel: Channel, peak: np.ndarray, power_levels: int, incumbent: float, failures: int
) -> int:
    """The fewest failures ``c`` (more than the incumbent's) from which on no allocation can
    beat the incumbent anywhere on the lattice: ``sum rate / 2^lambda <= incumbent`` for every
    allocation with ``lambda >= c`` users below QoS at any position. At a position with gains
    ``g <= peak`` such an allocation's users that meet QoS also meet it at ``peak`` with a
    higher rate and the failing ones add less than ``min(rate at peak, QoS rate)``: the DP at
    ``peak`` in which a user may count as failing at any level with that rate bounds them."""
    rates, fails = level_rates(channel, peak[None, :], power_levels)
    relaxed = np.minimum(rates, channel.qos_rate_bps)
    final, _ = _knapsack_block(rates, fails, 1, channel.k + 1, False, relaxed)
    best = final[0].max(axis=0) / 2.0 ** np.arange(channel.k + 1)  # per lambda
    tail = np.maximum.accumulate(best[::-1])[::-1]  # the best with lambda or more failures
    return next(
        (c for c in range(failures + 1, channel.k + 1) if tail[c] <= incumbent), channel.k + 1
    )


def useful_totals(
    channel: Channel, peak: np.ndarray, power_levels: int, incumbent: float, cap: int
) -> np.ndarray:
    """The level totals S whose best allocation can beat the incumbent somewhere: for fixed
    levels the objective grows with every gain, so the best with total S at the lattice's
    per-user peak gains bounds it at every position. In the shared band, where the position
    hardly matters, this leaves a few totals of the hundred for K = 20."""
    rates, fails = level_rates(channel, peak[None, :], power_levels)
    final, _ = _knapsack_block(rates, fails, 1, cap, False)
    per_total = (final[0] / 2.0 ** np.arange(cap)).max(axis=1)
    return np.flatnonzero(per_total > incumbent) + 1


def rate_ceiling(channel: Channel, gains: np.ndarray) -> np.ndarray:
    """OFDMA: the water-filling sum rate for gains ``(N, K)``, the best over any continuous
    split of ``P_max``, so above the objective of every discrete allocation (levels split at
    most ``P_max``; failures only divide). Ten times cheaper than the DP, it drops most boxes
    first. Shared band: no such cheap ceiling, ``inf``."""
    if channel.access != "ofdma":
        return np.full(len(gains), np.inf)
    a = np.sort(gains * channel.k / channel.noise_w, axis=1)[:, ::-1]  # SNR per watt, best first
    m = np.arange(1, channel.k + 1)
    level = (channel.p_max_w + np.cumsum(1.0 / a, axis=1)) / m  # water level with m users
    active = level > 1.0 / a  # the users the water level covers: a prefix
    used = active.sum(axis=1)
    mu = level[np.arange(len(gains)), used - 1]
    gain_bits = np.where(active, np.log2(np.maximum(a * mu[:, None], 1.0)), 0.0)
    return channel.user_bandwidth_hz() * gain_bits.sum(axis=1)


def _branch_and_bound(
    channel: Channel,
    gains: np.ndarray,
    power_levels: int,
    boxes: list[Box],
    incumbent: tuple[float, tuple[int, ...]],
    failures: int,
    told: Told,
) -> tuple[tuple[int, ...], int]:
    """The lattice index of the optimum and the number of DP solves.

    The DP leaves out allocations with ``_failure_cap`` or more users below QoS and level
    totals other than ``useful_totals``: they cannot beat the incumbent, so every bound above
    it, and every position's value above it, is exactly what the full DP gives.
    """
    best_value, best_index = incumbent
    peak = gains.max(axis=(0, 1, 2))
    cap = _failure_cap(channel, peak, power_levels, best_value, failures)
    totals = useful_totals(channel, peak, power_levels, best_value, cap)
    evaluations, frontier = 2, boxes if len(totals) else []
    total = int(np.prod(gains.shape[:3]))
    while frontier:
        if told.due():
            told(total - sum(_box_size(b) for b in frontier), total)
        peaks = np.array([gains[b].max(axis=(0, 1, 2)) for b in frontier])
        bounds = np.full(len(frontier), -np.inf)
        open_ = rate_ceiling(channel, peaks) > best_value
        bounds[open_] = optimal_objective(channel, peaks[open_], power_levels, cap, totals)
        evaluations += int(open_.sum())
        children: list[Box] = []
        for i in np.argsort(-bounds, kind="stable"):
            box, value = frontier[i], float(bounds[i])
            if value <= best_value:
                continue
            if all(s.stop - s.start == 1 for s in box):  # a single position: its exact value
                best_value, best_index = value, tuple(s.start for s in box)
                continue
            children.extend(_split(box))
        frontier = children
        # Boxes left behind by an improved incumbent are pruned on their next bound.
    told(total, total, force=True)
    return best_index, evaluations


def _box_size(box: Box) -> int:
    return math.prod(s.stop - s.start for s in box)


def _split(box: Box) -> list[Box]:
    halves = []
    for s in box:
        if s.stop - s.start > 1:
            mid = (s.start + s.stop) // 2
            halves.append((slice(s.start, mid), slice(mid, s.stop)))
        else:
            halves.append((s,))
    return [tuple(parts) for parts in itertools.product(*halves)]
