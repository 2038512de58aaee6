"""Monte Carlo tree search for collision avoidance (the paper's Tree-depth, eqs 12-14).

:func:`search` is the algorithm: it takes the encounter model as an argument and returns the
whole tree as data (:class:`SearchTree`), so that explanation, drawing and testing read the
same arrays the search decided from. :class:`MCTSPlanner` wraps it in the planner API of
SPEC §7: it predicts the intruders once per decision, searches, picks the most visited root
action and explains it.

One simulation walks from the root to the search depth (or to a terminal state): at every node
it takes the child with the best UCT score ``Q + 2C sqrt(2 ln n / n_j)``, children never
visited first, ties broken at random; a node met for the first time is expanded (its 9
children computed at once, vectorised). The value at the end of the walk is 1 for the goal,
0 for a collision or leaving the map, 0.1 for a time-out and ``1 - d(o, g) / d_max`` otherwise
(eqs 13/14); it is backed up along the walk. Each tree level holds its action for
``action_hold_s``. Child states are deterministic, so they are computed once, at expansion,
and reused by every later simulation.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from uavxai.avoidance.model import (
    NONE,
    OUTCOME_NAMES,
    TERMINAL_VALUE,
    TIMEOUT,
    EncounterModel,
    Track,
    accel_command,
    bank_command,
    ownship_state,
)
from uavxai.avoidance.types import (
    N_ACTIONS,
    ChildStats,
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
    SearchTree,
)

_VALUE_OF = np.array(TERMINAL_VALUE)


def search(
    model: EncounterModel,
    root: np.ndarray,
    goal: np.ndarray,
    tracks: Sequence[Track],
    *,
    simulations: int,
    c: float,
    hold_s: float,
    rng: np.random.Generator,
    time_left_s: float = math.inf,
) -> SearchTree:
    """Run MCTS from ``root`` (a model state row) and return the tree.

    ``tracks[d]`` holds the intruders during tree level ``d``, i.e. over
    ``[d * hold_s, (d + 1) * hold_s]`` from now; the search depth is ``len(tracks)``.
    ``time_left_s`` is when the episode times out: nodes reached later are time-outs.
    Node 0 is the root; the children of a node are 9 consecutive nodes in action order.
    """
    depth_limit = len(tracks)
    tree = _Builder(model, root, goal, tracks, hold_s, time_left_s)
    visits, value_sum, first_child = tree.visits, tree.value_sum, tree.first_child
    is_leaf, value = tree.is_leaf, tree.value
    explore = 2.0 * c * math.sqrt(2.0)  # 2C sqrt(2 ln n / n_j) = explore sqrt(ln n) / sqrt(n_j)
    draws = rng.random(simulations * depth_limit).tolist()  # tie-breaks, one per step
    draw = 0
    path = [0] * (depth_limit + 1)
    for _ in range(simulations):
        node, length = 0, 1
        while not is_leaf[node]:
            first = first_child[node]
            if first < 0:
                first = tree.expand(node)
            kids = visits[first : first + N_ACTIONS]
            if 0 in kids:
                best = [j for j in range(N_ACTIONS) if kids[j] == 0]
            else:
                e = explore * math.sqrt(math.log(visits[node]))
                scores = [
                    value_sum[first + j] / kids[j] + e / math.sqrt(kids[j])
                    for j in range(N_ACTIONS)
                ]
                top = max(scores)
                best = [j for j in range(N_ACTIONS) if scores[j] == top]
            pick = best[0] if len(best) == 1 else best[int(draws[draw] * len(best))]
            draw += 1
            node = first + pick
            path[length] = node
            length += 1
        v = value[node]
        for k in range(length):
            p = path[k]
            visits[p] += 1
            value_sum[p] += v
    return tree.finish()


def best_child(tree: SearchTree, node: int) -> int | None:
    """The most visited child of ``node`` (ties: higher Q, then lower action), or None."""
    kids = tree.children_of(node)
    kids = kids[tree.visits[kids] > 0]
    if kids.size == 0:
        return None
    q = tree.q[kids]
    order = np.lexsort((tree.action[kids], -q, -tree.visits[kids]))
    return int(kids[order[0]])


def best_line(tree: SearchTree, node: int) -> list[int]:
    """``node`` and the most visited path below it: what the search expects to follow."""
    line = [node]
    while (nxt := best_child(tree, line[-1])) is not None:
        line.append(nxt)
    return line


class MCTSPlanner:
    """The MCTS avoidance planner (SPEC §7). Same seed and inputs, same decision."""

    def __init__(self, config: PlannerConfig | None = None, *, name: str = "mcts") -> None:
        self.config = config or PlannerConfig()
        self.name = name
        self.model = EncounterModel(self.config)
        self._rng = np.random.default_rng(self.config.seed)

    def reset(self, seed: int) -> None:
        self._rng = np.random.default_rng(seed)

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        t_start = time.perf_counter()
        cfg, model = self.config, self.model
        root = ownship_state(own)
        goal_xyz = np.asarray(goal, dtype=float)
        pos, vel = intruder_arrays(intruders)
        hold = cfg.action_hold_s
        tracks = [model.predict(pos, vel, hold, t0=d * hold) for d in range(cfg.depth)]
        tree = search(
            model,
            root,
            goal_xyz,
            tracks,
            simulations=cfg.simulations,
            c=cfg.c,
            hold_s=hold,
            rng=self._rng,
            time_left_s=(cfg.max_steps - step) * cfg.decision_period_s,
        )
        root_child = best_child(tree, 0)
        assert root_child is not None  # simulations >= 1 visits a root child
        action = int(tree.action[root_child])
        decision = decision_from_tree(
            tree, action, own, intruders, goal_xyz, tracks, model, name=self.name
        )
        decision.ms = 1000.0 * (time.perf_counter() - t_start)
        return decision


def intruder_arrays(intruders: Sequence[Intruder]) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) positions and velocities of the planner-API intruders."""
    if not intruders:
        return np.zeros((0, 3)), np.zeros((0, 3))
    a = np.array([(i.x, i.y, i.h, i.vx, i.vy, i.vh) for i in intruders], dtype=float)
    return a[:, :3], a[:, 3:]


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
) -> Decision:
    """Everything a tree says about a decision: per-root-action stats, plan, explanation.

    Shared by the tree planners (MCTS and exhaustive).
    """
    from uavxai.xai.explain import explain  # xai reads planner types; import late, no cycle

    cfg = model.config
    ids = [i.id for i in intruders]
    root = ownship_state(own)
    children: list[ChildStats] = []
    chosen_line: list[int] = []
    for node in tree.children_of(0):
        a = int(tree.action[node])
        line = best_line(tree, int(node))
        if a == action:
            chosen_line = line
        children.append(_child_stats(tree, a, line, root, cfg, ids))

    # The trust figure: the chosen action held for one decision period, every intruder.
    period = cfg.decision_period_s
    pos, vel = intruder_arrays(intruders)
    next_seg = model.fly(
        root[None], np.array([action]), goal, period, model.predict(pos, vel, period), cull=False
    )
    branch_sep = float(np.min(tree.min_sep[chosen_line])) if chosen_line else math.inf
    visits_root = int(tree.visits[0])
    chosen = next(ch for ch in children if ch.action == action)
    decision = Decision(
        bank_cmd_rad=float(bank_command(own.bank, action, cfg)),
        accel_mps2=float(accel_command(action, cfg)),
        action=action,
        children=children,
        explanation="",
        tree=tree,
        plan=_plan_path(model, tree, chosen_line, goal, tracks, root),
        predicted_min_separation_m=float(next_seg.min_sep[0]),
        confidence=chosen.visits / visits_root if visits_root else 0.0,
        branch_min_separation_m=branch_sep,
        planner=name,
        d_min_m=cfg.d_min_m,
    )
    decision.explanation, decision.counterfactual = explain(decision)
    return decision


