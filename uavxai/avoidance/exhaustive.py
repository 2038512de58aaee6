"""The `exhaustive` planner: every action sequence to the search depth (the optimality
reference for MCTS).

It builds the same tree MCTS samples, but whole: all ``9^depth`` sequences, each level held
``action_hold_s``, over the same encounter model, and scores each sequence as MCTS scores a
walk (1 goal, 0 collision or out of bounds, 0.1 time-out, ``1 - d/d_max`` at the depth
limit). Since the model is deterministic, the value of a node is the best value below it, and
the action taken is the root action with the best value; among lines that all reach the goal,
the one that reaches it sooner is preferred (:func:`uavxai.avoidance.kernel.goal_delay`). In
its :class:`SearchTree` every node is visited once and ``Q`` is that best value, so the
explanation code reads it like an MCTS tree (as MCTS's with ``backup: best``). Cost grows
as ``9^depth``; that is the point of the comparison.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from uavxai.avoidance.kernel import goal_delay
from uavxai.avoidance.mcts import TreeBuilder, TreePlanner
from uavxai.avoidance.model import GOAL, EncounterModel, Track
from uavxai.avoidance.types import PlannerConfig, SearchTree


def exhaustive_search(
    model: EncounterModel,
    root: np.ndarray,
    goal: np.ndarray,
    tracks: Sequence[Track],
    *,
    hold_s: float,
    time_left_s: float = math.inf,
) -> SearchTree:
    """The full tree to depth ``len(tracks)`` with best-value backups (see module docstring)."""
    # the body motions the tree can expand, memoised in one batch per level (one at a time,
    # as the builder meets them, they cost more than the search)
    model.motions(np.asarray(root, dtype=float).tolist(), hold_s, len(tracks))
    builder = TreeBuilder(model, root, goal, tracks, hold_s, time_left_s)
    frontier = [0]
    for _ in range(len(tracks)):
        nxt: list[int] = []
        for node in frontier:
            if not builder.is_leaf[node]:
                first = builder.expand(node)
                nxt.extend(range(first, first + builder.k))
        frontier = nxt
    value = np.array(builder.value)
    tree = builder.finish()
    unscored = np.isnan(value) & (tree.depth == len(tracks))
    value[unscored] = model.leaf_value(tree.pos[unscored], goal)
    # sooner is better (goal_delay: MCTS with backup "best" takes the same off its walks)
    delay = goal_delay(model.config, len(tracks))
    reached = tree.terminal == GOAL
    value[reached] -= delay * (tree.depth[reached] - 1)
    assert tree.first_child is not None
    blocks = np.arange(builder.k)
    for d in range(len(tracks) - 1, -1, -1):  # best value below, bottom up
        inner = np.flatnonzero((tree.depth == d) & (tree.first_child >= 0))
        value[inner] = value[tree.first_child[inner, None] + blocks].max(axis=1)
    tree.visits = np.ones(tree.size, dtype=int)
    tree.value_sum = value
    return tree


class ExhaustivePlanner(TreePlanner):
    """Exhaustive search over the planner API (README, planner API); deterministic."""

    sampled = False

    def __init__(self, config: PlannerConfig | None = None, *, name: str = "exhaustive") -> None:
        # Risk as a probability weighs the values MCTS backs up (avoidance.mcts.risk); the
        # exhaustive reference keeps the k-sigma wall, whatever the scenario asks of MCTS.
        # Likewise mcts_sep's NMAC cost and walls, the vertical margin, the goal's height
        # scale, the pinning, the aim inside the goal and the cornered rule are the MCTS
        # planners' only: the reference values lines without them, and its config says so.
        config = dataclasses.replace(
            config or PlannerConfig(), risk="margin", nmac_cost=0.0, wall_slack_s=0.0,
            vertical_reach_mps=None, goal_height_scale=1.0, pinned_slack_s=0.0,
            goal_margin_m=0.0, cornered_rule="latest",
        )
        super().__init__(config, name=name)

    def search(
        self, root: np.ndarray, goal: np.ndarray, tracks: list[Track], time_left_s: float
    ) -> SearchTree:
        return exhaustive_search(
            self.model,
            root,
            goal,
            tracks,
            hold_s=self.config.action_hold_s,
            time_left_s=time_left_s,
        )
