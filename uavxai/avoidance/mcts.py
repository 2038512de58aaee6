"""Monte Carlo tree search for collision avoidance (the paper's Tree-depth, eqs 12-14).

:func:`search` (compiled: :mod:`uavxai.avoidance.kernel`) is the algorithm: it takes the
encounter model as an argument and returns the whole tree as data (:class:`SearchTree`), so
that explanation, drawing and testing read the same arrays the search decided from.
:class:`MCTSPlanner` wraps it in the planner API (README, "Using the planner in another
simulator"): it predicts the intruders once per decision, searches, takes the most visited root
action (with ``backup: best``, the one with the best Q) and explains it.

One simulation walks from the root down to the search depth (or to a terminal state): at
every node it takes the child with the best UCT score ``Q + 2C sqrt(2 ln n / n_j)``, children
never visited first, ties broken at random. ``Q`` is min-max normalised over the siblings
before it enters the score (as in mctx): the leaf values ``1 - d/d_max`` of neighbouring actions
differ by about 1 %, and against the paper's exploration term raw values would leave the
visits uniform, the choice arbitrary and the confidence meaningless. A node met for the
first time is expanded: its children (one per action of the set: the paper's 9, or 11 with
climb and descend) are computed at once, vectorised, and kept (child
states are deterministic, so every later simulation reuses them). The value at the end of
the walk is 1 for the goal, 0 for a collision or leaving the map, 0.1 for a time-out and
``1 - d(o, g) / d_max`` otherwise (eqs 13/14); it is backed up along the walk: a node's ``Q``
is the mean of its walks' values (the paper), or with ``PlannerConfig.backup`` "best" the best
value a walk through it scored (the model is deterministic: a node is worth its best line, as
in the exhaustive search, :mod:`uavxai.avoidance.exhaustive`); then the root action taken is
the one with the best ``Q`` (ties: more visits, then action order), and as in the exhaustive
search a goal one tree level later costs a little (:func:`uavxai.avoidance.kernel.goal_delay`).
Issue 31 measured why: a mean values an action by its random continuations, most of which
collide among traffic or fly off slower, so the search prefers slowing down and arrives in
1.7x the exhaustive search's steps (docs/results, "MCTS episodes as short as exhaustive
search's"). Beyond the
paper, a collision predicted ``t`` seconds ahead is worth ``late_collision_value * t /
horizon`` (below 0.1): when every line meets someone (likely among manoeuvring traffic with
its protected zones grown, see :mod:`uavxai.avoidance.model`) the search still prefers the
line that meets them latest, which re-planning can turn into a miss; with 0 every collision
is worth 0 as in the paper. Each tree level holds its action for ``action_hold_s``.
Intruders are predicted as ``PlannerConfig.intruder_model`` says (:func:`predict_levels`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from uavxai.avoidance.kernel import pinned_by, search, wall_share  # the MCTS loop, compiled
from uavxai.avoidance.lines import cornered_choice, measured_children
from uavxai.avoidance.model import (
    COLLISION,
    NONE,
    OUTCOME_NAMES,
    TERMINAL_VALUE,
    TIMEOUT,
    Children,
    EncounterModel,
    Track,
    accel_command,
    bank_command,
    intruder_margin,
    ownship_air,
    ownship_state,
    place_children,
    track_sigma,
    vertical_command,
    vertical_margin,
)
from uavxai.avoidance.types import (
    ChildStats,
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
    SearchTree,
    check_plan_inputs,
)
from uavxai.geometry import turn_rate_of_bank
from uavxai.vocabulary import Outcome

_VALUE_OF = np.array(TERMINAL_VALUE)


def chosen_action(tree: SearchTree) -> int:
    """The root action the search ranks first (:meth:`SearchTree.best_child`): the most
    visited (ties: higher Q, then lower index), or with the best-value backup the best Q."""
    child = tree.best_child(0)
    if child is None:
        raise ValueError("the search visited no root action (simulations must be >= 1)")
    return int(tree.action[child])


class TreePlanner:
    """What the tree planners share (the planner API): predict the intruders once per decision,
    search, take the chosen root action and explain it. Subclasses give the search."""

    sampled = True  # visits count simulations (MCTS), not one per node (exhaustive)

    def __init__(self, config: PlannerConfig | None = None, *, name: str) -> None:
        self.config = config or PlannerConfig()
        self.name = name
        self.model = EncounterModel(self.config)

    def reset(self, seed: int) -> None:
        """Nothing random to re-seed."""

    def search(
        self, root: np.ndarray, goal: np.ndarray, tracks: list[Track], time_left_s: float
    ) -> SearchTree:
        raise NotImplementedError

    def plan(
        self,
        own: Ownship,
        intruders: Sequence[Intruder],
        goal: Goal,
        *,
        step: int = 0,
        keep: int | None = None,
    ) -> Decision:
        """The planner API's decision. ``keep``: an action taken whenever its line has no
        conflict, whatever the search prefers (the alerting stage's route, `alerting.py`)."""
        t_start = time.perf_counter()
        check_plan_inputs(own, intruders, goal)
        cfg, model = self.config, self.model
        goal_xyz = np.asarray(goal, dtype=float)
        model.carry_ownship(ownship_air(own, cfg))  # before predicting: it sets their index
        model.hold_speed_band(own.speed_band)
        tracks = predict_levels(model, intruders, cfg.depth, cfg.action_hold_s)
        time_left_s = (cfg.max_steps - step) * cfg.decision_period_s
        root = ownship_state(own)
        tree = self.search(root, goal_xyz, tracks, time_left_s)
        decision = decision_from_tree(
            tree,
            chosen_action(tree),
            own,
            intruders,
            goal_xyz,
            tracks,
            model,
            name=self.name,
            sampled=self.sampled,
            route_action=keep,
        )
        decision.ms = 1000.0 * (time.perf_counter() - t_start)
        return decision


class MCTSPlanner(TreePlanner):
    """The MCTS avoidance planner. Same seed, same inputs: same decision."""

    def __init__(self, config: PlannerConfig | None = None, *, name: str = "mcts") -> None:
        super().__init__(config, name=name)
        self._rng = np.random.default_rng(self.config.seed)
        self._scratch: dict = {}  # the kernel's tree arrays, reused (kernel.search)

    def reset(self, seed: int) -> None:
        super().reset(seed)
        self._rng = np.random.default_rng(seed)

    def search(
        self, root: np.ndarray, goal: np.ndarray, tracks: list[Track], time_left_s: float
    ) -> SearchTree:
        cfg = self.config
        return search(
            self.model,
            root,
            goal,
            tracks,
            simulations=cfg.simulations,
            c=cfg.c,
            hold_s=cfg.action_hold_s,
            rng=self._rng,
            time_left_s=time_left_s,
            scratch=self._scratch,
        )


def intruder_arrays(intruders: Sequence[Intruder]) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) positions and velocities of the planner-API intruders."""
    if not intruders:
        return np.zeros((0, 3)), np.zeros((0, 3))
    a = np.array([(i.x, i.y, i.h, i.vx, i.vy, i.vh) for i in intruders], dtype=float)
    return a[:, :3], a[:, 3:]


def intruder_bank_limits(intruders: Sequence[Intruder], config: PlannerConfig) -> np.ndarray:
    """(N,) the bank limit (rad) each intruder may turn at: its own (issue 31: its
    aircraft's, by the ADS-B emitter category its track carries), or the planner's
    ``intruder_bank_limit_deg`` where it has none."""
    default = config.intruder_bank_limit_deg
    deg = [default if i.bank_limit_deg is None else i.bank_limit_deg for i in intruders]
    return np.radians(np.array(deg, dtype=float))


def intruder_turn_rates(intruders: Sequence[Intruder], config: PlannerConfig) -> np.ndarray | None:
    """(N,) turn rates the planner predicts with: the intruders' estimates (within what
    each one's bank limit allows, :func:`intruder_bank_limits`), or None (straight) for the
    constant-velocity model."""
    if config.intruder_model == "cv" or not intruders:
        return None
    rate = np.array([i.turn_rate for i in intruders], dtype=float)
    speed = np.maximum(np.hypot([i.vx for i in intruders], [i.vy for i in intruders]), 1.0)
    # a noisy estimate must not predict a turn tighter than a coordinated turn can be
    limit = turn_rate_of_bank(intruder_bank_limits(intruders, config), speed)
    return np.clip(rate, -limit, limit)


def predict_levels(
    model: EncounterModel, intruders: Sequence[Intruder], depth: int, hold_s: float
) -> list[Track]:
    """The intruders' tracks for each tree level, computed once per decision: constant
    velocity or a constant turn (``intruder_model``), with the margin that their possible
    manoeuvres and track uncertainty add to ``d_min`` (:func:`intruder_margin`)."""
    cfg = model.config
    pos, vel = intruder_arrays(intruders)
    turn = intruder_turn_rates(intruders, cfg)
    margin = with_keep(intruder_margin(
        cfg, vel, np.zeros(len(intruders)) if turn is None else turn, *_track_errors(intruders),
        bank_limit_rad=intruder_bank_limits(intruders, cfg),
    ), intruders)  # fmt: skip
    sigma = None
    if cfg.risk == "probability":  # the track error as a chance, not a wall (avoidance.risk)
        sigma = track_sigma(cfg, len(intruders), *_track_errors(intruders))
    starts = [d * hold_s for d in range(depth)]
    tracks = model.predict_levels(
        pos, vel, hold_s, starts, turn_rate=turn, margin=margin, sigma=sigma
    )
    vertical = vertical_margin(cfg, *_vertical_errors(intruders))
    if vertical is None or margin is None:  # before the keep: with_keep makes a margin of none
        return tracks
    vertical = with_keep(vertical, intruders)
    # the vertical margin at each level's sub-step instants, as the horizontal one was taken
    n = model.substeps(hold_s)
    t = np.array(starts, dtype=float)[:, None] + (hold_s / n) * np.arange(n + 1)
    d = cfg.d_min_m
    return [
        dataclasses.replace(
            tr, vscale=(d + tr.margin) / (d + np.minimum(v, tr.margin))
        ) if tr.margin is not None else tr
        for tr, v in zip(tracks, vertical(t), strict=True)
    ]


def _vertical_errors(intruders: Sequence[Intruder]) -> tuple[np.ndarray, np.ndarray]:
    """(N,) vertical position and (N,) vertical velocity 1-sigma errors of the tracks (the
    horizontal ones where a track does not know its own: never a smaller margin unknowingly)."""
    return (
        np.array([i.sigma_m if i.sigma_h_m is None else i.sigma_h_m for i in intruders]),
        np.array([i.sigma_v if i.sigma_vh is None else i.sigma_vh for i in intruders]),
    )


def with_keep(
    margin: Callable[[np.ndarray], np.ndarray] | None, intruders: Sequence[Intruder]
) -> Callable[[np.ndarray], np.ndarray] | None:
    """``margin`` with each track's ``keep_m`` (a fleet member's clearance) added at every
    instant; ``margin`` itself when every ``keep_m`` is 0 (traffic alone: nothing changes)."""
    keep = np.array([i.keep_m for i in intruders], dtype=float)
    if not keep.any():
        return margin
    if margin is None:
        return lambda t: np.broadcast_to(keep, (*np.shape(t), keep.size)).copy()
    return lambda t: margin(t) + keep


def _track_errors(intruders: Sequence[Intruder]) -> tuple[np.ndarray, np.ndarray]:
    """(N,) position and (N,) velocity 1-sigma errors of the intruders' tracks."""
    return np.array([i.sigma_m for i in intruders]), np.array([i.sigma_v for i in intruders])


