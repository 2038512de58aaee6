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
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.comms.service_env import SearchSpace, levels_to_power
from uavxai.errors import UserError

DP_BYTES_PER_CALL = 4_000_000  # positions per vectorised DP call: a few MB, stays in cache
MAX_DP_COST = 20.0  # relative to K = 10, L = 6 (5 ms a position, 5-20 s a grid); beyond: hours
INITIAL_BOX = 8  # lattice points per side of the first boxes


def level_rates(
    channel: Channel, gain: np.ndarray, power_levels: int
) -> tuple[np.ndarray, np.ndarray]:
    """Rate of user k at level l when the levels add up to S, and whether it misses QoS.

    ``gain`` is ``(N, K)``; returns ``rates, fails`` of shape ``(N, S_max, K, L)`` where index
    ``i`` along axis 1 is the total ``S = i + 1``.
    """
    L = power_levels
    s_total = np.arange(1, channel.k * (L - 1) + 1, dtype=float)  # (nS,)
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
    rates: np.ndarray, fails: np.ndarray, keep_choices: bool = False
) -> tuple[np.ndarray, tuple[int, int] | None, list[np.ndarray]]:
    """Exact DP over users: the best objective per position ``(N,)``; with ``keep_choices``
    (N = 1) also the best ``(S index, lambda)`` and the per-user choice tables to backtrack."""
    N, nS, K, L = rates.shape
    s_max = K * (L - 1)
    # value[n, S, s, lam]: the best sum rate of the users so far, with levels adding up to s
    # and lam of them below QoS, knowing that all K users will add up to S.
    value = np.full((N, nS, s_max + 1, K + 1), -np.inf)
    value[:, :, 0, 0] = 0.0
    choices: list[np.ndarray] = []
    for j in range(K):
        reach = j * (L - 1)  # after j users: level sum <= reach, failures <= j
        src = value[:, :, : reach + 1, : j + 1]
        cand = np.empty_like(src)
        new = np.full_like(value, -np.inf)
        choice = np.zeros(value.shape, dtype=np.int8) if keep_choices else None
        for level in range(L):
            rate, fail = rates[:, :, j, level], fails[:, :, j, level]
            # A user that meets QoS keeps lam, one that misses it moves to lam + 1.
            for lam_shift, bias in (
                (0, np.where(fail, -np.inf, rate)),
                (1, np.where(fail, rate, -np.inf)),
            ):
                np.add(src, bias[:, :, None, None], out=cand)
                dst = new[:, :, level : level + reach + 1, lam_shift : lam_shift + j + 1]
                if choice is not None:
                    view = choice[:, :, level : level + reach + 1, lam_shift : lam_shift + j + 1]
                    view[cand > dst] = level
                np.maximum(dst, cand, out=dst)
        value = new
        if choice is not None:
            choices.append(choice)
    final = value[:, np.arange(nS), np.arange(1, nS + 1), :]  # (N, nS, K + 1)
    objective = (final / 2.0 ** np.arange(K + 1)).reshape(N, -1)
    flat = objective.argmax(axis=1)
    best = objective[np.arange(N), flat]
    where = divmod(int(flat[0]), K + 1) if keep_choices else None
    return best, where, choices


