"""`mcts_sep_daa` (issue 27): `mcts_sep`'s tree behind `mcts_daa`'s alerting stage. Quiet (the
nominal route) while no track threatens well clear; alerted, the tree searches with
`mcts_sep`'s settings and keeps the route only while the route's line is clear as that tree
sees it: no meeting and no NMAC intrusion (its graded separation)."""

from __future__ import annotations

import dataclasses

import pytest

from uavxai.avoidance.alerting import AlertingPlanner
from uavxai.avoidance.planners import make_planner, sep_config
from uavxai.avoidance.types import ChildStats, Intruder, Meeting, Ownship, PlannerConfig
from uavxai.vocabulary import AVOIDANCE_PLANNERS, VERTICAL_PLANNERS

OWN = Ownship(x=1000.0, y=0.0, h=120.0, speed=25.0, heading=0.0)  # north at 25 m/s
GOAL = (1000.0, 2000.0, 120.0)
CONFIG = PlannerConfig(x_bounds=(0, 2000), y_bounds=(-500, 4500))


def _coming_south(x: float, y: float) -> Intruder:
    """A GA aircraft ``x - 1000`` m to the side of the route, coming south at 35 m/s."""
    return Intruder(id=7, x=x, y=y, h=120.0, vx=0.0, vy=-35.0)


def test_it_is_registered_and_flies_the_vertical_set() -> None:
    assert "mcts_sep_daa" in AVOIDANCE_PLANNERS and "mcts_sep_daa" in VERTICAL_PLANNERS
    planner = make_planner("mcts_sep_daa", CONFIG)
    assert isinstance(planner, AlertingPlanner) and planner.name == "mcts_sep_daa"
    # the tree is mcts_sep's, written once (planners.sep_config)
    assert planner.inner.config == sep_config(CONFIG)
    assert planner.inner.config.nmac_cost > 0 and planner.inner.config.wall_slack_s > 0


def test_quiet_without_a_threat_the_nominal_route() -> None:
    planner = make_planner("mcts_sep_daa", CONFIG)
    far = [_coming_south(1000.0, 4500.0)]  # well clear for the next 55 s
    d = planner.plan(OWN, far, GOAL)
    n = make_planner("none", CONFIG).plan(OWN, far, GOAL)
    assert (d.action, d.bank_cmd_rad, d.accel_mps2) == (n.action, n.bank_cmd_rad, n.accel_mps2)
    assert d.tree is None and d.children == [] and d.planner == "mcts_sep_daa"
    assert d.words[0].startswith("clear of traffic")


def test_a_threat_hands_the_decision_to_mcts_seps_tree() -> None:
    """Head on at 900 m (15 s): the tree decides, and it is mcts_sep's (same seed, same
    decision)."""
    pic = [_coming_south(1000.0, 900.0)]
    daa = make_planner("mcts_sep_daa", CONFIG)
    sep = make_planner("mcts_sep", CONFIG)
    for seed in range(3):
        daa.reset(seed)
        sep.reset(seed)
        d, s = daa.plan(OWN, pic, GOAL), sep.plan(OWN, pic, GOAL)
        assert d.tree is not None and d.planner == "mcts_sep_daa"
        assert d.tree.nmac_depth is not None  # the graded tree: mcts_sep's settings
        # the route's line meets the intruder: nothing to keep, the search's choice stands
        assert not d.route_kept
        assert (d.action, d.alt_target_m) == (s.action, s.alt_target_m)
        assert [c.q for c in d.children] == [c.q for c in s.children]


def test_the_route_is_kept_only_while_its_line_stays_out_of_the_nmac_volume() -> None:
    """Alerted by an aircraft 300 m ahead (5 s) passing 400 m to the side (outside the NMAC
    cylinder): the route's action at every seed. Passing 120 m to the side (inside the NMAC
    cylinder, outside the collision distance and its margin): the route's line has no meeting
    but an NMAC intrusion, so it is not kept (`mcts_daa`'s rule, a meeting only, would keep
    it), and the line flown goes less deep."""
    route = make_planner("none", CONFIG).plan(OWN, [_coming_south(1400.0, 300.0)], GOAL).action
    for seed in range(6):
        daa = make_planner("mcts_sep_daa", CONFIG)
        daa.reset(seed)
        wide = daa.plan(OWN, [_coming_south(1400.0, 300.0)], GOAL)
        line = next(c for c in wide.children if c.action == route)
        assert line.clear and wide.action == route
        daa = make_planner("mcts_sep_daa", CONFIG)
        daa.reset(seed)
        near = daa.plan(OWN, [_coming_south(1120.0, 300.0)], GOAL)
        line = next(c for c in near.children if c.action == route)
        assert line.meets is None and line.nmac_depth > 0 and not line.clear
        assert near.action != route and not near.route_kept
        chosen = next(c for c in near.children if c.action == near.action)
        assert chosen.nmac_depth < line.nmac_depth
        # decisions.jsonl says why the route was left: its line's NMAC depth, and none where 0
        rows = near.to_json()["children"]
        assert next(r for r in rows if r["action"]["index"] == route)["nmac_depth"] == (
            line.nmac_depth
        )
        for c, r in zip(near.children, rows, strict=True):
            assert ("nmac_depth" in r) == (c.nmac_depth > 0)


def test_a_line_is_clear_without_a_meeting_and_without_an_nmac_intrusion() -> None:
    base = ChildStats(action=4, bank_cmd_rad=0.0, accel_mps2=0.0, visits=1, q=0.5,
                      predicted_min_separation_m=300.0, closest_intruder=7)  # fmt: skip
    assert base.clear
    assert not dataclasses.replace(base, nmac_depth=0.2).clear
    meeting = Meeting(intruder=7, time_s=5.0, miss_m=40.0, needed_m=50.0)
    assert not dataclasses.replace(base, meets=meeting).clear


@pytest.mark.parametrize("name", ["mcts_daa", "mcts_vertical"])
def test_the_trees_that_grade_no_nmac_intrusion_report_none(name: str) -> None:
    """mcts_daa's keep rule is unchanged: its tree grades nothing, every line's depth is 0."""
    d = make_planner(name, CONFIG).plan(OWN, [_coming_south(1120.0, 300.0)], GOAL)
    assert d.tree is not None and d.tree.nmac_depth is None  # a tree was searched: it grades none
    assert all(c.nmac_depth == 0.0 for c in d.children)


def test_mcts_daa_flies_the_mean_backup_whatever_the_scenario_asks() -> None:
    """Its campaigns were flown with the mean backup: `avoidance.mcts.backup: best` would make
    another planner of it (planners._daa_config), so it is ignored there, and only there."""
    cfg = dataclasses.replace(CONFIG, backup="best")
    assert make_planner("mcts_daa", cfg).inner.config.backup == "mean"
    assert make_planner("mcts_sep_daa", cfg).inner.config.backup == "best"