def decision_from_tree(
    tree: SearchTree,
    action: int,
    own: Ownship,
    intruders: Sequence[Intruder],
    goal: np.ndarray,
    tracks: Sequence[Track],
    model: EncounterModel,
    *,
    name: str,
    sampled: bool = True,
    route_action: int | None = None,
) -> Decision:
    """Everything a tree says about a decision: per-root-action stats, plan, explanation.
    The action taken: :func:`_final_action` (``route_action``: the route's, or None).

    The best line under every root action is re-flown exactly against every intruder (the
    search itself may skip far ones), and those numbers are written back into the tree.
    Shared by the tree planners; ``sampled``: visits count simulations (MCTS), so the share
    of each action's simulations that collided is reported too.
    """
    cfg = model.config
    ids = [i.id for i in intruders]
    root_children = tree.children_of(0)
    lines = {int(tree.action[ch]): tree.best_line(int(ch)) for ch in root_children}
    samples, t_events = _remeasure(
        model, tree, [n for line in lines.values() for n in line], goal, tracks
    )
    children = _root_stats(tree, lines, own, model, goal, sampled, tracks, ids)
    children, horizons = measured_children(
        children, lines, tree, samples, t_events, tracks, ids, own, cfg
    )
    action, cornered, route_kept = _final_action(
        children, action, route_action, tree.by_value, cfg.cornered_rule, cfg.d_min_m
    )

    chosen_line = lines[action]
    plan = [np.array([[own.x, own.y, own.h]])]
    for node in chosen_line:
        plan.append(samples[node][1:])
        if tree.terminal[node] != NONE:
            break

    # The trust figure: the chosen action held for one decision period, against every
    # intruder, exactly; the dynamics then fly that period before the next decision.
    period = cfg.decision_period_s
    pos, vel = intruder_arrays(intruders)
    next_seg = model.fly(
        ownship_state(own)[None],
        np.array([action]),
        goal,
        period,
        model.predict(
            pos, vel, period, index=False, turn_rate=intruder_turn_rates(intruders, cfg)
        ),
        cull=False,
        exact=True,
    )
    visits_root = int(tree.visits[0])
    chosen = next(ch for ch in children if ch.action == action)
    return Decision(
        bank_cmd_rad=float(bank_command(own.bank, action, cfg)),
        accel_mps2=float(accel_command(action, cfg)),
        alt_target_m=height_command(model, action, own, goal),
        action=action,
        children=children,
        tree=tree,
        plan=np.concatenate(plan),
        predicted_min_separation_m=float(next_seg.min_sep[0]),
        confidence=chosen.visits / visits_root if visits_root else 0.0,
        branch_min_separation_m=chosen.predicted_min_separation_m,
        branch_horizon_s=horizons[action],
        cornered=cornered,
        route_kept=route_kept,
        planner=name,
        by_value=tree.by_value,
        d_min_m=cfg.d_min_m,
        cornered_rule=cfg.cornered_rule,
    )


