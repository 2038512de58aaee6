"""An operator on the ground station says where to go; avoidance stays on whatever it says.

Scripted operators (`operator.commands`) send real MAVLink frames (a ground station's
COMMAND_LONG / COMMAND_INT) through the bridge's decoder, in both command paths.
"""

from __future__ import annotations

import math

import pytest
from head_on import GOAL, HEAD_ON

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.scenario import ScenarioError, default_scenario, parse_scenario
from uavxai.sim.build import fly
from uavxai.sim.episode import Observer
from uavxai.sim.run import mavlink_path
from uavxai.sim.spec import episode_spec
from uavxai.vocabulary import Outcome


class Watch(Observer):
    """Per decision: time, height, airspeed, planner, words, (x, y)."""

    def __init__(self) -> None:
        self.rows: list[tuple] = []

    def on_decision(self, ep, event) -> None:
        s = event.truth
        self.rows.append((event.t, float(s.pos[0, 2]), float(s.airspeed[0]),
                          event.decision.planner, event.decision.explanation,
                          (float(s.pos[0, 0]), float(s.pos[0, 1]))))  # fmt: skip


def _fly(commands: list[dict], path=None, **changes):
    sc = default_scenario("operator", **{**HEAD_ON, **changes},
                          operator={"commands": commands})  # fmt: skip
    planner = make_planner(sc.avoidance.planner, PlannerConfig.from_scenario(sc))
    watch = Watch()
    kwargs = {"path": path(sc)} if path is not None else {}
    r = fly(episode_spec(sc, goal=GOAL, dynamics="kinematic"), planner, observers=[watch], **kwargs)
    return r, watch


def test_without_an_operator_the_head_on_encounter_is_avoided_as_before() -> None:
    r, _ = _fly([])
    assert r.outcome is Outcome.GOAL
    assert r.min_separation_m > 50.0
    assert "operator" not in r.summary


@pytest.mark.parametrize("via_mavlink", [False, True])
def test_operator_height_and_speed_during_a_head_on_encounter_keep_avoidance_on(
    via_mavlink: bool,
) -> None:
    """The issue's attack: one in-limits command used to switch avoidance off for 30 s and
    collide. Now the commands set the aim and the planner keeps deciding and sending."""
    commands = [{"t": 5, "speed_mps": 22}, {"t": 8, "altitude_m": 130}]
    path = (lambda sc: mavlink_path(sc, None)) if via_mavlink else None
    r, watch = _fly(commands, path=path)
    assert r.outcome is Outcome.GOAL
    assert r.min_separation_m > 50.0
    # every decision is the planner's own, none is advice
    assert all(row[3] == "mcts_fast" for row in watch.rows), {row[3] for row in watch.rows}
    assert len(watch.rows) == r.steps
    if via_mavlink:
        assert r.summary["bridge"]["failsafe_events"] == 0
        assert r.summary["bridge"]["operator_commands"] == 2
    # the aims were flown: the height the operator asked for, the speed held when holding
    t_end, h_end, v_end, *_ = watch.rows[-1]
    assert abs(h_end - 130.0) < 3.0, h_end
    assert abs(v_end - 22.0) < 1.5, v_end
    # and never faster than asked once slowed to it (the avoidance may fly below it)
    assert max(row[2] for row in watch.rows if row[0] >= 15) < 22.6
    # the explanations open with the operator's aim
    later = [row[4] for row in watch.rows if row[0] >= 9]
    assert later and all(w.startswith("the operator asked for 130 m") for w in later), later[0]
    ops = r.summary["operator"]["commands"]
    assert [c["kind"] for c in ops] == ["speed", "altitude"]


def test_guided_goto_then_rtl_completes_at_home() -> None:
    """GUIDED to a point (DO_REPOSITION), where it loiters; then RTL ends the flight home."""
    commands = [{"t": 2, "goto": [1400, 1000, 150]}, {"t": 80, "mode": "RTL"}]
    r, watch = _fly(commands, intruders={"count": 0}, avoidance={"planner": "mcts_fast",
                    "max_steps": 300})  # fmt: skip
    assert r.outcome is Outcome.COMPLETED, r.outcome
    assert r.summary["operator"]["mode_end"] == "RTL"
    # it went to the point, climbed to 150 m, and loitered about it (the planner flying the
    # circle) until RTL, every decision saying what the operator asked for
    near = [row for row in watch.rows if 40 <= row[0] <= 78]
    assert near and all(row[4].startswith("the operator asked for go to") for row in near)
    assert all(math.dist(row[5], (1400, 1000)) < 300 for row in near)
    assert any(abs(row[1] - 150.0) < 5.0 for row in near)
    assert r.flight_time_s > 80.0


