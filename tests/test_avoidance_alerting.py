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
