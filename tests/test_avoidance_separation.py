"""Graded separation and walls in the value (`mcts_sep`, issues 27 and 31): a leaf heading into
a wall it can no longer turn away from is worth nothing, one turning away keeps its value; a
line inside the NMAC volume of a track is worth less, the deeper the less; a collision stays
the hard conflict, worth less than any line that only intrudes on the NMAC volume."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from engine_runs import flown_twice

from uavxai.avoidance import Intruder, Ownship, PlannerConfig
from uavxai.avoidance.kernel import WALLT, _params, nmac_depth, wall_factor
from uavxai.avoidance.mcts import predict_levels, search
from uavxai.avoidance.model import COLLISION, NONE, EncounterModel, ownship_state
from uavxai.avoidance.planners import make_planner, sep_config
from uavxai.errors import UserError
from uavxai.xai.explain import render_record

CFG = sep_config(PlannerConfig())  # the default 2 km box, d_min 50 m, as mcts_sep flies it
GOAL = np.array([1000.0, 1000.0, 120.0])
NMAC_R = math.hypot(*CFG.nmac_m)  # the sphere holding the NMAC cylinder


def _par(cfg: PlannerConfig = CFG) -> np.ndarray:
    return _params(EncounterModel(cfg), GOAL, cfg.action_hold_s, math.inf, [])


def _row(x: float, y: float, heading_deg: float, speed: float = 20.0) -> np.ndarray:
    own = Ownship(x=x, y=y, h=120.0, speed=speed, heading=math.radians(heading_deg))
    return ownship_state(own)


def test_a_leaf_heading_into_a_wall_is_worth_less_than_one_turning_away() -> None:
    par = _par()
    # 60 m from the east wall (x = 2000)
    into = wall_factor(_row(1940.0, 1000.0, 90.0), par)  # due east, straight at it
    oblique = wall_factor(_row(1940.0, 1000.0, 45.0), par)  # north-east, closing slower
    along = wall_factor(_row(1940.0, 1000.0, 0.0), par)  # due north, along it
    away = wall_factor(_row(1940.0, 1000.0, 270.0), par)  # due west, away from it
    assert into == 0.0  # a 41 m turn radius at 30 deg bank, after rolling in: too late
    assert into < oblique < along == away == 1.0
    # far from every wall, whatever the heading, the leaf keeps its value
    assert all(wall_factor(_row(1000.0, 1000.0, h), par) == 1.0 for h in range(0, 360, 30))
    # the same heading, farther from the wall: more slack, more value, up to all of it
    f = [wall_factor(_row(2000.0 - d, 1000.0, 60.0), par) for d in (40, 80, 120, 160, 400)]
    assert f == sorted(f) and f[0] < f[-1] == 1.0
    # a corner counts both of its walls
    corner = wall_factor(_row(1940.0, 1940.0, 45.0), par)
    assert 0.0 < corner < wall_factor(_row(1940.0, 1000.0, 45.0), par)


def test_without_wall_slack_the_leaf_ignores_the_walls() -> None:
    par = _par(dataclasses.replace(CFG, wall_slack_s=0.0))
    assert par[WALLT] == 0.0 and _par()[WALLT] == CFG.wall_slack_s > 0  # kernel.run skips it


def test_nmac_intrusion_is_measured_in_the_nmac_cylinder_by_its_depth() -> None:
    par = _par()
    h, v = CFG.nmac_m
    # on the rim and beyond: no intrusion; 40 m above a track is outside the cylinder however
    # close horizontally (the sphere holding it would have counted it)
    assert nmac_depth(h, 0.0, par) == nmac_depth(0.0, v, par) == nmac_depth(200.0, 0.0, par) == 0
    assert nmac_depth(100.0, 40.0, par) == 0.0
    deeper = [nmac_depth(d, 0.0, par) for d in (150.0, 120.0, 90.0, 60.0, 50.0, 10.0)]
    assert deeper == sorted(deeper) and deeper[0] > 0.0 and deeper[-2] == deeper[-1] == 1.0
    assert 0.0 < nmac_depth(0.0, 25.0, par) < nmac_depth(0.0, 10.0, par)


def test_nmac_cost_must_leave_a_line_some_value() -> None:
    with pytest.raises(UserError, match="nmac_cost"):
        PlannerConfig(nmac_cost=1.0)
    with pytest.raises(UserError, match="wall_slack_s"):
        PlannerConfig(wall_slack_s=-1.0)


def _head_on() -> tuple[Ownship, list[Intruder]]:
    """Ownship due east at 20 m/s; an intruder 400 m ahead coming west at 20 m/s, 10 m lower:
    flying straight collides in 10 s; turning away passes inside the NMAC volume."""
    own = Ownship(x=500.0, y=1000.0, h=120.0, speed=20.0, heading=math.pi / 2)
    return own, [Intruder(id=1, x=900.0, y=1000.0, h=110.0, vx=-20.0, vy=0.0)]


def _tree(cfg: PlannerConfig, own: Ownship, intruders: list[Intruder]):
    model = EncounterModel(cfg)
    tracks = predict_levels(model, intruders, cfg.depth, cfg.action_hold_s)
    return search(model, ownship_state(own), GOAL, tracks, simulations=cfg.simulations, c=cfg.c,
                  hold_s=cfg.action_hold_s, rng=np.random.default_rng(0))  # fmt: skip


def test_a_collision_stays_worth_less_than_any_nmac_intrusion() -> None:
    own, intruders = _head_on()
    tree = _tree(CFG, own, intruders)
    seen = tree.visits > 0
    value = np.divide(tree.value_sum, tree.visits, out=np.zeros(tree.size), where=seen)
    hit = seen & (tree.terminal == COLLISION)
    leaf = seen & (tree.terminal == NONE) & (tree.depth == CFG.depth)
    assert hit.any() and leaf.any()
    # some open leaves paid for the NMAC volume (eq 13 alone: 1 - d / d_max, far from the
    # walls), down to 1 - nmac_cost of it, and still outrank every collision
    eq13 = 1.0 - np.linalg.norm(tree.pos[leaf] - GOAL, axis=1) / CFG.d_max
    paid = value[leaf] / eq13
    assert paid.min() < 1.0 - 1e-9 and paid.min() >= 1.0 - CFG.nmac_cost - 1e-9
    assert value[hit].max() < value[leaf].min()


def test_the_nmac_cost_buys_separation_where_there_is_room() -> None:
    """The intruder crosses 120 m north of the straight route: no conflict at 50 m, an NMAC
    intrusion. mcts_vertical keeps to the route; mcts_sep's line passes farther."""
    own = Ownship(x=500.0, y=1000.0, h=120.0, speed=20.0, heading=math.pi / 2)
    intruders = [Intruder(id=1, x=900.0, y=1120.0, h=120.0, vx=-20.0, vy=0.0)]
    plain = make_planner("mcts_vertical", PlannerConfig()).plan(own, intruders, tuple(GOAL))
    sep = make_planner("mcts_sep", PlannerConfig()).plan(own, intruders, tuple(GOAL))
    assert sep.planner == "mcts_sep"
    assert sep.branch_min_separation_m > plain.branch_min_separation_m
    assert sep.branch_min_separation_m >= NMAC_R > plain.branch_min_separation_m


