"""Aiming inside the goal (`avoidance.mcts.goal_margin_m`, issue 31): the MCTS planners'
compiled search counts the goal reached only within the goal radius less the margin, so a line
predicted to clip the sphere's rim is no longer a goal; the judge still counts the radius."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.avoidance import Ownship, PlannerConfig
from uavxai.avoidance.model import GOAL, NONE, EncounterModel, ownship_state
from uavxai.avoidance.planners import make_planner
from uavxai.cli import main
from uavxai.errors import UserError

HOLD = 4  # bank hold, speed hold: the line flies straight on
OWN = Ownship(x=1000.0, y=1000.0, h=120.0, speed=20.0, heading=0.0)  # due north
RIM = (1045.0, 1030.0, 120.0)  # the straight path passes it 45 m off: inside 50, outside 40


def _straight(margin: float) -> int:
    """The event of the straight line past RIM in the model (the exhaustive search's path)."""
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
    assert _root_hold_code(10.0) != GOAL


def test_exhaustive_and_mcts_daa_keep_the_whole_sphere() -> None:
    cfg = PlannerConfig(goal_margin_m=10.0)
    assert make_planner("exhaustive", cfg).config.goal_margin_m == 0.0
    assert make_planner("mcts_daa", cfg).inner.config.goal_margin_m == 0.0


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
