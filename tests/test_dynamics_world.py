"""The multi-aircraft JSBSim world: initial conditions, lockstep time, commands, determinism,
intruder behaviours, failures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.dynamics.aircraft import BANK_LIMIT
from uavxai.dynamics.state import TrafficState
from uavxai.dynamics.traffic import draw_intruders
from uavxai.dynamics.world import JSBSimWorld, jsbsim_seed
from uavxai.errors import UserError
from uavxai.scenario import IntruderSpec, default_scenario


def _scenario(count: int = 3, behaviour: str = "straight", seed: int = 0, **kw):
    return default_scenario(
        "world-test", seed=seed, intruders={"count": count, "behaviour": behaviour}, **kw
    )


def _fly(world: JSBSimWorld, seconds: float, every_s: float = 0.5) -> list[TrafficState]:
    states = [world.state()]
    for _ in range(round(seconds / every_s)):
        world.advance(every_s)
        states.append(world.state())
    return states


def test_initial_state_is_the_scenario_start() -> None:
    sc = _scenario(count=4)
    specs = draw_intruders(sc, np.random.default_rng(sc.seed))
    with JSBSimWorld(sc) as w:
        s = w.state()
        assert s.ids == ("ownship", "intruder-1", "intruder-2", "intruder-3", "intruder-4")
        assert s.pos.shape == s.vel.shape == s.att.shape == (5, 3)
        assert w.t == 0.0 and s.t == 0.0
        assert all(w.trimmed)
        st = sc.ownship.start
        expected = [(st.x, st.y, st.h, st.heading_deg, st.speed_mps)] + [
            (p.x, p.y, p.h, p.heading_deg, p.speed_mps) for p in specs
        ]
        for i, (x, y, h, heading_deg, speed) in enumerate(expected):
            np.testing.assert_allclose(s.pos[i], (x, y, h), atol=1e-3)
            assert s.airspeed[i] == pytest.approx(speed, abs=1e-3)
            assert math.degrees(s.att[i, 2]) == pytest.approx(heading_deg % 360, abs=1e-6)
            psi = math.radians(heading_deg)
            np.testing.assert_allclose(
                s.vel[i], (speed * math.sin(psi), speed * math.cos(psi), 0.0), atol=1e-3
            )
            assert abs(s.att[i, 0]) < 1e-3  # wings level


def test_geodetic_round_trip_through_the_origin() -> None:
    with JSBSimWorld(_scenario(count=0)) as w:
        fdm = w.aircraft[0].fdm
        lat, lon = fdm["position/lat-geod-deg"], fdm["position/long-gc-deg"]
        x, y, _ = w.frame.to_local(lat, lon, 0.0)
        start = w.scenario.ownship.start
        assert (float(x), float(y)) == pytest.approx((start.x, start.y), abs=1e-3)
        ground_ft = fdm["position/terrain-elevation-asl-ft"]
        assert ground_ft * 0.3048 == pytest.approx(w.origin.alt_m, abs=1e-6)


def test_steady_from_t0_and_moves_at_its_speed() -> None:
    with JSBSimWorld(_scenario(count=2)) as w:
        s0 = w.state()
        w.advance(10.0)
        s1 = w.state()
        assert w.t == pytest.approx(10.0)
        travelled = np.linalg.norm(s1.pos[:, :2] - s0.pos[:, :2], axis=1)
        np.testing.assert_allclose(travelled, 10.0 * s0.airspeed, rtol=0.01)
        np.testing.assert_allclose(s1.pos[:, 2], s0.pos[:, 2], atol=0.5)
        np.testing.assert_allclose(s1.airspeed, s0.airspeed, atol=0.2)


def test_step_and_advance_count_integration_steps() -> None:
    sc = _scenario(count=1, dynamics={"rate_hz": 100})
    with JSBSimWorld(sc) as w:
        assert w.dt == pytest.approx(0.01)
        w.step(7)
        assert w.t == pytest.approx(0.07)
        w.advance(1.0)
        assert w.t == pytest.approx(1.07)
        assert w.aircraft[1].fdm.get_sim_time() == pytest.approx(1.07)


def test_same_seed_gives_bit_identical_trajectories() -> None:
    def run(seed: int) -> np.ndarray:
        with JSBSimWorld(_scenario(count=4, behaviour="random_turns", seed=seed)) as w:
            out = []
            for k, s in enumerate(_fly(w, 20.0, every_s=1.0)):
                if k == 5:
                    w.command_ownship(bank_cmd_rad=0.3, accel_cmd_mps2=0.5)
                out.append(np.concatenate((s.pos, s.vel, s.att), axis=1).ravel())
            return np.array(out)

    a, b, c = run(7), run(7), run(8)
    assert np.array_equal(a, b)  # bit for bit
    assert a.shape == c.shape and not np.allclose(a, c)


def test_seeds_reach_jsbsim() -> None:
    with JSBSimWorld(_scenario(count=2, seed=11)) as w:
        seeds = [a.fdm["simulation/randomseed"] for a in w.aircraft]
    assert seeds == [jsbsim_seed(11, i) for i in range(3)]
    assert len(set(seeds)) == 3


def test_explicit_intruders_replace_the_draw() -> None:
    spec = IntruderSpec(x=900, y=900, h=130, heading_deg=270, speed_mps=18, behaviour="straight")
    with JSBSimWorld(_scenario(count=5), intruders=[spec]) as w:
        s = w.state()
        assert s.n == 2
        np.testing.assert_allclose(s.pos[1], (900, 900, 130), atol=1e-3)


def test_command_ownship_reaches_the_autopilot() -> None:
    with JSBSimWorld(_scenario(count=0)) as w:
        w.command_ownship(bank_cmd_rad=0.2, alt_target_m=140.0)
        cmd = w.ownship_command()
        assert cmd["bank_cmd_rad"] == pytest.approx(0.2)
        assert cmd["alt_target_m"] == pytest.approx(140.0)
        assert cmd["accel_cmd_mps2"] == 0.0
        w.command_ownship(accel_cmd_mps2=1.0)  # the others unchanged
        w.advance(3.0)
        cmd = w.ownship_command()
        assert cmd["bank_cmd_rad"] == pytest.approx(0.2)
        assert cmd["speed_target_mps"] == pytest.approx(23.0, abs=0.05)
        s = w.state()
        assert s.att[0, 0] == pytest.approx(0.2, abs=0.01)
        assert s.pos[0, 2] > 121.0  # climbing towards 140 m
        w.command_ownship(speed_target_mps=15.0, accel_cmd_mps2=0.0)
        assert w.ownship_command()["speed_target_mps"] == 15.0


def test_ownship_limits_come_from_the_scenario() -> None:
    sc = _scenario(count=0, avoidance={"bank_limit_deg": 20, "speed_mps": [14, 25]})
    with JSBSimWorld(sc) as w:
        w.command_ownship(bank_cmd_rad=math.radians(45), speed_target_mps=40.0)
        w.advance(8.0)
        s = w.state()
        assert math.degrees(s.att[0, 0]) == pytest.approx(20.0, abs=0.5)
        assert w.ownship_command()["speed_target_mps"] == pytest.approx(25.0)


def test_intruders_autopilots_keep_their_aircrafts_bank_limit() -> None:
    # the ownship's 20 deg is the ownship's; an intruder's autopilot keeps its XML's 30
    sc = _scenario(count=2, avoidance={"bank_limit_deg": 20})
    with JSBSimWorld(sc) as w:
        own, *intruders = w.aircraft
        assert own.fdm[BANK_LIMIT] == pytest.approx(math.radians(20.0))
        for a in intruders:
            assert a.fdm[BANK_LIMIT] == pytest.approx(math.radians(30.0))


def test_bad_commands_and_speeds_are_user_errors() -> None:
    with JSBSimWorld(_scenario(count=0)) as w, pytest.raises(UserError, match="bank_cmd_rad"):
        w.command_ownship(bank_cmd_rad=float("nan"))
    fast = IntruderSpec(x=900, y=900, h=130, heading_deg=0, speed_mps=70)
    with pytest.raises(UserError, match="intruder 1 speed_mps = 70 m/s.*between 12 and 30"):
        JSBSimWorld(_scenario(), intruders=[fast])
    # the scenario schema refuses these already (same numbers, read from the aircraft XML)
    with pytest.raises(UserError, match="ownship.start.speed_mps"):
        JSBSimWorld(_scenario(count=0, ownship={"start": {"speed_mps": 8}}))
    with pytest.raises(UserError, match="avoidance.speed_mps"):
        JSBSimWorld(_scenario(count=0, avoidance={"speed_mps": [40, 50]}))


def test_intruder_behaviours_are_flown() -> None:
    sc = default_scenario(
        "behaviours",
        seed=3,
        intruders={"count": 0, "flow": "none"},  # the straight one leaves: keep watching it
        ownship={"start": {"x": 100, "y": 100}},
    )
    specs = [
        IntruderSpec(x=1000, y=1000, h=120, heading_deg=0, speed_mps=20, behaviour=b)
        for b in ("straight", "random_turns", "goal_seeking")
    ]
    with JSBSimWorld(sc, intruders=specs) as w:
        states = _fly(w, 60.0)
        goal = w._pilots[2].goal
    headings = np.unwrap(np.array([s.att[1:, 2] for s in states]), axis=0)
    banks = np.array([s.att[1:, 0] for s in states])
    straight, random_turns, seeking = range(3)
    assert np.ptp(headings[:, straight]) < math.radians(2)
    assert np.abs(banks[:, straight]).max() < math.radians(1)
    assert np.ptp(headings[:, random_turns]) > math.radians(20)
    assert np.abs(banks[:, random_turns]).max() > math.radians(5)
    # the goal seeker heads for its goal: after turning it closes in on it
    final = states[-1]
    bearing = math.atan2(goal[0] - final.pos[3, 0], goal[1] - final.pos[3, 1])
    error = math.atan2(math.sin(bearing - final.att[3, 2]), math.cos(bearing - final.att[3, 2]))
    assert abs(error) < math.radians(15)
    # every intruder held its altitude
    assert max(abs(s.pos[1:, 2] - 120).max() for s in states) < 5.0


def test_nan_is_reported_by_failure_and_stops_the_world() -> None:
    with JSBSimWorld(_scenario(count=1)) as w:
        w.advance(1.0)
        assert w.failure() is None
        w.aircraft[0].fdm["fcs/elevator-cmd-norm"] = float("nan")
        w.advance(2.0)  # no exception
        reason = w.failure()
        assert reason is not None and reason.startswith("NaN in ownship state")
        t = w.t
        w.advance(1.0)
        assert w.t == t  # a failed world does not advance


def test_flying_into_the_ground_is_reported() -> None:
    with JSBSimWorld(_scenario(count=0)) as w:
        w.command_ownship(alt_target_m=-100.0)  # descend through the ground
        for _ in range(120):
            w.advance(1.0)
            if w.failure():
                break
        assert w.failure() is not None
        assert w.failure().startswith("ownship hit the ground")
        assert w.state().pos[0, 2] < 1.0


def _lose_control(w: JSBSimWorld, row: int) -> None:
    w.aircraft[row].fdm["ap/engaged"] = 0.0
    w.aircraft[row].fdm["fcs/aileron-cmd-norm"] = 1.0  # full aileron, no autopilot


def test_loss_of_control_is_reported() -> None:
    sc = default_scenario("world-test", intruders={"count": 1, "flow": "none"})
    with JSBSimWorld(sc) as w:
        _lose_control(w, 1)
        w.advance(10.0)
        assert w.failure() is not None
        assert w.failure().startswith("intruder-1 left the flight envelope")


def test_an_intruder_lost_with_persistent_traffic_is_replaced_and_the_flight_goes_on() -> None:
    """The ownship's run does not end because an intruder crashed: as one that left the
    area, it gives way to a newcomer at the edge at once, and nobody sees the wreck."""
    with JSBSimWorld(_scenario(count=2)) as w:
        _lose_control(w, 1)
        for _ in range(100):
            w.step(round(0.1 / w.dt))
            s = w.state()
            assert w.failure() is None
            if w.lost_intruders:
                break
        assert len(w.lost_intruders) == 1
        assert w.lost_intruders[0].startswith("intruder-1 left the flight envelope")
        assert s.ids == ("ownship", "intruder-3", "intruder-2")
        assert abs(s.att[1, 0]) < 0.1 and 15.0 <= s.airspeed[1] <= 30.0  # trimmed, level
        x, y = s.pos[1, :2]
        assert (
            min(abs(x - v) for v in w.scenario.world.x) < 1
            or min(abs(y - v) for v in w.scenario.world.y) < 1
        )  # at the edge
        assert math.hypot(x - s.pos[0, 0], y - s.pos[0, 1]) >= 999.0  # clear of the ownship
        w.advance(5.0)
        assert w.failure() is None and w.state().t == pytest.approx(s.t + 5.0)


def test_random_intruders_start_clear_of_every_fleet_members_start() -> None:
    """fleet-mission.yaml seed 43 (issue 32, round 9) placed intruders 119-122 m from members 1
    and 2, which only member 0's start was kept clear of: every member's start is kept clear
    now; one ownship draws the same traffic as a fleet's member 0 alone would."""
    from uavxai.paths import scenarios_dir
    from uavxai.scenario import load_scenario

    sc = load_scenario(scenarios_dir() / "fleet-mission.yaml").model_copy(update={"seed": 43})
    starts = sc.member_starts()
    assert len(starts) == 3
    gap = sc.intruders.min_start_distance_m
    specs = draw_intruders(sc, np.random.default_rng(43))
    assert len(specs) == sc.intruders.n
    for p in specs:
        assert min(math.hypot(p.x - s.x, p.y - s.y) for s in starts) >= gap
    alone = sc.model_copy(update={"fleet": sc.fleet.model_copy(update={"size": 1, "leave": None})})
    solo = draw_intruders(alone, np.random.default_rng(43))
    assert any(min(math.hypot(p.x - s.x, p.y - s.y) for s in starts[1:]) < gap for p in solo)
    assert all(math.hypot(p.x - starts[0].x, p.y - starts[0].y) >= gap for p in solo)


def test_intruders_with_no_room_to_start_are_refused_by_the_keys_to_change() -> None:
    """A world whose every point is within intruders.min_start_distance_m of a member's start
    (three members 370 m apart in a 1.3 km square, 900 m kept clear): a UserError naming both
    keys that fence the starts off and what to change (before: a bare ValueError)."""
    sc = default_scenario(
        world={"x": [0, 1300], "y": [0, 1300]},
        ownship={"start": {"x": 600, "y": 1000, "h": 120, "heading_deg": 90}},
        fleet={"size": 3},
        intruders={"count": 2, "min_start_distance_m": 900},
        mission={"service_s": 60},
    )
    with pytest.raises(UserError) as err:
        draw_intruders(sc, np.random.default_rng(0))
    said = str(err.value)
    assert "intruders.min_start_distance_m (900 m)" in said
    assert "fleet.spacing_m 370 m" in said and "a smaller fleet.spacing_m" in said
    alone = sc.model_copy(update={"fleet": sc.fleet.model_copy(update={"size": 1})})
    assert len(draw_intruders(alone, np.random.default_rng(0))) == 2  # one start leaves room
