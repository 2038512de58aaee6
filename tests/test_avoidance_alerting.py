"""The alerting stage of `mcts_daa` (issue 27, part 3): quiet until an intruder is predicted
inside well clear within the alerting time, then the tree; the alert holds a while."""

from __future__ import annotations

import math

import pytest

from uavxai.avoidance.alerting import threats
from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import Intruder, Ownship, PlannerConfig

WC = (609.6, 76.2)
OWN = Ownship(x=1000.0, y=0.0, h=120.0, speed=25.0, heading=0.0)  # north at 25 m/s
GOAL = (1000.0, 2000.0, 120.0)


def _head_on(distance_m: float, dh: float = 0.0, **kw) -> Intruder:
    """A GA aircraft dead ahead, coming south at 35 m/s: 60 m/s of closure."""
    return Intruder(id=7, x=1000.0, y=distance_m, h=120.0 + dh, vx=0.0, vy=-35.0, **kw)


@pytest.mark.parametrize(
    ("distance", "dh", "alerted"),
    [(3500.0, 0.0, True),  # inside well clear at (3500 - 609.6) / 60 = 48 s < 55 s
     (4000.0, 0.0, False),  # at 56.5 s: beyond the alerting time
     (3500.0, 80.0, False),  # 80 m above: outside the 76.2 m of height
     (-1000.0, 0.0, False)],  # behind and going away
)  # fmt: skip
def test_an_alert_is_a_predicted_loss_of_well_clear_within_the_horizon(
    distance: float, dh: float, alerted: bool
) -> None:
    found = threats(OWN, [_head_on(distance, dh)], 55.0, WC, 2.0)
    assert bool(found) is alerted
    if alerted:
        assert found[0].id == 7
        assert found[0].t_enter_s == pytest.approx((distance - WC[0]) / 60.0, abs=0.5)
        assert found[0].hmd_m == pytest.approx(max(distance - 60.0 * 55.0, 0.0), abs=1.0)


def test_an_uncertain_track_alerts_earlier() -> None:
    """4 km ahead is no alert for a sure track, an alert for one whose velocity is known to
    3 m/s (the cylinder widens by 2 sigma as the error grows)."""
    assert not threats(OWN, [_head_on(4000.0)], 55.0, WC, 2.0)
    assert threats(OWN, [_head_on(4000.0, sigma_v=3.0)], 55.0, WC, 2.0)


def _planner():
    return make_planner("mcts_daa", PlannerConfig(x_bounds=(0, 2000), y_bounds=(-500, 4500)))


def test_quiet_without_a_threat_the_nominal_route_and_says_so() -> None:
    planner = _planner()
    nominal = make_planner("none", planner.config)
    far = [_head_on(4500.0)]
    d = planner.plan(OWN, far, GOAL, step=0)
    n = nominal.plan(OWN, far, GOAL, step=0)
    assert (d.bank_cmd_rad, d.accel_mps2) == (n.bank_cmd_rad, n.accel_mps2)
    assert d.alt_target_m == GOAL[2]  # back at the leg's height
    assert d.children == [] and d.tree is None
    assert d.planner == "mcts_daa"
    assert d.words[0].startswith("clear of traffic: no intruder predicted within 610 m")
    assert "nearest intruder 7 at 4500 m" in d.words[0]


def test_a_threat_hands_the_decision_to_the_tree_and_the_alert_holds() -> None:
    planner = _planner()
    d = planner.plan(OWN, [_head_on(1500.0)], GOAL, step=0)
    assert d.tree is not None and len(d.children) > 0
    assert d.planner == "mcts_daa"
    # the threat gone (passed behind): the tree keeps deciding for alert_hold_s (5 s) ...
    hold = planner.config.alert_hold_s
    gone = [_head_on(-2000.0)]
    steps = [planner.plan(OWN, gone, GOAL, step=k) for k in range(1, 1 + math.ceil(hold) + 1)]
    searched = [s.tree is not None for s in steps]
    assert searched[: int(hold) - 1] == [True] * (int(hold) - 1)
    # ... and then the ownship flies its route again
    assert searched[-1] is False


def test_the_same_inputs_give_the_same_decisions() -> None:
    a, b = _planner(), _planner()
    pic = [_head_on(1500.0)]
    da, db = a.plan(OWN, pic, GOAL), b.plan(OWN, pic, GOAL)
    assert (da.action, da.bank_cmd_rad, da.alt_target_m) == (db.action, db.bank_cmd_rad,
                                                             db.alt_target_m)  # fmt: skip


