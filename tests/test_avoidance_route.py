"""The route layer above the tree (uavxai.avoidance.route): the goal itself when the straight
route is clear or the goal is near, a waypoint around traffic that blocks the straight route,
never a leg out of the area, and `mcts_route` flies an episode deterministically."""

from __future__ import annotations

import math

import pytest
from engine_runs import flown_twice

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.route import ROUTE_HORIZON_S, leg_costs, route_goal
from uavxai.avoidance.types import Intruder, Ownship, PlannerConfig

CFG = PlannerConfig()  # the default 2 km box, d_min 50 m
GOAL = (1900.0, 1000.0, 120.0)


def _own(x: float = 200.0, y: float = 1000.0) -> Ownship:
    return Ownship(x=x, y=y, h=120.0, speed=20.0, heading=math.pi / 2)  # due east


def _wall_of_traffic() -> list[Intruder]:
    """Five intruders parked (slowly) across the straight route, 400 m ahead."""
    return [Intruder(id=f"i{k}", x=600.0, y=900.0 + 50.0 * k, h=120.0, vx=0.0, vy=0.1, vh=0.0)
            for k in range(5)]  # fmt: skip


def test_a_clear_route_and_a_near_goal_keep_the_goal() -> None:
    assert route_goal(_own(), [], GOAL, CFG) == GOAL
    near = _own(x=GOAL[0] - 20.0 * ROUTE_HORIZON_S + 10.0)
    assert route_goal(near, _wall_of_traffic(), GOAL, CFG) == GOAL


def test_traffic_across_the_route_moves_the_waypoint_off_it() -> None:
    wp = route_goal(_own(), _wall_of_traffic(), GOAL, CFG)
    assert wp != GOAL
    # the leg's end is one leg out, and off the blocked band y in [900, 1100] +- 2 d_min
    assert math.hypot(wp[0] - 200.0, wp[1] - 1000.0) == pytest.approx(600.0)
    assert abs(wp[1] - 1000.0) > 150.0


def test_legs_that_leave_the_area_are_ruled_out() -> None:
    corner = Ownship(x=1950.0, y=1950.0, h=120.0, speed=20.0, heading=math.pi / 4)
    cost = leg_costs(corner, [], (100.0, 100.0, 120.0), CFG)
    assert math.isinf(cost[0])  # north-east, straight out of the box
    assert math.isfinite(cost.min())


def test_mcts_route_flies_an_episode_the_same_twice() -> None:
    from uavxai.scenario import default_scenario

    sc = default_scenario("route", intruders={"behaviour": "random_turns"},
                          avoidance={"max_steps": 30}, ownship={"goal": [1000, 1000, 120]})
    a, b = flown_twice(sc, "mcts_route", 20, 4)
    assert a["method"] == "mcts_route" and a["steps"] > 0 and a == b
    assert make_planner("mcts_route", CFG).name == "mcts_route"
