"""Aiming inside the goal (`avoidance.mcts.goal_margin_m`, issue 31): the MCTS planners'
compiled search counts the goal reached only within the goal radius less the margin, so a line
predicted to clip the sphere's rim is no longer a goal; the judge still counts the radius."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.avoidance import Ownship, PlannerConfig
from uavxai.avoidance.mcts import TreeBuilder, predict_levels, search
from uavxai.avoidance.model import GOAL, NONE, EncounterModel, ownship_state
from uavxai.avoidance.planners import make_planner
from uavxai.cli import main
from uavxai.errors import UserError

HOLD = 4  # bank hold, speed hold: the line flies straight on
OWN = Ownship(x=1000.0, y=1000.0, h=120.0, speed=20.0, heading=0.0)  # due north
RIM = (1045.0, 1030.0, 120.0)  # the straight path passes it 45 m off: inside 50, outside 40


def _straight(margin: float) -> int:
    """The event of the straight line past RIM in the model (the Python expansion of the tree,
    TreeBuilder, and the lines an explanation measures)."""
    model = EncounterModel(PlannerConfig(goal_margin_m=margin))
    track = model.predict(np.zeros((0, 3)), np.zeros((0, 3)), 4.0)
    seg = model.fly(ownship_state(OWN)[None], np.array([HOLD]), np.asarray(RIM), 4.0, track)
    return int(seg.event[0])


def test_a_line_past_the_rim_is_a_goal_only_without_the_margin() -> None:
    assert _straight(0.0) == GOAL
    assert _straight(10.0) == NONE
    assert _straight(4.9) == GOAL  # 45 m is still inside 50 - 4.9


def _root_hold_code(margin: float) -> int:
    """What the compiled search (mcts_sep) makes of the root's straight action."""
    cfg = PlannerConfig(goal_margin_m=margin, backup="best")
    tree = make_planner("mcts_sep", cfg).plan(OWN, [], RIM).tree
    children = np.flatnonzero((tree.depth == 1) & (tree.action == HOLD))
    assert children.size == 1
    return int(tree.terminal[children[0]])


def test_the_compiled_search_aims_inside_by_the_margin() -> None:
    assert _root_hold_code(0.0) == GOAL
    assert _root_hold_code(4.9) == GOAL  # 45 m is still inside 50 - 4.9: the margin, no constant
    assert _root_hold_code(10.0) == NONE


def _margin(name: str) -> float:
    planner = make_planner(name, PlannerConfig(goal_margin_m=10.0))
    inner = getattr(planner, "inner", planner)  # the alerting and routed planners wrap a tree
    return inner.config.goal_margin_m


MCTS_NAMES = ["mcts", "mcts_sep", "mcts_vertical", "mcts_sep_daa", "mcts_route"]


@pytest.mark.parametrize("name", MCTS_NAMES)
def test_the_mcts_planners_aim_inside(name: str) -> None:
    assert _margin(name) == 10.0


@pytest.mark.parametrize("name", ["exhaustive", "mcts_daa", "mvp", "none"])
def test_the_others_keep_the_whole_sphere(name: str) -> None:
    # the reference and mcts_daa's judged campaigns, and the planners that do not search
    # toward the goal, whose decisions.jsonl evidence shows the judge's goal
    assert _margin(name) == 0.0


def test_mvps_evidence_shows_the_judges_goal() -> None:
    cfg = PlannerConfig(goal_margin_m=10.0)
    decision = make_planner("mvp", cfg).plan(OWN, [], RIM)
    straight = next(c for c in decision.children if c.action == HOLD)
    assert straight.outcome == "goal"


@pytest.mark.parametrize("margin", ["50", "-1"])
def test_the_margin_is_checked_at_load(tmp_path, capsys, margin: str) -> None:
    # at or beyond the radius there is no goal left to aim at; below 0, the schema refuses
    path = tmp_path / "s.yaml"
    path.write_text(
        f"name: x\navoidance:\n  goal_radius_m: 50\n  mcts:\n    goal_margin_m: {margin}\n"
    )
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "goal_margin_m" in err


def test_the_planner_config_refuses_a_margin_past_the_radius() -> None:
    with pytest.raises(UserError, match="goal_margin_m"):
        PlannerConfig(goal_radius_m=50.0, goal_margin_m=50.0)


@pytest.mark.parametrize("margin", [0.0, 10.0, 30.0])
@pytest.mark.parametrize("actions", ["paper", "vertical"])
def test_near_the_goal_the_kernel_expands_as_the_python_tree(margin: float, actions: str) -> None:
    # 150 m short of the goal, so goal leaves arise: the compiled search and the Python
    # expansion (TreeBuilder) must agree on each, as tests/test_avoidance_kernel.py checks
    # them in crowded traffic far from any goal
    cfg = PlannerConfig(goal_margin_m=margin, actions=actions)
    model = EncounterModel(cfg)
    root, goal = ownship_state(OWN), np.array([1000.0, 1150.0, 125.0])
    tracks = predict_levels(model, [], cfg.depth, cfg.action_hold_s)
    hold = cfg.action_hold_s
    tree = search(model, root, goal, tracks, simulations=cfg.simulations, c=cfg.c,
                  hold_s=hold, rng=np.random.default_rng(0), time_left_s=60.0)  # fmt: skip
    builder = TreeBuilder(model, root, goal, tracks, hold, 60.0)
    expanded = np.flatnonzero(tree.first_child >= 0)
    for node in expanded[np.argsort(tree.first_child[expanded])]:
        assert builder.expand(int(node)) == tree.first_child[node]
    python = builder.finish()
    for name in ("parent", "action", "depth", "terminal", "first_child"):
        np.testing.assert_array_equal(getattr(tree, name), getattr(python, name), name)
    assert (tree.terminal == GOAL).sum() > 5