def _final_action(
    children: Sequence[ChildStats],
    action: int,
    route_action: int | None,
    by_value: bool = False,
    rule: str = "latest",
    d_min_m: float = math.nan,
) -> tuple[int, bool, bool]:
    """The action taken, and whether the cornered rule or the route rule (rather than the
    search) chose it: every option conflicts, the rule words can state
    (:func:`cornered_choice`); else the route's when its line has no conflict
    (``route_action`` given; :attr:`ChildStats.clear`: no meeting, and no NMAC intrusion where
    the search grades one); else the search's ``action``. ``by_value``: the search ranks
    by Q first (:func:`uavxai.avoidance.lines.search_key`); ``rule``: the cornered rule
    (`avoidance.mcts.cornered_rule`), ``d_min_m`` the collision distance it may weigh."""
    cornered = cornered_choice(children, by_value, rule, d_min_m)
    if cornered is not None:
        return cornered.action, True, False
    if route_action is not None:
        kept = next((c for c in children if c.action == route_action), None)
        # a route line that leaves the area is no route to keep (the episode ends there)
        if kept is not None and kept.clear and kept.outcome != Outcome.OUT_OF_BOUNDS:
            return route_action, False, route_action != action
    return action, False, False


def height_command(
    model: EncounterModel, action: int, own: Ownship, goal: np.ndarray
) -> float | None:
    """The height target ``action`` gives the autopilot with the vertical set (None with the
    paper's nine: the leg's height, unchanged)."""
    if not model.vertical:
        return None
    vertical = int(vertical_command(own.vertical, action))
    return float(model.config.height_target(vertical, float(goal[2])))


