"""Turn a planner's search tree into a small, readable graph: which nodes, where, what label.

A full MCTS tree has hundreds of nodes; drawn as-is it is a hairball. We keep what a reader
needs to see why the action was chosen: every visited root action, and below that only the
chosen branch and its runner-up, each with its most visited few children. The tree grows left
to right (root on the left, leaves stacked evenly, each parent level with the middle of its
children), so two-line labels stack instead of overlapping side by side.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from uavxai.avoidance.model import COLLISION
from uavxai.avoidance.types import Decision
from uavxai.vocabulary import ACTIONS

CHOSEN_COLOR = (46, 204, 113)
OTHER_COLOR = (120, 144, 156)
COLLISION_COLOR = (231, 76, 60)
ROOT_COLOR = (52, 152, 219)

LEAF_SPACING = 42.0  # graph-view units between stacked leaves; fits a two-line label
LEVEL_SPACING = 150.0  # between depths; fits the widest label


def short_action(a: int) -> str:
    return ACTIONS[a].short


@dataclass
class TreeGraph:
    node_ids: list[str] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    colors: list[tuple[int, int, int]] = field(default_factory=list)
    radii: list[float] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)  # index into node_ids, -1 for the root
    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def edges(self) -> list[tuple[str, str]]:
        return [(self.node_ids[p], self.node_ids[i]) for i, p in enumerate(self.parents) if p >= 0]

    def add(
        self,
        node_id: str,
        label: str,
        color: tuple[int, int, int],
        visits: int,
        root_visits: int,
        parent: int,
    ) -> int:
        self.node_ids.append(node_id)
        self.labels.append(label)
        self.colors.append(color)
        # Area proportional to visits, with a floor so rarely visited nodes stay clickable.
        self.radii.append(6.0 + 18.0 * float(np.sqrt(visits / max(root_visits, 1))))
        self.parents.append(parent)
        return len(self.node_ids) - 1


def tree_graph(
    decision: Decision, max_depth: int = 2, expand: int = 2, branch: int = 3
) -> TreeGraph:
    """The displayed part of ``decision``'s search tree, with node positions.

    All visited root actions are shown. Of each shown level only the chosen node and the most
    visited others, ``expand`` in all, show their children, and then only the ``branch`` most
    visited ones; nothing deeper than ``max_depth``.
    """
    tree = decision.tree
    graph = _from_tree(decision, max_depth, expand, branch) if tree is not None else None
    if graph is None:
        graph = _from_children(decision)
    graph.positions = _tidy_layout(graph.parents)
    return graph


def _from_tree(decision: Decision, max_depth: int, expand: int, branch: int) -> TreeGraph | None:
    tree = decision.tree
    assert tree is not None
    if tree.size == 0 or tree.visits[0] <= 0:
        return None
    q = tree.q
    root_visits = int(tree.visits[0])
    graph = TreeGraph()
    graph.add("n0", f"now\nn={root_visits}", ROOT_COLOR, root_visits, root_visits, -1)
    frontier: list[tuple[int, int, bool]] = [(0, 0, True)]  # (tree node, graph index, chosen)
    while frontier:
        node, g_index, chosen = frontier.pop()
        depth = int(tree.depth[node])
        if depth >= max_depth:
            continue
        kids = [int(c) for c in tree.children_of(node) if tree.visits[c] > 0]
        # Most visited first, ties as the plan breaks them (higher Q, then action order), so
        # that the first below a chosen node is the plan's next node (SearchTree.best_child).
        kids.sort(key=lambda c: (-int(tree.visits[c]), -float(q[c]), int(tree.action[c])))
        if depth >= 1:
            kids = kids[:branch]
        chosen_kid = _chosen_child(tree, kids, decision.action, depth) if chosen else None
        opened = {chosen_kid} if chosen_kid is not None else set()
        for c in kids:  # most visited first
            if len(opened) >= expand:
                break
            opened.add(c)
        # Drawn in action order, so "left" branches sit on top in every decision.
        for c in sorted(kids, key=lambda c: int(tree.action[c])):
            # The plan stays green to its end, a collision on it included (said in the
            # label), so the chosen action is never drawn red without a green line.
            if c == chosen_kid:
                color = CHOSEN_COLOR
            else:
                color = COLLISION_COLOR if tree.terminal[c] == COLLISION else OTHER_COLOR
            label = f"{short_action(int(tree.action[c]))}\nn={int(tree.visits[c])} Q={q[c]:.2f}"
            if tree.terminal[c] == COLLISION:
                label += "\ncollision"
            index = graph.add(f"n{c}", label, color, int(tree.visits[c]), root_visits, g_index)
            if c in opened:
                frontier.append((c, index, c == chosen_kid))
    return graph


def _chosen_child(tree, kids: list[int], action: int, depth: int) -> int | None:
    """The root action the planner took, then the line below it that is its plan
    (:meth:`SearchTree.best_line`)."""
    if depth == 0:
        return next((c for c in kids if int(tree.action[c]) == action), None)
    return kids[0] if kids else None


def _from_children(decision: Decision) -> TreeGraph:
    """Root and its actions from the ChildStats alone, for planners that keep no tree."""
    visited = [c for c in decision.children if c.visits > 0]
    root_visits = sum(c.visits for c in visited)
    graph = TreeGraph()
    graph.add("root", f"now\nn={root_visits}", ROOT_COLOR, root_visits, root_visits, -1)
    for c in sorted(visited, key=lambda c: c.action):
        color = CHOSEN_COLOR if c.action == decision.action else OTHER_COLOR
        label = f"{short_action(c.action)}\nn={c.visits} Q={c.q:.2f}"
        graph.add(f"a{c.action}", label, color, c.visits, root_visits, 0)
    return graph


def _tidy_layout(parents: list[int]) -> np.ndarray:
    """(x, y) per node: depth to the right, leaves stacked downwards, parents mid-children."""
    n = len(parents)
    children: list[list[int]] = [[] for _ in range(n)]
    depth = np.zeros(n)
    for i, p in enumerate(parents):
        if p >= 0:
            children[p].append(i)
            depth[i] = depth[p] + 1
    y = np.zeros(n)
    next_leaf = 0.0

    def place(i: int) -> None:
        nonlocal next_leaf
        for c in children[i]:
            place(c)
        if children[i]:
            y[i] = 0.5 * (y[children[i][0]] + y[children[i][-1]])
        else:
            y[i] = next_leaf
            next_leaf += LEAF_SPACING

    if n:
        place(0)  # depth is at most a few levels, so recursion is shallow
    return np.stack([depth * LEVEL_SPACING, y - (y[0] if n else 0.0)], axis=1)
