"""The flight-quality columns (issue 31): path excess, bank reversals per minute, steep bank."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.avoidance import PlannerConfig, make_planner
from uavxai.daa_metrics import reversals
from uavxai.dynamics.state import TrafficState
from uavxai.sim.flight_quality import FlightQuality


class _Decision:
    def __init__(self, bank: float) -> None:
        self.bank_cmd_rad = bank


class _Event:
    def __init__(self, bank: float) -> None:
        self.decision = _Decision(bank)


def _state(t: float, pos, phi_deg: float) -> TrafficState:
    return TrafficState(t=t, ids=("ownship",), pos=np.array([pos], float),
                        vel=np.zeros((1, 3)), att=np.array([[math.radians(phi_deg), 0, 0]]),
                        airspeed=np.array([20.0]))  # fmt: skip


def _fly(points, phis, banks, route=((0, 0, 100), (1000, 0, 100))) -> FlightQuality:
    q = FlightQuality(route)
    for k, (p, phi) in enumerate(zip(points, phis, strict=True)):
        q.on_sample(None, _state(float(k), p, phi))
    for b in banks:
        q.on_decision(None, _Event(b))
    return q


def test_a_straight_level_flight_is_perfect() -> None:
    q = _fly([(20.0 * k, 0, 100) for k in range(61)], [0.0] * 61, [0.0] * 60).result()
    assert q.path_excess == pytest.approx(0.0, abs=1e-12)
    assert q.reversals_per_min == 0.0 and q.bank_over_25_s == 0.0


def test_a_dogleg_counts_its_extra_path_reversals_and_steep_bank() -> None:
    # east 300 m, then 45 deg off for 400 m, then back parallel: progress 300 + 400/sqrt2 + 300
    pts = [(0, 0, 100), (300, 0, 100), (300 + 400 / math.sqrt(2), 400 / math.sqrt(2), 100),
           (600 + 400 / math.sqrt(2), 400 / math.sqrt(2), 100)]  # fmt: skip
    phis = [0.0, 30.0, -26.0, 10.0]  # 2 of the 3 one-second intervals steeper than 25 deg
    banks = [0.3, 0.0, -0.3, 0.3, 0.1]  # right, left, right: 2 reversals
    q = _fly(pts, phis, banks).result()
    progress = 600 + 400 / math.sqrt(2)
    assert q.path_excess == pytest.approx(1000 / progress - 1)
    assert q.reversals_per_min == pytest.approx(2 / (3 / 60))
    assert q.bank_over_25_s == pytest.approx(2.0)


def test_a_mission_has_no_route_and_no_progress_gives_nan() -> None:
    pts = [(0, 0, 100), (10, 0, 100)]
    assert math.isnan(_fly(pts, [0, 0], [], route=None).result().path_excess)
    back = [(0, 0, 100), (-10, 0, 100)]  # flew away from the goal
    assert math.isnan(_fly(back, [0, 0], []).result().path_excess)


def test_an_avoiding_kinematic_episode_reports_what_it_flew() -> None:
    """On the engine: a head-on with one intruder makes the tree turn off the line and back,
    which costs path and bank; the `none` planner flying the same start has neither."""
    from uavxai.scenario import IntruderSpec, default_scenario
    from uavxai.sim.build import fly
    from uavxai.sim.spec import episode_spec

    sc = default_scenario().model_copy(deep=True)
    start = sc.ownship.start
    goal = (start.x + 1500.0 * math.sin(start.heading_deg * math.pi / 180),
            start.y + 1500.0 * math.cos(start.heading_deg * math.pi / 180), start.h)
    intruder = IntruderSpec(x=goal[0], y=goal[1], h=start.h,
                            heading_deg=(start.heading_deg + 180.0) % 360.0, speed_mps=20.0)
    got = {}
    for method in ("none", "mcts"):
        q = FlightQuality(((start.x, start.y, start.h), goal))
        planner = make_planner(method, PlannerConfig.from_scenario(sc))
        fly(episode_spec(sc, goal=goal, intruders=[intruder]), planner, observers=[q])
        got[method] = q.result()
    assert got["none"].path_excess < 0.01 and got["none"].bank_over_25_s == 0.0
    assert got["mcts"].path_excess > got["none"].path_excess


def test_campaign_rows_and_results_carry_the_flight_quality() -> None:
    """`evaluate`'s rows have the three columns (an encounter campaign's path excess is the
    encounter record's, by the same definition) and its results their median / means."""
    from uavxai.campaign import FLIGHT_COLUMNS, run_campaign, summarise
    from uavxai.paths import scenarios_dir
    from uavxai.scenario import default_scenario, load_scenario
    from uavxai.sim.encounter import fly_encounter

    rows = run_campaign(default_scenario(), ["none", "mcts_fast"], [10], 3)
    for r in rows:
        assert all(k in r for k in FLIGHT_COLUMNS)
        assert r["bank_over_25_s"] >= 0 and r["reversals_per_min"] >= 0
    results = {r["method"]: r for r in summarise(rows)}
    for method in ("none", "mcts_fast"):
        mine = [r for r in rows if r["method"] == method]
        excess = [r["path_excess"] for r in mine if math.isfinite(r["path_excess"])]
        got = results[method]
        assert got["median_path_excess"] == pytest.approx(float(np.median(excess)))
        assert got["mean_reversals_per_min"] == pytest.approx(
            float(np.mean([r["reversals_per_min"] for r in mine])))
        assert got["mean_bank_over_25_s"] == pytest.approx(
            float(np.mean([r["bank_over_25_s"] for r in mine])))

    enc = load_scenario(scenarios_dir() / "encounters.yaml")
    from uavxai.campaign import run_campaign_episode
    from uavxai.campaign.episode import planner_for

    row = run_campaign_episode(enc, "mcts_fast", 1, 5)
    quality = FlightQuality(((-3000.0, 0.0, 120.0), enc.ownship.goal))  # the file's route
    _, rec, _ = fly_encounter(enc, planner_for(enc, "mcts_fast"), 5, quality=quality)
    assert row["path_excess"] == pytest.approx(quality.result().path_excess, abs=1e-4)
    assert row["reversals"] == rec.reversals == reversals(quality.bank_cmd)
    assert len(quality.own) == len(quality.t) > 1