def test_mcts_sep_flies_an_episode_the_same_twice() -> None:
    from uavxai.scenario import default_scenario

    sc = default_scenario("sep", intruders={"behaviour": "random_turns"},
                          avoidance={"max_steps": 30}, ownship={"goal": [1000, 1000, 120]})
    a, b = flown_twice(sc, "mcts_sep", 20, 4)
    assert a["method"] == "mcts_sep" and a["steps"] > 0 and a == b


def test_settings_that_would_break_the_grading_are_refused() -> None:
    # the depth is graded from the NMAC rim down to d_min_m: d_min_m at or beyond the rim
    # would divide by zero in the kernel or switch the cost off silently
    with pytest.raises(UserError, match="d_min_m"):
        PlannerConfig(nmac_cost=0.5, d_min_m=152.4)
    with pytest.raises(UserError, match="d_min_m"):
        PlannerConfig(nmac_cost=0.5, d_min_m=200.0)
    PlannerConfig(nmac_cost=0.0, d_min_m=200.0)  # no cost: nothing graded, allowed
    # a late collision may tie with the deepest time-out, never outrank it
    with pytest.raises(UserError, match="late_collision_value"):
        PlannerConfig(nmac_cost=0.5, late_collision_value=0.06)
    with pytest.raises(UserError, match="late_collision_value"):
        PlannerConfig(nmac_cost=0.3, late_collision_value=0.075)
    PlannerConfig(nmac_cost=0.5, late_collision_value=0.05)  # mcts_sep's own: a tie
    # above 0.5 no late_collision_value the user can reach ties: the key's own bound says so
    with pytest.raises(UserError, match="nmac_cost"):
        PlannerConfig(nmac_cost=0.6, late_collision_value=0.05)


