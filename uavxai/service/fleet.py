"""Fleet placement (issue 32): where N UAVs hover, which UAV serves each user, and with what
power, for the fleet's objective ``sum_k R_k / 2^lambda`` over all K users
(``uavxai.comms.fleet``, docs/service/fleet.md). Fading-free, on the one-UAV planners' lattice
(``SearchSpace.axes``) and discrete power levels.

- ``kmeans_baseline``: k-means of the users into N clusters (seeded), one UAV per cluster above
  the cluster's centroid (the nearest lattice column) at the lattice height that is best for
  its own users alone at equal power; association = cluster; equal power (levels all L-1).
- ``plan_fleet`` (the ``fleet`` planner): from the k-means baselines of seeds 0 and 1 (0-4
  where N K <= 40; one per distinct partition of the users; in the shared band where
  N K > 40, the 2 of seeds 0-4 with the fewest users short of QoS by ``qos_shortfall``, where
  N K > 120 only those tied at the fewest) a descent: a vectorised
  best-improvement local search over the whole fleet (a UAV moves 1 or 4 lattice steps, a
  user's level changes, a user changes UAV; candidates scored from the incumbent's received
  powers), in the shared band ``block_power`` (each UAV's best levels
  with the others fixed, ``grid.optimal_levels``) and the local search again; the best
  descent, then ``relocate`` (one UAV jumps on a coarse lattice) while it improves.
- ``reference_fleet``: exact by enumeration where the problem is tiny; otherwise the best of
  many starts (the planner's answer and k-means starts of several seeds) of a block-coordinate
  ascent: each UAV in turn re-placed by the exact one-UAV ``grid`` with the others fixed
  (their interference folded into its users' gains), then the fleet local search with a wider
  neighbourhood (steps 1-8, level moves between users), until a round improves nothing. What
  it certifies is in docs/service/fleet.md.
- ``upper_bound``: in OFDMA a certified bound on every fleet's objective (each user from its
  best lattice point, the budgets pooled, water-filled); none in the shared band.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass, replace

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.comms.fleet import FleetChannel
from uavxai.service.grid import (
    MAX_DP_COST,
    dp_cost,
    optimal_levels,
    rate_ceiling,
    solve_grid,
)
from uavxai.service.layouts import problem_scenario
from uavxai.service.service_env import MOVES, SearchSpace

PLANNER_STEPS = (1, 4)  # lattice steps a UAV may move in one local-search candidate
REFERENCE_STEPS = (1, 2, 4, 8)
COARSE_EVERY = 5  # the relocation's coarse lattice: every 5th point per axis (50 m apart)
RELOCATIONS = 3  # at most this many coarse jumps per plan
POWER_ROUNDS = 1  # exact per-UAV power passes per descent
PLANNER_STARTS = 2  # k-means seeds the planner descends from (OFDMA: seeds 0-1)
SMALL_STARTS = 5  # ... where N K <= SMALL_FLEET: a descent there costs a few ms
SMALL_FLEET = 40
SCREENED_STARTS = 5  # shared band, N K > SMALL_FLEET: seeds screened by their QoS shortfall
LARGE_FLEET = 120  # ... where N K > LARGE_FLEET only the starts tied at the fewest shortfalls
EXACT_POWER_K = 12  # the planner's exact per-UAV power DP up to this many users (5-25 ms)
REFERENCE_STARTS = 4  # k-means seeds the reference starts from, besides the planner's answer
EXHAUSTIVE_LIMIT = 2_000_000  # fleets the reference enumerates before it searches instead
KMEANS_ITERATIONS = 50
IMPROVES = 1.0 + 1e-12  # a candidate must beat the incumbent by more than rounding


@dataclass(frozen=True)
class Separation:
    """How far apart two stations must be (docs/fleet.md, "Orbits kept apart"): at least
    ``horizontal_m`` apart horizontally, or at least ``vertical_m`` apart in height (a layer
    of its own), so that UAVs orbiting them never share the NMAC cylinder."""

    horizontal_m: float
    vertical_m: float

    def apart(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Whether stations ``a (..., 3)`` and ``b (..., 3)`` are apart (broadcast)."""
        d = a - b
        return (np.hypot(d[..., 0], d[..., 1]) >= self.horizontal_m) | (
            np.abs(d[..., 2]) >= self.vertical_m
        )

    def violations(self, positions: np.ndarray) -> list[tuple[int, int]]:
        """The pairs of stations ``(N, 3)`` that are not apart."""
        n = len(positions)
        return [(i, j) for i, j in itertools.combinations(range(n), 2)
                if not self.apart(positions[i], positions[j])]  # fmt: skip


