"""Observers only observe, engine steps act (issue 29): what ends the mission (the battery) and
moves the station (the service) are engine steps with a declared place in the loop, so the
order the observers are given in changes nothing a run writes or sums up."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.comms.channel import Channel
from uavxai.scenario import default_scenario
from uavxai.service.stage import plan_service
from uavxai.sim.build import fly
from uavxai.sim.observers import SummaryJSON
from uavxai.sim.run import run_parts
from uavxai.sim.spec import episode_spec
from uavxai.sim.steps import Energy

# Wall-clock numbers: the same flight measures them anew.
TIMING = ("decision_ms", "sim_realtime_factor")
# A JSBSim mission (a battery) whose users walk, so that the service re-plans and moves the
# station while the other outputs watch.
SCENARIO = default_scenario(
    "order",
    seed=4,
    intruders={"count": 0},
    avoidance={"planner": "none"},
    comms={"access": "ofdma", "users": {"mobility": {"model": "random_waypoint",
                                                     "speed_mps": [1.5, 2.0]}}},
    service={"replan_s": 10},
    mission={"service_s": 30, "return_home": False},
    log={"rerun": False},
)  # fmt: skip


def _fly(out: Path, reverse: bool) -> dict:
    """The run's own steps and observers (sim/run.py: run_parts), its summary.json too."""
    sc = SCENARIO
    plan = plan_service(sc)
    spec = episode_spec(sc, goal=plan.service_point, dynamics="jsbsim", mission=True)
    channel = Channel.from_scenario(sc, users=plan.users)
    steps, observers = run_parts(spec, channel, plan.power_w, out)
    observers.append(SummaryJSON(out / "summary.json", {"point": list(plan.service_point)}))
    assert [type(s).__name__ for s in steps] == ["Energy", "Service"]
    if reverse:
        observers.reverse()
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    r = fly(spec, planner, observers=observers, engine_steps=steps)
    return {k: v for k, v in r.summary.items() if k not in TIMING}


def test_the_observers_order_changes_nothing(tmp_path: Path) -> None:
    forward, backward = tmp_path / "forward", tmp_path / "backward"
    forward.mkdir()
    backward.mkdir()
    a, b = _fly(forward, reverse=False), _fly(backward, reverse=True)
    # the flight did what the steps do: energy drawn, the station moved at least once
    assert a["energy"]["energy_wh"] > 0
    assert len({tuple(p[1:]) for p in a["mission"]["service_points"]}) >= 2
    assert a["mission"]["energy_wh"] == a["energy"]["energy_wh"]
    assert a == b
    written = [json.loads((d / "summary.json").read_text()) for d in (forward, backward)]
    for s in written:
        for k in TIMING:
            s.pop(k)
    assert written[0] == written[1] == json.loads(json.dumps(a))
    for name in ("trajectory.csv", "users.csv", "service.csv"):
        assert (forward / name).read_bytes() == (backward / name).read_bytes(), name


def test_a_step_given_as_an_observer_is_refused() -> None:
    sc = default_scenario("refused", intruders={"count": 0})
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    spec = episode_spec(sc, goal=(1000.0, 1000.0, 120.0), dynamics="kinematic")
    with pytest.raises(TypeError, match="Energy act on the episode: give them as engine_steps"):
        fly(spec, planner, observers=[Energy()])