def _chased_to_the_wall(y: float) -> tuple[Ownship, list[Intruder]]:
    """Ownship due south ``y`` m from the south wall; an intruder 150 m behind it, coming
    south at 30 m/s: with its margins every straight line meets it, late (issue 31's dev seed
    5027: the late meetings led mcts_sep out of the area)."""
    own = Ownship(x=1000.0, y=y, h=120.0, speed=20.0, heading=math.pi)
    return own, [Intruder(id=1, x=1000.0, y=y + 150.0, h=120.0, vx=0.0, vy=-30.0)]


def test_a_late_collision_heading_out_of_the_area_is_worth_what_leaving_is() -> None:
    own, intruders = _chased_to_the_wall(200.0)
    par = _par()
    for cfg in (CFG, dataclasses.replace(CFG, wall_slack_s=0.0)):
        tree = _tree(cfg, own, intruders)
        hit = np.flatnonzero((tree.visits > 0) & (tree.terminal == COLLISION))
        value = tree.value_sum[hit] / tree.visits[hit]
        walls = np.array([wall_factor(tree.state[i], par) for i in hit])
        doomed, free = walls == 0.0, walls == 1.0
        assert doomed.any() and free.any()
        # a collision stays the hard conflict: never above the late collision's value
        assert value.max() <= cfg.late_collision_value
        if cfg.wall_slack_s > 0:  # mcts_sep: past the point of no return, worth nothing
            assert value[doomed].max() == 0.0 and value[free].min() > 0.0
            assert np.all(value <= cfg.late_collision_value * walls + 1e-12)
        else:  # the term off (every planner but mcts_sep): late meetings ignore the walls
            assert value[doomed].max() > 0.0


@pytest.mark.parametrize("y", [150.0, 200.0])
def test_mcts_sep_chased_towards_a_wall_keeps_a_line_that_can_stay_in_the_area(y: float) -> None:
    own, intruders = _chased_to_the_wall(y)
    decision = make_planner("mcts_sep", PlannerConfig()).plan(own, intruders, tuple(GOAL))
    assert decision.plan[:, 1].min() > 0.0  # the planned line stays north of the wall
    tree, node = decision.tree, 0
    while (child := tree.best_child(node)) is not None:  # the line the search preferred
        node = child
    assert node > 0 and wall_factor(tree.state[node], _par()) > 0.0  # it can still turn away


def test_only_a_planner_that_weighs_the_walls_marks_lines_trapped() -> None:
    own, intruders = _chased_to_the_wall(150.0)
    par = _par()
    for name in ("mcts_vertical", "mcts_sep"):
        decision = make_planner(name, PlannerConfig()).plan(own, intruders, tuple(GOAL))
        tree = decision.tree
        doomed_lines = 0
        for c in decision.children:
            node = next(int(n) for n in tree.children_of(0) if tree.action[n] == c.action)
            while (child := tree.best_child(node)) is not None:
                node = child
            doomed = tree.terminal[node] in (NONE, COLLISION) and wall_factor(
                tree.state[node], par) == 0.0  # fmt: skip
            assert c.trapped == (doomed and name == "mcts_sep")
            doomed_lines += doomed
        # mcts_vertical had doomed lines too and marked none of them: the mark is the walls'
        # planner's, not a property of the geometry every planner would report.
        assert doomed_lines > 0, f"{name}: no line ends unable to turn away; nothing is shown"
        record = decision.to_json()["children"]  # decisions.jsonl names the trapped lines only
        assert [r.get("trapped", False) for r in record] == [c.trapped for c in decision.children]
        # `uavxai explain`'s table of root actions says which lines are trapped, and only those
        table = render_record(decision.to_json(), 0, 1).split("root actions:")[1].splitlines()[2:]
        assert [row.endswith("cannot turn from the edge") for row in table] == [
            c.trapped for c in decision.children
        ]
        if name == "mcts_sep":
            assert any(c.trapped for c in decision.children)
            assert not next(c for c in decision.children if c.action == decision.action).trapped