def collision_shares(tree: SearchTree) -> np.ndarray:
    """(K,) share of each root action's visits that ended in a collision."""
    hit = np.flatnonzero((tree.terminal == COLLISION) & (tree.visits > 0))
    top = hit.copy()
    for _ in range(int(tree.depth.max(initial=0))):  # climb to the depth-1 ancestor
        top = np.where(tree.depth[top] > 1, tree.parent[top], top)
    k = tree.branching
    collided = np.bincount(tree.action[top], weights=tree.visits[hit], minlength=k)
    kids = tree.children_of(0)
    visits = np.zeros(k)
    visits[tree.action[kids]] = tree.visits[kids]
    return np.divide(collided, visits, out=np.zeros(k), where=visits > 0)


def _remeasure(
    model: EncounterModel,
    tree: SearchTree,
    nodes: list[int],
    goal: np.ndarray,
    tracks: Sequence[Track],
) -> tuple[dict[int, np.ndarray], dict[int, float]]:
    """Re-fly the edges into ``nodes`` exactly, against every intruder, in one batch.

    Updates the tree's min_sep, closest and t_closest of those nodes; returns each node's
    (n+1, 3) sub-step positions and the time of its event's sub-step within the edge (nan:
    none).
    """
    assert tree.state is not None and tree.t_closest is not None
    hold = model.config.action_hold_s
    group = np.array(nodes, dtype=int)
    level = tree.depth[group] - 1
    seg = model.fly_levels(
        tree.state[tree.parent[group]], tree.action[group], level, goal, hold, tracks
    )
    tree.min_sep[group] = seg.min_sep
    tree.closest[group] = seg.closest
    tree.t_closest[group] = seg.t_closest + level * hold
    nodes = group.tolist()
    return dict(zip(nodes, seg.samples, strict=True)), dict(
        zip(nodes, seg.t_event.tolist(), strict=True)
    )