def optimal_objective(channel: Channel, gain: np.ndarray, power_levels: int) -> np.ndarray:
    """The best objective over all discrete power levels for each row of ``gain (N, K)``."""
    gain = np.atleast_2d(gain)
    s_max = channel.k * (power_levels - 1)
    batch = max(1, DP_BYTES_PER_CALL // (8 * s_max * (s_max + 1) * (channel.k + 1)))
    out = np.empty(len(gain))
    for i in range(0, len(gain), batch):
        rates, fails = level_rates(channel, gain[i : i + batch], power_levels)
        out[i : i + batch] = _knapsack(rates, fails)[0]
    return out


def dp_cost(k: int, power_levels: int) -> float:
    """Work of one position's DP relative to K = 10, L = 6: (K (L-1))^2 K^2 L."""
    return (k * (power_levels - 1)) ** 2 * k**2 * power_levels / (50**2 * 10**2 * 6)


def optimal_levels(
    channel: Channel, gain: np.ndarray, power_levels: int
) -> tuple[np.ndarray, float]:
    """The optimal integer levels ``(K,)`` for one position's gains ``(K,)`` and the objective."""
    rates, fails = level_rates(channel, np.asarray(gain, float)[None, :], power_levels)
    best, (s_index, lam), choices = _knapsack(rates, fails, keep_choices=True)
    levels = np.zeros(channel.k, dtype=np.int64)
    s = s_index + 1
    for j in reversed(range(channel.k)):
        level = int(choices[j][0, s_index, s, lam])
        levels[j] = level
        s -= level
        lam -= int(fails[0, s_index, j, level])
    return levels, float(best[0])


@dataclass(frozen=True)
class GridResult:
    position: np.ndarray  # (3,) m
    levels: np.ndarray  # (K,)
    power_w: np.ndarray  # (K,)
    objective: float
    lattice_points: int
    evaluations: int  # DP solves (boxes and single positions)


def solve_grid(channel: Channel, space: SearchSpace, power_levels: int) -> GridResult:
    """The exact optimum of position (on the lattice) and power levels, fading-free."""
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
    xs, ys, hs = space.axes()
    mesh = np.stack(np.meshgrid(xs, ys, hs, indexing="ij"), axis=-1)  # (nx, ny, nh, 3)
    gains = channel.mean_gain(mesh)  # (nx, ny, nh, K)
    shape = gains.shape[:3]

    def bound(box: tuple[slice, slice, slice]) -> np.ndarray:
        return gains[box].max(axis=(0, 1, 2))

    def size(box: tuple[slice, slice, slice]) -> int:
        return int(np.prod([s.stop - s.start for s in box]))

    boxes = [
        tuple(slice(a, min(a + INITIAL_BOX, n)) for a, n in zip(corner, shape, strict=True))
        for corner in itertools.product(*(range(0, n, INITIAL_BOX) for n in shape))
    ]
    # A first incumbent: the centre of every initial box, evaluated exactly.
    centres = np.array([[(s.start + s.stop - 1) // 2 for s in box] for box in boxes])
    values = optimal_objective(channel, gains[tuple(centres.T)], power_levels)
    best_i = int(values.argmax())
    best_value, best_index = float(values[best_i]), tuple(int(v) for v in centres[best_i])
    evaluations = len(boxes)

    frontier = boxes
    while frontier:
        bounds = optimal_objective(channel, np.array([bound(b) for b in frontier]), power_levels)
        evaluations += len(frontier)
        children: list[tuple[slice, slice, slice]] = []
        order = np.argsort(-bounds, kind="stable")
        for i in order:
            box, value = frontier[i], float(bounds[i])
            if size(box) == 1:  # a single position: its bound is its exact value
                if value > best_value:
                    best_value, best_index = value, tuple(s.start for s in box)
                continue
            if value <= best_value:
                continue
            children.extend(_split(box))
        frontier = children
        # Boxes left behind by an improved incumbent are pruned on their next bound.
    position = mesh[best_index]
    levels, objective = optimal_levels(channel, gains[best_index], power_levels)
    return GridResult(
        position=position.copy(),
        levels=levels,
        power_w=levels_to_power(levels, channel.p_max_w, power_levels),
        objective=objective,
        lattice_points=int(np.prod(shape)),
        evaluations=evaluations,
    )


def _split(box: tuple[slice, slice, slice]) -> list[tuple[slice, slice, slice]]:
    halves = []
    for s in box:
        if s.stop - s.start > 1:
            mid = (s.start + s.stop) // 2
            halves.append((slice(s.start, mid), slice(mid, s.stop)))
        else:
            halves.append((s,))
    return [tuple(parts) for parts in itertools.product(*halves)]