def _child_stats(
    tree: SearchTree,
    action: int,
    line: list[int],
    root: np.ndarray,
    cfg: PlannerConfig,
    ids: list,
) -> ChildStats:
    seps = tree.min_sep[line]
    k = int(np.argmin(seps))
    closest = int(tree.closest[line[k]])
    finite = bool(np.isfinite(seps[k]))
    t_closest = tree.t_closest[line[k]] if tree.t_closest is not None else math.nan
    return ChildStats(
        action=action,
        bank_cmd_rad=float(bank_command(root[6], action, cfg)),
        accel_mps2=float(accel_command(action, cfg)),
        visits=int(tree.visits[line[0]]),
        q=float(tree.q[line[0]]),
        predicted_min_separation_m=float(seps[k]),
        closest_intruder=ids[closest] if finite and closest >= 0 else None,
        time_to_closest_s=float(t_closest) if finite else None,
        outcome=OUTCOME_NAMES[int(tree.terminal[line[-1]])],
    )


def _plan_path(
    model: EncounterModel,
    tree: SearchTree,
    line: list[int],
    goal: np.ndarray,
    tracks: Sequence[Track],
    root: np.ndarray,
) -> np.ndarray:
    """(P, 3) sub-step positions along the chosen line, from now to its end."""
    points = [root[None, :3]]
    state = root
    for d, node in enumerate(line):
        seg = model.fly(
            state[None], tree.action[node : node + 1], goal, model.config.action_hold_s, tracks[d]
        )
        points.append(seg.samples[0, 1:])
        state = seg.end[0]
        if seg.event[0] != NONE:
            break
    return np.concatenate(points)