def test_an_alerted_tree_keeps_the_route_while_the_route_line_is_clear() -> None:
    """Alerted by an aircraft that will pass 400 m to the side (inside well clear, outside the
    tree's conflict distance): the route's action, at every seed. The plain vertical tree,
    free to prefer any of the clear lines, leaves the route at some seed (what the encounter
    campaigns counted as unnecessary manoeuvres)."""
    import uavxai.xai  # noqa: F401  (the narrator)

    side = Intruder(id=7, x=1400.0, y=3000.0, h=120.0, vx=0.0, vy=-35.0)
    config = PlannerConfig(x_bounds=(0, 2000), y_bounds=(-500, 4500))
    route = make_planner("none", config).plan(OWN, [side], GOAL).action
    daa, free = make_planner("mcts_daa", config), make_planner("mcts_vertical", config)
    kept, left = [], []
    for seed in range(8):
        daa.reset(seed)
        free.reset(seed)
        d = daa.plan(OWN, [side], GOAL)
        assert d.children, "the alert hands the decision to the tree"
        assert next(c for c in d.children if c.action == route).meets is None
        kept.append(d.action == route)
        free_d = free.plan(OWN, [side], GOAL)
        left.append(free_d.action != route)
        # said as what it is: the route rule, not the search, chose (when they differ)
        assert d.route_kept == (free_d.action != route)
        assert not free_d.route_kept
        if d.route_kept:
            assert "keeps to its route" in d.explanation
            assert "has no conflict to avoid" in d.counterfactual
            assert "agree" not in d.explanation
    assert all(kept)
    assert any(left)


def test_an_alerted_tree_leaves_the_route_when_it_conflicts_and_avoids_the_nmac_radius() -> None:
    """Head on, 900 m (15 s): the route's line meets the intruder; the tree turns or climbs
    away, and its conflict distance is the smallest sphere holding the NMAC cylinder
    (avoidance.nmac): the cylinder's rim, not its radius (a line at 150 m and 30 m is an NMAC
    that a 152.4 m sphere lets through)."""
    config = PlannerConfig(x_bounds=(0, 2000), y_bounds=(-500, 4500), nmac_m=(200.0, 30.0))
    daa = make_planner("mcts_daa", config)
    route = make_planner("none", config).plan(OWN, [_head_on(900.0)], GOAL).action
    d = daa.plan(OWN, [_head_on(900.0)], GOAL)
    assert d.d_min_m == pytest.approx(math.hypot(200.0, 30.0))
    assert next(c for c in d.children if c.action == route).meets is not None
    assert d.action != route


def test_the_scenario_sets_the_nmac_and_well_clear_cylinders_of_the_planner() -> None:
    from uavxai.paths import scenarios_dir
    from uavxai.scenario import load_scenario

    sc = load_scenario(scenarios_dir() / "encounters.yaml")
    a = sc.avoidance.model_copy(update={
        "nmac": sc.avoidance.nmac.model_copy(update={"horizontal_m": 180.0}),
        "well_clear": sc.avoidance.well_clear.model_copy(update={"vertical_m": 90.0}),
    })  # fmt: skip
    config = PlannerConfig.from_scenario(sc.model_copy(update={"avoidance": a}))
    assert config.nmac_m == (180.0, 30.48) and config.alert_well_clear_m == (609.6, 90.0)
    assert make_planner("mcts_daa", config).inner.config.d_min_m == pytest.approx(
        math.hypot(180.0, 30.48))


def test_after_a_route_conflict_the_route_is_held_again_only_once_clear_for_the_hold() -> None:
    """Hysteresis: once the route's line has conflicted, the tree chooses freely until that
    line has been clear for alert_hold_s (5 decisions of 1 s); from then on the route again.
    Without it a line grazing the conflict distance rocks the wings left and right."""
    config = PlannerConfig(x_bounds=(0, 2000), y_bounds=(-500, 4500))
    side = [Intruder(id=7, x=1400.0, y=3000.0, h=120.0, vx=0.0, vy=-35.0)]
    route = make_planner("none", config).plan(OWN, side, GOAL).action
    free_in_hold, after = [], []
    for seed in range(8):
        daa = make_planner("mcts_daa", config)
        daa.reset(seed)
        assert daa.plan(OWN, [_head_on(900.0)], GOAL).children  # the route's line conflicts
        decisions = [daa.plan(OWN, side, GOAL) for _ in range(8)]
        assert all(d.children for d in decisions), "alerted throughout: the tree decides"
        free_in_hold.append(any(d.action != route for d in decisions[:5]))
        after += [d.action for d in decisions[5:]]
    assert any(free_in_hold)
    assert all(a == route for a in after)


def test_a_quiet_spell_ends_the_route_count() -> None:
    """The route's conflict is forgotten once the alert goes quiet (the ownship flies its
    route then): a new alert keeps the route from its first decision."""
    config = PlannerConfig(x_bounds=(0, 2000), y_bounds=(-500, 4500))
    side = [Intruder(id=7, x=1400.0, y=3000.0, h=120.0, vx=0.0, vy=-35.0)]
    far = [_head_on(4500.0)]  # no threat: quiet
    route = make_planner("none", config).plan(OWN, side, GOAL).action
    for seed in range(8):
        daa = make_planner("mcts_daa", config)
        daa.reset(seed)
        daa.plan(OWN, [_head_on(900.0)], GOAL)  # the route's line conflicts
        quiet = [daa.plan(OWN, far, GOAL) for _ in range(int(config.alert_hold_s) + 2)]
        assert not quiet[-1].children, "the alert has gone quiet"
        d = daa.plan(OWN, side, GOAL)
        assert d.children and d.action == route