def _root_stats(
    tree: SearchTree,
    lines: dict[int, list[int]],
    own: Ownship,
    model: EncounterModel,
    goal: np.ndarray,
    sampled: bool,
    tracks: Sequence[Track],
    ids: Sequence[int | str],
) -> list[ChildStats]:
    """:func:`_child_stats` of every root action's best line, with the share of its
    simulations that collided (``sampled``: MCTS) and the tracks pinning its end."""
    shares, q = (collision_shares(tree) if sampled else None), tree.q
    pinned = _pinned_ends(model, tree, lines, tracks, ids)
    return [
        _child_stats(tree, q, a, line, own, model, goal, None if shares is None else shares[a],
                     pinned[a])  # fmt: skip
        for a, line in lines.items()
    ]


def _child_stats(
    tree: SearchTree,
    q: np.ndarray,
    action: int,
    line: list[int],
    own: Ownship,
    model: EncounterModel,
    goal: np.ndarray,
    collision_share: float | None,
    pinned: tuple[tuple[int | str, float], ...] = (),
) -> ChildStats:
    """What the tree says of one root action (``q``: the tree's); the separations along its
    line are left unknown here: :func:`measured_children` measures them exactly."""
    cfg = model.config
    end = line[-1]
    code = int(tree.terminal[end])
    return ChildStats(
        action=action,
        bank_cmd_rad=float(bank_command(own.bank, action, cfg)),
        accel_mps2=float(accel_command(action, cfg)),
        alt_target_m=height_command(model, action, own, goal),
        visits=int(tree.visits[line[0]]),
        q=float(q[line[0]]),
        predicted_min_separation_m=math.inf,
        closest_intruder=None,
        outcome=OUTCOME_NAMES[code],
        collision_share=None if collision_share is None else float(collision_share),
        trapped=code in (NONE, COLLISION) and wall_share(model, tree.state[end]) == 0.0,
        nmac_depth=0.0 if tree.nmac_depth is None else float(tree.nmac_depth[end]),
        pinned=pinned,
    )


def _pinned_ends(
    model: EncounterModel,
    tree: SearchTree,
    lines: dict[int, list[int]],
    tracks: Sequence[Track],
    ids: Sequence[int | str],
) -> dict[int, tuple[tuple[int | str, float], ...]]:
    """Per root action, the tracks that pin its best line's end as the search weighed it
    (kernel.pin_share): only an open leaf the search scored (at the depth limit, visited)."""
    out: dict[int, tuple[tuple[int | str, float], ...]] = {a: () for a in lines}
    ends = {
        a: line[-1]
        for a, line in lines.items()
        if tree.terminal[line[-1]] == NONE
        and int(tree.depth[line[-1]]) == len(tracks)
        and tree.visits[line[-1]] > 0
    }
    if not ends:
        return out
    nodes = np.array(list(ends.values()), dtype=int)
    found = pinned_by(model, tree.state[nodes], tree.depth[nodes] - 1, tracks)
    for a, pins in zip(ends, found, strict=True):
        out[a] = tuple((ids[i], share) for i, share in pins)
    return out