@dataclass(frozen=True)
class FleetProblem:
    """One placement problem: the fleet's channel, the lattice the UAVs hover on, levels L;
    with ``separation`` the planner's stations keep it (None: stations may coincide)."""

    fleet: FleetChannel
    space: SearchSpace
    power_levels: int
    separation: Separation | None = None


def fleet_problem(
    users_xy: np.ndarray, n: int, access: str, model: str, environment: str = "urban"
) -> FleetProblem:
    """N UAVs over these users in the default scenario (fading-free, its lattice and levels)
    with the access mode and path-loss model (``comms.channel``) given."""
    sc = problem_scenario(users_xy, access, environment)
    sc = sc.model_copy(update={"comms": sc.comms.model_copy(update={"channel": model})})
    fleet = FleetChannel.of(Channel.from_scenario(sc), n)
    return FleetProblem(fleet, SearchSpace.from_scenario(sc), sc.comms.power_levels)


@dataclass(frozen=True)
class FleetPlan:
    positions: np.ndarray  # (N, 3) m
    association: np.ndarray  # (K,) serving UAV of each user
    levels: np.ndarray  # (K,) 0..L-1
    power_w: np.ndarray  # (K,)
    objective: float


def make_plan(
    problem: FleetProblem, positions, association, levels, gains: np.ndarray | None = None
) -> FleetPlan:
    """A plan with its power and objective computed from the channel (``gains``: the gains
    of ``positions`` if the caller has them already)."""
    fleet, L = problem.fleet, problem.power_levels
    positions = np.asarray(positions, float)
    association = np.asarray(association, np.int64)
    levels = np.asarray(levels, np.int64)
    power = fleet.power(levels, association, L)
    gains = fleet.gains(positions) if gains is None else gains
    value = float(fleet.evaluate_gains(gains, association, power).objective)
    return FleetPlan(positions, association, levels, power, value)