class _Builder:
    """The growing tree: hot statistics in Python lists (cheap to touch one element at a time
    from the simulation loop), per-child arrays appended a block of 9 at a time."""

    def __init__(self, model, root, goal, tracks, hold_s: float, time_left_s: float) -> None:
        self.model, self.goal, self.tracks = model, goal, tracks
        self.hold_s, self.time_left_s = hold_s, time_left_s
        self.depth_limit = len(tracks)
        self.parent = [-1]
        self.action = [-1]
        self.depth = [0]
        self.visits = [0]
        self.value_sum = [0.0]
        self.first_child = [-1]
        self.terminal = [NONE]
        self.is_leaf = [False]
        self.value = [math.nan]
        self.states = [root[None]]
        self.min_sep = [np.array([np.inf])]
        self.closest = [np.array([-1])]
        self.t_closest = [np.array([math.nan])]

    def expand(self, node: int) -> int:
        """Compute the 9 children of ``node``; returns the index of the first."""
        d = self.depth[node]
        state = self.states[(node + 8) // 9][(node - 1) % 9] if node else self.states[0][0]
        seg = self.model.fly_all_actions(state, self.goal, self.hold_s, self.tracks[d])
        code = seg.event
        if (d + 1) * self.hold_s >= self.time_left_s - 1e-9:
            code = np.where(code == NONE, TIMEOUT, code).astype(np.int8)
        leaf_depth = d + 1 == self.depth_limit
        value = _VALUE_OF[code]  # nan for open nodes: only leaves are ever evaluated
        if leaf_depth:
            value = np.where(code == NONE, self.model.leaf_value(seg.end, self.goal), value)
        first = len(self.parent)
        self.first_child[node] = first
        self.parent.extend([node] * N_ACTIONS)
        self.action.extend(range(N_ACTIONS))
        self.depth.extend([d + 1] * N_ACTIONS)
        self.visits.extend([0] * N_ACTIONS)
        self.value_sum.extend([0.0] * N_ACTIONS)
        self.first_child.extend([-1] * N_ACTIONS)
        codes = code.tolist()
        self.terminal.extend(codes)
        self.is_leaf.extend([leaf_depth or k != NONE for k in codes])
        self.value.extend(value.tolist())
        self.states.append(seg.end)
        self.min_sep.append(seg.min_sep)
        self.closest.append(seg.closest)
        self.t_closest.append(seg.t_closest + d * self.hold_s)
        return first

    def finish(self) -> SearchTree:
        states = np.concatenate(self.states)
        return SearchTree(
            parent=np.array(self.parent),
            action=np.array(self.action),
            depth=np.array(self.depth),
            visits=np.array(self.visits),
            value_sum=np.array(self.value_sum),
            min_sep=np.concatenate(self.min_sep),
            closest=np.concatenate(self.closest),
            terminal=np.array(self.terminal, dtype=np.int8),
            pos=states[:, :3].copy(),
            t_closest=np.concatenate(self.t_closest),
        )