class TreeBuilder:
    """A growing search tree over the encounter model (MCTS grows it, exhaustive fills it).

    Node 0 is the root; :meth:`expand` appends a node's K children (one per action of the
    set) as one block, so the children of a node are ``first_child[node] + action``. What the
    simulation loop touches one element at a time lives in Python lists, per node (cheap to
    index from Python); everything else is kept per block of K and assembled by
    :meth:`finish`. ``value`` holds
    what a walk ending at the node scores: its terminal value, or eq 13 for an open node at
    the depth limit, filled in by :meth:`leaf_value` when first needed (nan until then, and
    for open nodes above the limit, where no walk ends).
    """

    def __init__(self, model, root, goal, tracks, hold_s: float, time_left_s: float) -> None:
        self.model, self.tracks = model, tracks
        self.goal = tuple(np.asarray(goal, dtype=float).tolist())  # floats: cheap to index
        self.hold_s, self.time_left_s = hold_s, time_left_s
        self.depth_limit = len(tracks)
        self.k = k = int(model.actions.size)
        # Constant runs of K to extend the per-node lists with.
        self._open = [math.nan] * k  # open nodes: scored when a walk first ends there, or never
        self._zero, self._zero_f, self._no_child = [0] * k, [0.0] * k, [-1] * k
        self._true, self._false = [True] * k, [False] * k
        # per node
        self.visits = [0]
        self.value_sum = [0.0]
        self.first_child = [-1]
        self.is_leaf = [False]
        self.value = [math.nan]
        # per block of K children (block 0 is the root alone)
        self.block_parent = [-1]
        self.block_depth = [0]
        self.codes = [np.array([NONE], dtype=np.int8)]
        self.root = np.asarray(root, dtype=float).tolist()
        self.placed: list[Children] = []  # block b's children are placed by placed[b - 1]
        self.min_sep = [np.array([np.inf])]
        self.closest = [np.array([-1])]
        self.t_closest = [np.array([math.nan])]

    def expand(self, node: int) -> int:
        """Compute the K children of ``node``; returns the index of the first."""
        k = self.k
        block, row = ((node + k - 1) // k, (node - 1) % k) if node else (0, 0)
        d = self.block_depth[block]
        state = self.placed[block - 1].state(row) if node else self.root
        placed, seg = self.model.expand(state, self.goal, self.hold_s, self.tracks[d])
        code = seg.event
        if (d + 1) * self.hold_s >= self.time_left_s - 1e-9:
            code = np.where(code == NONE, TIMEOUT, code).astype(np.int8)
        at_limit = d + 1 == self.depth_limit
        codes = code.tolist()
        ended = any(codes)
        # Terminal children are scored now; open ones at the depth limit when a walk first
        # ends there (see leaf_value); open ones above it are never scored.
        if at_limit:
            self.value.extend(self._terminal_values(code, seg, d) if ended else self._open)
            self.is_leaf.extend(self._true)
        elif ended:
            self.value.extend(self._terminal_values(code, seg, d))
            self.is_leaf.extend([k != NONE for k in codes])
        else:
            self.value.extend(self._open)
            self.is_leaf.extend(self._false)
        first = len(self.visits)
        self.first_child[node] = first
        self.visits.extend(self._zero)
        self.value_sum.extend(self._zero_f)
        self.first_child.extend(self._no_child)
        self.block_parent.append(node)
        self.block_depth.append(d + 1)
        self.codes.append(code)
        self.placed.append(placed)
        self.min_sep.append(seg.min_sep)
        self.closest.append(seg.closest)
        self.t_closest.append(seg.t_closest)
        return first

    def _terminal_values(self, code: np.ndarray, seg, d: int) -> list[float]:
        """The values of the K children with terminal ``code`` (eq 14), a collision worth
        ``late_collision_value`` times how late in the horizon it comes."""
        values = _VALUE_OF[code]
        late = self.model.config.late_collision_value
        hit = code == COLLISION
        if late > 0 and hit.any():
            t = d * self.hold_s + np.nan_to_num(seg.t_event)
            values = np.where(hit, late * t / (self.depth_limit * self.hold_s), values)
        return values.tolist()

    def leaf_value(self, node: int) -> float:
        """Eq 13 at an open node: 1 - d(o, g) / d_max."""
        xyz = self.placed[(node - 1) // self.k].position((node - 1) % self.k)
        return 1.0 - math.dist(xyz, self.goal) / self.model.config.d_max

    def finish(self) -> SearchTree:
        blocks = len(self.block_parent) - 1
        states = np.concatenate([np.array([self.root]), place_children(self.placed)])
        k = self.k
        depth = np.concatenate([[0], np.repeat(self.block_depth[1:], k)]).astype(int)
        # Segment times count from the parent; the tree's from the decision.
        t_closest = np.concatenate(self.t_closest) + np.maximum(depth - 1, 0) * self.hold_s
        return SearchTree(
            parent=np.concatenate([[-1], np.repeat(self.block_parent[1:], k)]).astype(int),
            action=np.concatenate([[-1], np.tile(np.arange(k), blocks)]).astype(int),
            depth=depth,
            visits=np.array(self.visits),
            value_sum=np.array(self.value_sum),
            min_sep=np.concatenate(self.min_sep),
            closest=np.concatenate(self.closest),
            terminal=np.concatenate(self.codes),
            pos=states[:, :3].copy(),
            t_closest=t_closest,
            state=states,
            first_child=np.array(self.first_child),
            branching=k,
            time_left_s=self.time_left_s,
        )