# --------------------------------------------------------------------------- k-means baseline
def kmeans(xy: np.ndarray, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Lloyd's k-means with k-means++ seeding from ``default_rng(seed)``: labels ``(K,)`` and
    centres ``(n, 2)``. No cluster is left empty while K >= n (an empty one takes the user
    farthest from its centre)."""
    rng = np.random.default_rng(seed)
    centres = [xy[int(rng.integers(len(xy)))]]
    for _ in range(1, n):
        d2 = ((xy[:, None, :] - np.array(centres)[None]) ** 2).sum(-1).min(axis=1)
        p = d2 / d2.sum() if d2.sum() > 0 else np.full(len(xy), 1.0 / len(xy))
        centres.append(xy[int(rng.choice(len(xy), p=p))])
    c = np.array(centres, dtype=float)
    labels = np.zeros(len(xy), dtype=np.int64)
    for _ in range(KMEANS_ITERATIONS):
        d2 = ((xy[:, None, :] - c[None]) ** 2).sum(-1)
        labels = d2.argmin(axis=1)
        for j in range(n):
            if not np.any(labels == j) and len(xy) >= n:
                far = int(d2[np.arange(len(xy)), labels].argmax())
                labels[far] = j
        new = np.array([xy[labels == j].mean(axis=0) for j in range(n)])
        if np.allclose(new, c):
            break
        c = new
    return labels, c


def best_heights(problem: FleetProblem, xy: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Positions ``(N, 3)`` at ``xy`` each at the lattice height best for its own users alone
    (no other UAV transmitting) at equal power. The gains of every UAV's column are one
    call; with nobody else transmitting each UAV's channel is its users' own (no
    interference folded in), so its rates are the one-UAV channel's of those gains."""
    fleet = problem.fleet
    hs = problem.space.axes()[2]
    columns = np.concatenate([np.repeat(xy[:, None, :], len(hs), axis=1),
                              np.broadcast_to(hs[None, :, None], (len(xy), len(hs), 1))], -1)
    gains = fleet.channel.mean_gain(columns.reshape(-1, 3)).reshape(len(xy), len(hs), -1)
    silent, nobody = np.zeros(fleet.k), np.zeros((fleet.n, fleet.k))
    out = []
    for n in range(fleet.n):
        mine = labels == n
        if not np.any(mine):
            out.append(columns[n, 0])
            continue
        own = fleet.uav_channel(n, nobody, labels, silent)
        values = own.objective(own.rate(gains[n][:, mine], own.equal_power()))
        out.append(columns[n, int(np.argmax(values))])
    return np.array(out)


def kmeans_baseline(problem: FleetProblem, seed: int = 0) -> FleetPlan:
    """The naive fleet: k-means clusters, each UAV above its centroid (the nearest lattice
    column) at the best lattice height for its own users at equal power, association =
    cluster, equal power."""
    labels, centres = kmeans(problem.fleet.channel.users[:, :2], problem.fleet.n, seed)
    return equal_power(problem, kmeans_positions(problem, labels, centres), labels)


def kmeans_positions(problem: FleetProblem, labels: np.ndarray, centres: np.ndarray):
    """The baseline's UAV positions ``(N, 3)`` for these clusters: above each centroid (the
    nearest lattice column) at the height best for its own users (``best_heights``)."""
    columns = snap(problem.space, np.column_stack([centres, np.zeros(len(centres))]))[:, :2]
    return best_heights(problem, columns, labels)


def equal_power(problem: FleetProblem, positions: np.ndarray, association: np.ndarray):
    """The plan with every user at the top level (each UAV's budget split equally)."""
    levels = np.full(problem.fleet.k, problem.power_levels - 1)
    return make_plan(problem, positions, association, levels)


# --------------------------------------------------------------------------- local search
class GainCache:
    """Gains ``(K,)`` of lattice points, computed once per problem: every UAV has the same
    gain function, and the local search asks for the same neighbours round after round. A
    lattice point's row is found through a dense index over the lattice (no Python loop per
    point: the search asks for ~50 points a round)."""

    def __init__(self, problem: FleetProblem) -> None:
        self.channel = problem.fleet.channel
        axes = problem.space.axes()
        self.origin = np.array([ax[0] for ax in axes])
        self.step = problem.space.step_m
        self.shape = tuple(len(ax) for ax in axes)
        self.slot = np.full(int(np.prod(self.shape)), -1, dtype=np.int64)
        self.table = np.empty((64, self.channel.k))
        self.size = 0

    def __call__(self, positions: np.ndarray) -> np.ndarray:
        """Gains ``(M, K)`` of lattice positions ``(M, 3)``."""
        index = np.rint((positions - self.origin) / self.step).astype(np.int64)
        flat = np.ravel_multi_index(tuple(index.T), self.shape)
        missing = self.slot[flat] < 0
        if missing.any():
            new, first = np.unique(flat[missing], return_index=True)
            end = self.size + len(new)
            if end > len(self.table):
                self.table = np.vstack([self.table, np.empty((end + len(self.table),
                                                              self.channel.k))])
            self.table[self.size : end] = self.channel.mean_gain(positions[missing][first])
            self.slot[new] = np.arange(self.size, end)
            self.size = end
        return self.table[self.slot[flat]]


@dataclass(frozen=True)
class Incumbent:
    """What every candidate of the local search is scored against (docs/service/fleet.md,
    "Local search"): the plan, the gains ``G (N, K)`` of its positions, each UAV's level total
    ``S (N,)``, watts per level ``unit (N,)`` and power ``P (N,)``, each user's gain from its
    own UAV ``served (K,)`` and total received power ``T (K,)`` from every UAV (its own
    UAV's included)."""

    plan: FleetPlan
    gains: np.ndarray
    totals: np.ndarray
    unit: np.ndarray
    power: np.ndarray
    served: np.ndarray
    received: np.ndarray

    @classmethod
    def of(cls, problem: FleetProblem, plan: FleetPlan, gains: np.ndarray) -> Incumbent:
        fleet = problem.fleet
        totals = np.bincount(plan.association, weights=plan.levels, minlength=fleet.n)
        unit = fleet.p_max_w / np.maximum(totals, problem.power_levels - 1)
        power = unit * totals
        served = gains[plan.association, np.arange(fleet.k)]
        return cls(plan, gains, totals, unit, power, served, power @ gains)


Terms = tuple[np.ndarray, np.ndarray, np.ndarray]  # served gain, own power, received power


def scores(problem: FleetProblem, served: np.ndarray, own: np.ndarray, received: np.ndarray):
    """The objective ``(C,)`` of C candidates from each user's served gain, own power and
    total received power ``(C, K)``: in the shared band everything user k receives but its
    own signal interferes (``T_k - g_k p_k``, the fleet SINR of docs/service/fleet.md)."""
    c = problem.fleet.channel
    sinr = served * own  # the signal, turned into the SINR and the rate in place (no copies)
    if c.access == "shared":
        interference = received - sinr
        interference += c.noise_w
        sinr /= interference
    else:
        sinr /= c.noise_w / c.k
    sinr += 1.0
    rate = np.log2(sinr, out=sinr)
    rate *= c.user_bandwidth_hz()
    return rate.sum(axis=-1) / 2.0 ** (rate < c.qos_rate_bps).sum(axis=-1)


@dataclass(frozen=True)
class Edits:
    """C candidates, each setting E users' serving UAV and level, positions fixed: user
    ``users[c, e]`` to UAV ``uavs[c, e]`` at level ``levels[c, e]`` (``(C, E)`` each; the E
    users of a candidate are distinct)."""

    users: np.ndarray
    uavs: np.ndarray
    levels: np.ndarray

    def __len__(self) -> int:
        return len(self.users)

    def applied(self, plan: FleetPlan, c: int) -> tuple[np.ndarray, np.ndarray]:
        """Candidate ``c``'s association and levels."""
        association, levels = plan.association.copy(), plan.levels.copy()
        association[self.users[c]], levels[self.users[c]] = self.uavs[c], self.levels[c]
        return association, levels


def edit_scores(problem: FleetProblem, inc: Incumbent, edits: Edits) -> np.ndarray:
    """The objective of every candidate of ``edits`` (``edit_terms``)."""
    return scores(problem, *edit_terms(problem, inc, edits))


def edit_terms(problem: FleetProblem, inc: Incumbent, edits: Edits) -> Terms:
    """Each user's served gain, own power and received power ``(C, K)`` for every candidate
    of ``edits``: an edit changes the level totals of at
    most two UAVs, so each candidate's totals, watts per level and powers are the incumbent's
    with those entries changed, its received powers ``P' G`` a ``(C, N) x (N, K)`` product,
    and only the edited users' served gains change."""
    plan, L, C = inc.plan, problem.power_levels, len(edits)
    rows = np.arange(C)
    totals = np.repeat(inc.totals[None], C, axis=0)
    for k, to, level in zip(edits.users.T, edits.uavs.T, edits.levels.T, strict=True):
        totals[rows, plan.association[k]] -= plan.levels[k]
        totals[rows, to] += level
    unit = problem.fleet.p_max_w / np.maximum(totals, L - 1)
    received = (unit * totals) @ inc.gains
    own = unit[:, plan.association] * plan.levels
    served = np.repeat(inc.served[None], C, axis=0)
    for k, to, level in zip(edits.users.T, edits.uavs.T, edits.levels.T, strict=True):
        own[rows, k] = unit[rows, to] * level
        served[rows, k] = inc.gains[to, k]
    return served, own, received


def move_scores(problem: FleetProblem, inc: Incumbent, who: np.ndarray, moved: np.ndarray):
    """The objective of every move candidate (``move_terms``)."""
    return scores(problem, *move_terms(inc, who, moved))


def move_terms(inc: Incumbent, who: np.ndarray, moved: np.ndarray) -> Terms:
    """The terms of ``scores`` ``(C, K)`` for candidates that move UAV ``who[c]`` to gains
    ``moved (C, K)``: only that UAV's gains change, so every user's received power changes
    by ``(G' - G) P`` of that UAV."""
    plan = inc.plan
    received = inc.received + (moved - inc.gains[who]) * inc.power[who, None]
    mine = plan.association[None, :] == who[:, None]
    served = np.where(mine, moved, inc.served)
    own = inc.unit[plan.association] * plan.levels
    return served, np.broadcast_to(own, served.shape), received


def edit_candidates(problem: FleetProblem, plan: FleetPlan, pairs: bool) -> list[Edits]:
    """The candidates one edit away: one user's level set to any other value, one user moved
    to another UAV (its level kept), and with ``pairs`` one level moved between two users."""
    N, K, L = problem.fleet.n, problem.fleet.k, problem.power_levels
    assoc, lev = plan.association, plan.levels
    k, level = np.repeat(np.arange(K), L), np.tile(np.arange(L), K)
    other = level != lev[k]
    k, level = k[other], level[other]
    users, to = np.nonzero(assoc[:, None] != np.arange(N)[None])
    singles = Edits(np.concatenate([k, users])[:, None], np.concatenate([assoc[k], to])[:, None],
                    np.concatenate([level, lev[users]])[:, None])
    if not pairs:
        return [singles]
    i, j = np.nonzero(~np.eye(K, dtype=bool))
    ok = (lev[i] > 0) & (lev[j] < L - 1)
    i, j = i[ok], j[ok]
    both = Edits(np.column_stack([i, j]), np.column_stack([assoc[i], assoc[j]]),
                 np.column_stack([lev[i] - 1, lev[j] + 1]))
    return [singles, both]


@functools.lru_cache(maxsize=16)
def move_offsets(step_m: float, steps: tuple[int, ...]) -> np.ndarray:
    """Every axis move of ``steps`` lattice steps ``(6 len(steps), 3)``, m (built once: the
    search asks every round)."""
    return (MOVES[:6, None, :] * np.array(steps)[None, :, None]).reshape(-1, 3) * step_m


def move_candidates(problem: FleetProblem, plan: FleetPlan, steps: tuple[int, ...]):
    """Each UAV moved by each of ``steps`` lattice steps along each axis, inside the box:
    which UAV ``(C,)`` and where ``(C, 3)``."""
    N, space = problem.fleet.n, problem.space
    moves = move_offsets(space.step_m, steps)
    who = np.repeat(np.arange(N), len(moves))
    where = (plan.positions[:, None, :] + moves[None]).reshape(-1, 3)
    keep = space.contains(where) & kept_apart(problem, plan.positions, who, where)
    return who[keep], where[keep]


def kept_apart(problem: FleetProblem, positions, who: np.ndarray, where: np.ndarray):
    """Whether moving UAV ``who[c]`` to ``where[c]`` keeps it apart from every other UAV of
    ``positions`` ``(C,)`` (all True without a separation)."""
    sep = problem.separation
    if sep is None:
        return np.ones(len(who), dtype=bool)
    ok = sep.apart(where[:, None, :], np.asarray(positions)[None])  # (C, N)
    ok[np.arange(len(who)), who] = True  # a UAV is not kept apart from itself
    return ok.all(axis=1)


def separate(problem: FleetProblem, plan: FleetPlan) -> FleetPlan:
    """The plan with its stations kept apart (``problem.separation``): each UAV in turn, if it
    is too near one before it, moves to the nearest lattice point apart from all of those
    (association and levels kept). The planner's search starts from here and only moves
    where the separation holds, so its answer keeps it too."""
    sep = problem.separation
    if sep is None or not sep.violations(plan.positions):
        return plan
    points = np.stack(np.meshgrid(*problem.space.axes(), indexing="ij"), -1).reshape(-1, 3)
    positions = plan.positions.copy()
    for n in range(1, len(positions)):
        if all(sep.apart(positions[n], positions[m]) for m in range(n)):
            continue
        ok = sep.apart(points[:, None, :], positions[None, :n]).all(axis=1)
        if not ok.any():
            raise ValueError(
                f"no station for UAV {n} is {sep.horizontal_m:.0f} m apart horizontally or "
                f"{sep.vertical_m:.0f} m in height from the others on this lattice"
            )
        d = np.linalg.norm(points[ok] - positions[n], axis=1)
        positions[n] = points[ok][int(np.argmin(d))]
    return make_plan(problem, positions, plan.association, plan.levels)


def local_search(
    problem: FleetProblem,
    plan: FleetPlan,
    steps: tuple[int, ...] = PLANNER_STEPS,
    pairs: bool = False,
    max_rounds: int = 500,
    cache: GainCache | None = None,
) -> FleetPlan:
    """Best-improvement local search on the fleet objective over one UAV's move, one user's
    level, one user's UAV (and with ``pairs`` one level moved between two users). Candidates
    are scored from the incumbent's received powers (``Incumbent``, ``scores``); the answer's
    objective is recomputed from the channel and returned only if it beats the start."""
    cache = GainCache(problem) if cache is None else cache
    gains = problem.fleet.gains(plan.positions)
    current = plan
    for _ in range(max_rounds):
        inc = Incumbent.of(problem, current, gains)
        groups = edit_candidates(problem, current, pairs)
        who, where = move_candidates(problem, current, steps)
        moved = cache(where)
        terms = [edit_terms(problem, inc, e) for e in groups] + [move_terms(inc, who, moved)]
        values = scores(problem, *(np.concatenate(t) for t in zip(*terms, strict=True)))
        i = int(np.argmax(values))
        if not values[i] > current.objective * IMPROVES:
            break
        value, positions = float(values[i]), current.positions
        association, levels = current.association, current.levels
        for edits in groups:
            if i < len(edits):
                association, levels = edits.applied(current, i)
                break
            i -= len(edits)
        else:
            n, positions, gains = who[i], positions.copy(), gains.copy()
            positions[n], gains[n] = where[i], moved[i]
        # the scored value stands in for the objective until the end (same SINR, summed in
        # another order: equal to rounding, far below IMPROVES)
        current = FleetPlan(positions, association, levels, levels, value)
    if current is plan:
        return plan
    final = make_plan(problem, current.positions, current.association, current.levels)
    return final if final.objective > plan.objective * IMPROVES else plan


def block_power(problem: FleetProblem, plan: FleetPlan, max_users: int) -> FleetPlan:
    """Each UAV with at most ``max_users`` users in turn gets the best levels for its users,
    the other UAVs fixed (``grid.optimal_levels`` on its one-UAV channel), among those that
    leave no more of its users below QoS than now (each more one halves the objective; the DP's
    work is proportional to the failure counts it keeps, so this is 5-10x cheaper than all of
    them); kept where the fleet objective improves."""
    fleet, L = problem.fleet, problem.power_levels
    gains = fleet.gains(plan.positions)
    for n in range(fleet.n):
        mine = plan.association == n
        if not 0 < mine.sum() <= max_users:
            continue
        own = fleet.uav_channel(n, gains, plan.association, plan.power_w)
        g = own.mean_gain(plan.positions[n])
        failing = int((own.rate(g, plan.power_w[mine]) < own.qos_rate_bps).sum())
        levels, _ = optimal_levels(own, g, L, cap=failing + 1)
        trial = plan.levels.copy()
        trial[mine] = levels
        candidate = make_plan(problem, plan.positions, plan.association, trial, gains)
        if candidate.objective > plan.objective * IMPROVES:
            plan = candidate
    return plan


# --------------------------------------------------------------------------- the planner
def snap(space: SearchSpace, positions: np.ndarray) -> np.ndarray:
    """The nearest lattice points ``(N, 3)``."""
    return np.column_stack(
        [ax[np.abs(ax[None, :] - positions[:, i : i + 1]).argmin(axis=1)]
         for i, ax in enumerate(space.axes())]
    )


def coarse_lattice(space: SearchSpace, every: int = COARSE_EVERY) -> np.ndarray:
    """Every ``every``-th lattice point per axis ``(M, 3)``: where ``relocate`` looks."""
    axes = [ax[::every] for ax in space.axes()]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def relocate(problem: FleetProblem, plan: FleetPlan, cache: GainCache) -> FleetPlan:
    """The move the local search cannot make: one UAV jumps anywhere on a coarse lattice
    (associations and levels kept, the others fixed), the best such jump over all UAVs,
    then the local search from there; repeated while it improves the fleet."""
    points = coarse_lattice(problem.space)
    table = cache(points)
    N = problem.fleet.n
    for _ in range(RELOCATIONS):
        inc = Incumbent.of(problem, plan, problem.fleet.gains(plan.positions))
        who = np.repeat(np.arange(N), len(points))
        values = move_scores(problem, inc, who, np.tile(table, (N, 1)))
        values[~kept_apart(problem, plan.positions, who, np.tile(points, (N, 1)))] = -np.inf
        i = int(np.argmax(values))
        if not values[i] > plan.objective * IMPROVES:
            break
        positions = plan.positions.copy()
        positions[who[i]] = points[i % len(points)]
        jumped = make_plan(problem, positions, plan.association, plan.levels)
        if not jumped.objective > plan.objective * IMPROVES:
            break
        plan = descend(problem, jumped, cache)
    return plan


def descend(problem: FleetProblem, plan: FleetPlan, cache: GainCache) -> FleetPlan:
    """The local search and, in the shared band, the exact per-UAV power (where the local
    search's one-level moves stall) and the local search again while that improves."""
    plan = local_search(problem, plan, cache=cache)
    if problem.fleet.channel.access != "shared":
        return plan
    for _ in range(POWER_ROUNDS):
        polished = block_power(problem, plan, EXACT_POWER_K)
        if polished is plan:
            break
        plan = local_search(problem, polished, cache=cache)
    return plan


def plan_fleet(problem: FleetProblem, starts: int | None = None) -> FleetPlan:
    """The fleet planner (module docstring): the descent (local search, exact per-UAV power in
    the shared band) from each start ``chosen_starts`` keeps (or from every one of ``starts``
    k-means seeds), the best of them, then the coarse relocations. With
    ``problem.separation`` every start is ``separate``d and every move keeps it: the
    answer's stations are apart."""
    cache = GainCache(problem)
    firsts = (chosen_starts(problem) if starts is None else
              [equal_power(problem, *s) for s in distinct_starts(problem, starts)])
    plans = [descend(problem, separate(problem, start), cache) for start in firsts]
    return relocate(problem, max(plans, key=lambda p: p.objective), cache)


Start = tuple[np.ndarray, np.ndarray]  # a k-means baseline's positions (N, 3) and association


def distinct_starts(problem: FleetProblem, seeds: int) -> list[Start]:
    """The positions and association of the k-means baselines of seeds ``0..seeds-1``, one
    per distinct partition of the users (a seed whose clusters an earlier seed found starts
    the same descent, its UAVs numbered otherwise), found before the heights are searched."""
    firsts: dict[frozenset, Start] = {}
    for seed in range(seeds):
        labels, centres = kmeans(problem.fleet.channel.users[:, :2], problem.fleet.n, seed)
        if partition(labels) not in firsts:
            firsts[partition(labels)] = (kmeans_positions(problem, labels, centres), labels)
    return list(firsts.values())


def chosen_starts(problem: FleetProblem) -> list[FleetPlan]:
    """The starts the planner descends from (k-means baselines). OFDMA, and small fleets in
    the shared band: every distinct one of ``planner_starts`` seeds. Larger fleets in the
    shared band: the descents of different partitions end a factor 2-30 apart (each user
    below QoS halves the objective) and a descent costs 30-80 ms, so ``SCREENED_STARTS`` seeds
    are screened by ``qos_shortfall`` (under 1 ms each) and only the 2 with the fewest users
    that cannot meet QoS are descended (ties in seed order); where N K > ``LARGE_FLEET`` only
    those tied at the fewest (at most 2). docs/service/fleet.md, round four."""
    fleet = problem.fleet
    if fleet.channel.access != "shared" or fleet.n * fleet.k <= SMALL_FLEET:
        return [equal_power(problem, *s) for s in distinct_starts(problem, planner_starts(problem))]
    screened = sorted(((qos_shortfall(problem, *s), i), s) for i, s in
                      enumerate(distinct_starts(problem, SCREENED_STARTS)))
    fewest = screened[0][0][0]
    return [equal_power(problem, *s) for (short, _), s in screened[:PLANNER_STARTS]
            if fleet.n * fleet.k <= LARGE_FLEET or short == fewest]


def qos_shortfall(problem: FleetProblem, positions: np.ndarray, association: np.ndarray) -> int:
    """How many users UAVs at ``positions`` with this association leave below QoS however
    each UAV splits its power (shared band, power continuous). With every UAV at its full
    budget ``P_n``, user k of UAV n meets QoS (SINR ``gamma_q = 2^(qos / B) - 1``) exactly when
    its share of the budget is at least ``s_k = gamma_q / (1 + gamma_q) (1 + (I_k + sigma^2) /
    (g_k P_n))`` (``I_k`` the other UAVs' power at k); the most users a UAV can hold are its
    smallest shares that sum to at most 1, the rest fall short. A screen of a start's
    partition, not the descent's outcome: levels are discrete and the descent moves the UAVs."""
    fleet, c = problem.fleet, problem.fleet.channel
    gains = fleet.gains(positions)
    full = fleet.p_max_w
    gamma = 2.0 ** (c.qos_rate_bps / fleet.user_bandwidth_hz()) - 1.0
    served = gains[association, np.arange(fleet.k)] * full[association]
    others = full @ gains - served
    share = gamma / (1.0 + gamma) * (1.0 + (others + c.noise_w) / served)
    short = 0
    for n in range(fleet.n):
        mine = np.sort(share[association == n])
        short += len(mine) - int(np.searchsorted(np.cumsum(mine), 1.0, side="right"))
    return short


def planner_starts(problem: FleetProblem) -> int:
    """How many k-means seeds the planner descends from where it does not screen them
    (``chosen_starts``): in the shared band the descents of different partitions end in
    optima a factor 2 apart (each more user below QoS halves the objective), and the best
    partition is often not the first seeds' (N = 3, K = 10: the 5th seed's); small fleets
    try more, where a descent costs a few ms."""
    return SMALL_STARTS if problem.fleet.n * problem.fleet.k <= SMALL_FLEET else PLANNER_STARTS


def partition(association: np.ndarray) -> frozenset[tuple[int, ...]]:
    """The users each UAV serves, whatever the UAVs' numbering."""
    n = int(association.max()) + 1
    return frozenset(tuple(np.flatnonzero(association == i)) for i in range(n))


# --------------------------------------------------------------------------- the reference
def grid_block(problem: FleetProblem, plan: FleetPlan, n: int) -> FleetPlan:
    """UAV ``n`` re-placed by the exact one-UAV grid for its users with the others fixed
    (their power at its users folded into its users' gains); kept where the fleet improves."""
    mine = plan.association == n
    if not mine.any() or dp_cost(int(mine.sum()), problem.power_levels) > MAX_DP_COST:
        return plan
    fleet = problem.fleet
    own = fleet.uav_channel(n, fleet.gains(plan.positions), plan.association, plan.power_w)
    best = solve_grid(own, problem.space, problem.power_levels, hint=plan.positions[n])
    positions, levels = plan.positions.copy(), plan.levels.copy()
    positions[n], levels[mine] = best.position, best.levels
    candidate = make_plan(problem, positions, plan.association, levels)
    return candidate if candidate.objective > plan.objective * IMPROVES else plan


def block_ascent(problem: FleetProblem, plan: FleetPlan, max_rounds: int = 20) -> FleetPlan:
    """Block-coordinate ascent: every UAV by the exact grid, then the wide local search,
    until a round improves nothing."""
    for _ in range(max_rounds):
        before = plan.objective
        for n in range(problem.fleet.n):
            plan = grid_block(problem, plan, n)
        plan = local_search(problem, plan, REFERENCE_STEPS, pairs=True)
        if plan.objective <= before * IMPROVES:
            break
    return plan


def fleet_count(problem: FleetProblem) -> int:
    """How many fleets (lattice positions per UAV, associations, levels) there are."""
    points = int(np.prod([len(a) for a in problem.space.axes()]))
    fleet = problem.fleet
    return points**fleet.n * fleet.n**fleet.k * problem.power_levels**fleet.k


def exhaustive(problem: FleetProblem) -> FleetPlan:
    """The exact optimum by enumerating every fleet (tiny problems only)."""
    fleet, L = problem.fleet, problem.power_levels
    points = np.stack(np.meshgrid(*problem.space.axes(), indexing="ij"), -1).reshape(-1, 3)
    choices = np.array(list(itertools.product(range(fleet.n), range(L), repeat=fleet.k)))
    assoc, levels = choices[:, 0::2], choices[:, 1::2]
    power = fleet.power(levels, assoc, L)
    best: FleetPlan | None = None
    for combo in itertools.product(range(len(points)), repeat=fleet.n):
        g = fleet.gains(points[list(combo)])
        values = fleet.evaluate_gains(g[None], assoc, power).objective
        i = int(np.argmax(values))
        if best is None or values[i] > best.objective:
            best = make_plan(problem, points[list(combo)], assoc[i], levels[i])
    assert best is not None
    return best


def reference_fleet(
    problem: FleetProblem, starts: int = REFERENCE_STARTS, hint: FleetPlan | None = None
) -> FleetPlan:
    """The reference (module docstring): exact if tiny, else the best block-coordinate ascent
    from the planner's answer (or ``hint``) and ``starts`` k-means starts."""
    if fleet_count(problem) <= EXHAUSTIVE_LIMIT:
        return exhaustive(problem)
    first = plan_fleet(problem) if hint is None else hint
    best = block_ascent(problem, first)
    for seed in range(1, starts + 1):
        plan = block_ascent(problem, local_search(problem, kmeans_baseline(problem, seed)))
        if plan.objective > best.objective:
            best = plan
    return best


# --------------------------------------------------------------------------- the upper bound
def best_gains(problem: FleetProblem, chunk: int = 4096) -> np.ndarray:
    """Each user's highest gain ``(K,)`` from any lattice point (every point of the lattice,
    in chunks: no assumption on how the gain varies with position)."""
    points = np.stack(np.meshgrid(*problem.space.axes(), indexing="ij"), -1).reshape(-1, 3)
    best = np.zeros(problem.fleet.k)
    for i in range(0, len(points), chunk):
        best = np.maximum(best, problem.fleet.channel.mean_gain(points[i : i + chunk]).max(0))
    return best


def upper_bound(problem: FleetProblem) -> float:
    """A certified upper bound on the objective of every fleet (docs/service/fleet.md, "Upper
    bound"). OFDMA: every user served from its best lattice point, the N budgets pooled and
    split continuously by water-filling, nobody below QoS: each fleet is one of the
    allocations this maximises over (its user's gain is at most the best, its powers split at
    most the pooled budget, and failures only halve), so none beats it. Shared band: no
    bound is built (the other UAVs' interference and the association do not relax to a
    tractable problem that is still tight), ``inf``."""
    c = problem.fleet.channel
    if c.access != "ofdma":
        return math.inf
    pooled = replace(c, p_max_w=float(problem.fleet.p_max_w.sum()))
    return float(rate_ceiling(pooled, best_gains(problem)[None])[0])


# The fleet's planners by name (the one-UAV planners of ``service.stage.PLANNERS`` place one
# UAV; these place N).
FLEET_PLANNERS = {"fleet": plan_fleet, "kmeans": kmeans_baseline, "reference": reference_fleet}