def test_a_goal_is_not_reached_in_passing_while_the_operator_flies_elsewhere() -> None:
    """The scenario's goal ends the episode only while the scenario's flight is flown."""
    commands = [{"t": 1, "mode": "LOITER"}, {"t": 60, "mode": "AUTO"}]
    r, watch = _fly(commands, intruders={"count": 0})
    assert r.outcome is Outcome.GOAL
    assert r.flight_time_s > 60.0
    # it loitered about where it was at t = 1 s, passing nowhere near the goal 1.2 km north
    loitering = [row for row in watch.rows if 20 <= row[0] <= 59]
    assert loitering and all(math.dist(row[5], (1000, 720)) < 300 for row in loitering)
    assert all(row[4].startswith("the operator asked for mode LOITER") for row in loitering)


def test_scripted_operator_commands_are_validated() -> None:
    with pytest.raises(ScenarioError, match="exactly one of"):
        parse_scenario({"name": "x", "operator": {"commands": [{"t": 1}]}})
    with pytest.raises(ScenarioError, match="exactly one of"):
        parse_scenario({"name": "x", "operator": {"commands": [
            {"t": 1, "altitude_m": 100, "speed_mps": 20}]}})  # fmt: skip
    with pytest.raises(ScenarioError, match="override_s was removed"):
        parse_scenario({"name": "x", "bridge": {"override_s": 30}})
    with pytest.raises(ScenarioError, match="IP address"):
        parse_scenario({"name": "x", "bridge": {"ground_stations": [{"address": "gcs"}]}})
    with pytest.raises(ScenarioError):
        parse_scenario({"name": "x", "operator": {"commands": [{"t": 1, "mode": "FBWA"}]}})


def test_the_same_scripted_flight_repeats_exactly() -> None:
    commands = [{"t": 5, "speed_mps": 25}, {"t": 10, "orbit": {"x": 1100, "y": 1200,
                "h": 140, "radius_m": 150}}]  # fmt: skip
    a, wa = _fly(commands)
    b, wb = _fly(commands)
    assert a.outcome == b.outcome and a.steps == b.steps
    assert [r[:3] for r in wa.rows] == [r[:3] for r in wb.rows]
    assert math.isfinite(a.min_separation_m)


def test_the_recording_shows_the_operators_modes_as_phases(tmp_path) -> None:
    """rerun (a real .rrd read back): while the operator's mode flies, the phase log and the
    phase plot say so ("GUIDED (operator)", then "RTL (operator)")."""
    import numpy as np
    from rerun.chunk import RrdReader

    from uavxai.recording.recorder import RunRecorder
    from uavxai.sim.observers import Rerun

    sc = default_scenario("operator", **{**HEAD_ON, "intruders": {"count": 0}},
                          operator={"commands": [{"t": 2, "goto": [1400, 1000, 150]},
                                                 {"t": 40, "mode": "RTL"}]})  # fmt: skip
    planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
    rrd = tmp_path / "run.rrd"
    setup = {"bounds": {"x": sc.world.x, "y": sc.world.y, "h": sc.world.h}, "origin": None,
             "users": np.zeros((0, 3)), "service_point": None, "search_path": None}  # fmt: skip
    rec = Rerun(RunRecorder(rrd), setup)
    fly(episode_spec(sc, goal=GOAL, dynamics="kinematic"), planner, observers=[rec])
    texts = []
    for chunk in RrdReader(str(rrd)).stream().to_chunks():
        if chunk.entity_path == "/mission/phase":
            batch = chunk.to_record_batch()
            for name in batch.schema.names:
                if name.endswith("TextLog:text"):
                    texts += [v for row in batch.column(name).to_pylist() for v in (row or [])]
    assert texts == ["phase: GUIDED (operator)", "phase: RTL (operator)"], texts


@pytest.mark.parametrize("world_kind", ["kinematic", "jsbsim"])
def test_an_operators_airspeed_is_a_ceiling_the_planner_may_slow_below(world_kind: str) -> None:
    """DO_CHANGE_SPEED lowers the autopilot's top speed: a speed-up asked for above it is
    flown at it, a slow-down below it is flown; raising it lets the speed-up through again."""
    from uavxai.dynamics.world import JSBSimWorld
    from uavxai.sim.kinematic import KinematicWorld
    from uavxai.sim.manoeuvres import flight_test_scenario

    world = (JSBSimWorld if world_kind == "jsbsim" else KinematicWorld)(
        flight_test_scenario(25.0))
    try:
        world.advance(2.0)
        world.command_ownship(speed_target_mps=18.0, speed_max_mps=18.0)
        world.command_ownship(accel_cmd_mps2=1.0)  # the planner asks to speed up: held at 18
        top = 0.0
        for _ in range(30):
            world.advance(1.0)
            top = max(top, float(world.state().airspeed[0])) if world.t > 14 else top
        assert 17.0 < float(world.state().airspeed[0]) < 18.6
        assert top < 18.6, top
        world.command_ownship(accel_cmd_mps2=-1.0)  # slowing below the ceiling is flown
        world.advance(4.0)
        assert float(world.state().airspeed[0]) < 16.5
        world.command_ownship(speed_max_mps=30.0, accel_cmd_mps2=1.0)  # the ceiling raised
        world.advance(12.0)
        assert float(world.state().airspeed[0]) > 22.0
        assert world.failure() is None
    finally:
        world.close()
