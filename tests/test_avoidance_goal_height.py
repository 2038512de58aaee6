"""The leg's height in the leaf value (`avoidance.mcts.goal_height_scale`, issue 31): a leaf's
distance to the goal counts each metre of height off the goal's as this many metres, so that
the vertical action set's tree does not sit out of the traffic's layer at the floor's or the
ceiling's level-off for nothing (the paper's 3-D distance: 1)."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.avoidance import Ownship, PlannerConfig
from uavxai.avoidance.kernel import wall_share
from uavxai.avoidance.model import EncounterModel
from uavxai.avoidance.planners import make_planner
from uavxai.cli import main

GOAL = (1000.0, 1900.0, 120.0)


def _tree(scale: float, h: float = 120.0):
    """mcts_sep's tree with no traffic, 1,400 m short of the goal, far from every wall."""
    own = Ownship(x=1000.0, y=500.0, h=h, speed=20.0, heading=0.0)  # due north, at the goal
    cfg = PlannerConfig(goal_height_scale=scale, backup="best")  # the best line's Q: tree.best
    return make_planner("mcts_sep", cfg).plan(own, [], GOAL).tree, cfg


def _leaf_values(tree, cfg: PlannerConfig, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """The open leaves' values as the tree keeps them, and as the formula has them."""
    leaf = (tree.depth == tree.depth.max()) & (tree.visits > 0) & (tree.terminal == 0)
    got = tree.value_sum[leaf] / tree.visits[leaf]
    x, y, h = tree.state[leaf, 0], tree.state[leaf, 1], tree.state[leaf, 2]
    d = np.sqrt((x - GOAL[0]) ** 2 + (y - GOAL[1]) ** 2 + (scale * (h - GOAL[2])) ** 2)
    return got, 1.0 - d / cfg.d_max


@pytest.mark.parametrize("scale", [1.0, 8.0])
def test_a_leaf_counts_its_height_off_the_goal_by_the_scale(scale: float) -> None:
    tree, cfg = _tree(scale)
    got, want = _leaf_values(tree, cfg, scale)
    leaf = (tree.depth == tree.depth.max()) & (tree.visits > 0) & (tree.terminal == 0)
    assert got.size > 20 and np.ptp(tree.state[leaf, 2]) > 10.0  # leaves at several heights
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_at_the_legs_height_with_the_papers_actions_nothing_changes() -> None:
    # the paper's nine hold the goal's height: every leaf is at it, so the scale is idle
    def tree(scale: float):
        own = Ownship(x=1000.0, y=500.0, h=120.0, speed=20.0, heading=0.0)
        cfg = PlannerConfig(goal_height_scale=scale, backup="best")
        return make_planner("mcts", cfg).plan(own, [], GOAL).tree

    a, b = tree(1.0), tree(4.0)
    assert np.ptp(a.state[:, 2]) < 1e-9
    for name in ("visits", "value_sum", "best", "action"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_a_leaf_farther_than_the_diagonal_is_worth_0_never_less() -> None:
    # the review's case: near the ceiling, far from a goal at 120 m, a scale of 50 took leaf
    # values to -1.9, so a line that could no longer turn away from a wall (its value times
    # 0) outranked every other; the value now stops at 0 before the factors multiply it
    own = Ownship(x=300.0, y=300.0, h=290.0, speed=20.0, heading=45.0)
    goal = (1900.0, 1900.0, 120.0)
    planner = make_planner("mcts_sep", PlannerConfig(goal_height_scale=50.0, backup="best"))
    tree = planner.plan(own, [], goal).tree
    cfg, model = planner.config, EncounterModel(planner.config)
    leaf = (tree.visits > 0) & (tree.terminal == 0) & (tree.depth == tree.depth.max())
    got = tree.value_sum[leaf] / tree.visits[leaf]
    rows = tree.state[leaf]
    d = np.sqrt((rows[:, 0] - goal[0]) ** 2 + (rows[:, 1] - goal[1]) ** 2
                + (50.0 * (rows[:, 2] - goal[2])) ** 2)  # fmt: skip
    assert got.size > 20 and (1.0 - d / cfg.d_max).min() < 0.0  # the case arises
    want = np.maximum(1.0 - d / cfg.d_max, 0.0) * [wall_share(model, r) for r in rows]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    assert got.min() >= 0.0


def test_exhaustive_and_mcts_daa_keep_the_papers_distance() -> None:
    # exhaustive's leaf values at 8 are those at 1 (the setting is dropped from its config)
    own = Ownship(x=1000.0, y=500.0, h=150.0, speed=20.0, heading=0.0)

    def values(scale: float) -> np.ndarray:
        cfg = PlannerConfig(goal_height_scale=scale, actions="vertical", depth=2)
        return make_planner("exhaustive", cfg).plan(own, [], GOAL).tree.value_sum

    np.testing.assert_array_equal(values(1.0), values(8.0))
    daa = make_planner("mcts_daa", PlannerConfig(goal_height_scale=8.0))
    assert daa.inner.config.goal_height_scale == 1.0


def test_the_scale_is_checked_at_load(tmp_path, capsys) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("avoidance:\n  mcts:\n    goal_height_scale: 0.5\n")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "goal_height_scale" in err
    path.write_text("avoidance:\n  mcts:\n    goal_height_scale: 51\n")
    assert main(["validate", str(path)]) == 2
    assert "goal_height_scale" in capsys.readouterr().err
