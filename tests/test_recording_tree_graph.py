"""Which part of a search tree is drawn, how it is labelled and laid out."""

from __future__ import annotations

import math

import numpy as np

from uavxai.avoidance.model import COLLISION
from uavxai.avoidance.types import ChildStats, Decision, SearchTree
from uavxai.recording.tree_graph import (
    CHOSEN_COLOR,
    COLLISION_COLOR,
    LEVEL_SPACING,
    short_action,
    tree_graph,
)


def hand_made_tree() -> tuple[SearchTree, list[int]]:
    """Root, 9 actions (action 8 never visited), 9 grandchildren under actions 0, 4 and 5.

    Visits: action 4 most (60), then 0 (30), then 5 (20); each of these has children with
    visits 9..1 so the top three are the first three. Grandchild (4, action 2) ends in a
    collision.
    """
    parent, action, depth, visits = [-1], [-1], [0], [120]
    root_visits = {0: 30, 1: 3, 2: 2, 3: 2, 4: 60, 5: 20, 6: 2, 7: 1, 8: 0}
    for a in range(9):
        parent.append(0)
        action.append(a)
        depth.append(1)
        visits.append(root_visits[a])
    grand_parents = []
    for a in (0, 4, 5):
        for b in range(9):
            parent.append(1 + a)
            action.append(b)
            depth.append(2)
            visits.append(9 - b)
            grand_parents.append(1 + a)
    m = len(parent)
    visits = np.array(visits)
    terminal = np.zeros(m, dtype=np.int8)
    collision_node = 10 + 9 + 2  # under action 4, action 2
    terminal[collision_node] = COLLISION
    tree = SearchTree(
        parent=np.array(parent),
        action=np.array(action),
        depth=np.array(depth),
        visits=visits,
        value_sum=0.5 * visits,
        min_sep=np.full(m, 100.0),
        closest=np.zeros(m, dtype=int),
        terminal=terminal,
        pos=np.zeros((m, 3)),
    )
    return tree, grand_parents


def decision_with(tree: SearchTree | None, action: int, children=()) -> Decision:
    return Decision(0.0, 0.0, action, list(children), tree=tree, words=("because", ""))


def test_shows_visited_actions_and_two_expanded_branches():
    tree, _ = hand_made_tree()
    graph = tree_graph(decision_with(tree, action=4))
    depth1 = [i for i, p in enumerate(graph.parents) if p == 0]
    assert len(depth1) == 8  # action 8 had no visits
    expanded = {graph.node_ids[graph.parents[i]] for i, p in enumerate(graph.parents) if p > 0}
    assert expanded == {"n5", "n1"}  # chosen action 4, runner-up action 0
    assert len(graph.node_ids) == 1 + 8 + 2 * 3
    # Under each expanded node: its three most visited children, i.e. actions 0, 1, 2.
    under_chosen = [graph.labels[i] for i, p in enumerate(graph.parents) if p == depth1[4]]
    assert [lbl.split("\n")[0] for lbl in under_chosen] == [short_action(a) for a in (0, 1, 2)]


def test_the_chosen_action_is_expanded_even_when_rarely_visited():
    tree, _ = hand_made_tree()
    graph = tree_graph(decision_with(tree, action=1))
    expanded = {graph.node_ids[graph.parents[i]] for i, p in enumerate(graph.parents) if p > 0}
    # Action 1 has no children in this tree, so only the most visited (4) shows children.
    assert expanded == {"n5"}
    chosen = graph.node_ids.index("n2")
    assert graph.colors[chosen] == CHOSEN_COLOR


def test_labels_carry_action_visits_and_q_and_collisions_are_red():
    tree, _ = hand_made_tree()
    graph = tree_graph(decision_with(tree, action=4))
    i = graph.node_ids.index("n5")
    assert graph.labels[i] == f"{short_action(4)}\nn=60 Q=0.50"
    assert graph.colors[graph.node_ids.index("n21")] == COLLISION_COLOR
    assert graph.labels[0].startswith("now\nn=120")


def test_layout_is_a_left_to_right_tree_with_parents_between_children():
    tree, _ = hand_made_tree()
    graph = tree_graph(decision_with(tree, action=4))
    pos = graph.positions
    assert pos.shape == (len(graph.node_ids), 2)
    depth = np.zeros(len(graph.parents))
    for i, p in enumerate(graph.parents):
        if p >= 0:
            depth[i] = depth[p] + 1
    np.testing.assert_allclose(pos[:, 0], depth * LEVEL_SPACING)
    for node in range(len(graph.parents)):
        kids = [i for i, p in enumerate(graph.parents) if p == node]
        if kids:
            assert min(pos[kids, 1]) <= pos[node, 1] <= max(pos[kids, 1])
    leaves = [i for i in range(len(graph.parents)) if i not in graph.parents]
    assert len({round(y, 6) for y in pos[leaves, 1]}) == len(leaves)  # no two leaves overlap
    assert {(a, b) for a, b in graph.edges} == {
        (graph.node_ids[p], graph.node_ids[i]) for i, p in enumerate(graph.parents) if p >= 0
    }


def test_without_a_tree_the_root_actions_come_from_child_stats():
    children = [
        ChildStats(
            a,
            0.0,
            0.0,
            visits=v,
            q=0.1 * a,
            predicted_min_separation_m=math.inf,
            closest_intruder=None,
        )
        for a, v in enumerate([5, 0, 7, 0, 0, 0, 0, 0, 1])
    ]
    graph = tree_graph(decision_with(None, action=2, children=children))
    assert graph.node_ids == ["root", "a0", "a2", "a8"]
    assert graph.labels[0] == "now\nn=13"
    assert graph.colors[2] == CHOSEN_COLOR
    assert len(graph.edges) == 3


def _colors(graph) -> dict[int, tuple[int, int, int]]:
    return {int(n[1:]): c for n, c in zip(graph.node_ids, graph.colors, strict=True)}


def test_the_green_node_below_the_choice_is_the_plan_on_a_visit_tie():
    """Two children of the chosen action tie on visits: the plan (best_line) takes the higher
    Q, and so must the green node, whatever the action order says."""
    tree, _ = hand_made_tree()
    under_4 = [int(c) for c in tree.children_of(5)]  # node 5 is root action 4
    tree.visits[under_4[1]] = tree.visits[under_4[0]]  # a visit tie between actions 0 and 1
    tree.value_sum[under_4[0]] = 0.2 * tree.visits[under_4[0]]
    tree.value_sum[under_4[1]] = 0.9 * tree.visits[under_4[1]]  # the later one has the higher Q
    plan = tree.best_line(5)
    assert plan[1] == under_4[1]  # the situation under test
    colors = _colors(tree_graph(decision_with(tree, 4)))
    green = [n for n, c in colors.items() if c == CHOSEN_COLOR and tree.depth[n] == 2]
    assert green == [plan[1]]


def test_the_chosen_action_is_green_even_when_its_line_collides():
    tree, _ = hand_made_tree()
    tree.terminal[5] = COLLISION  # root action 4, the chosen one, ends in a collision
    graph = tree_graph(decision_with(tree, 4))
    index = graph.node_ids.index("n5")
    assert graph.colors[index] == CHOSEN_COLOR
    assert graph.labels[index].endswith("\ncollision")
    other = graph.node_ids.index("n1")  # root action 0, not chosen
    tree.terminal[1] = COLLISION
    graph = tree_graph(decision_with(tree, 4))
    assert graph.colors[other] == COLLISION_COLOR
