"""Intruder pilots, without any dynamics: what they command and that it repeats."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from uavxai.dynamics.behaviours import IntruderPilot, make_pilots, track_pilot
from uavxai.scenario import IntruderSpec, aircraft_bank_limit_deg, default_scenario

# the ownship's bank limit is 25 deg; the intruders fly their aircraft's own (uav_fw: 30)
SC = default_scenario("pilots", avoidance={"bank_limit_deg": 25})
LIMIT = math.radians(aircraft_bank_limit_deg("uav_fw"))


def _spec(behaviour: str, speed: float = 21.0) -> IntruderSpec:
    return IntruderSpec(x=500, y=500, h=120, heading_deg=90, speed_mps=speed, behaviour=behaviour)


def _commands(pilot: IntruderPilot, seconds: int = 300) -> np.ndarray:
    pos, vel = (500.0, 500.0, 120.0), (20.0, 0.0, 0.0)
    return np.array([pilot.command(float(t), pos, vel, math.pi / 2) for t in range(seconds)])


def test_straight_flies_wings_level_at_its_speed() -> None:
    cmds = _commands(IntruderPilot(_spec("straight"), np.random.default_rng(0), SC))
    assert np.all(cmds[:, 0] == 0.0)
    assert np.all(cmds[:, 1] == 21.0)


def test_random_turns_change_within_the_bank_limit() -> None:
    cmds = _commands(IntruderPilot(_spec("random_turns"), np.random.default_rng(0), SC))
    banks = cmds[:, 0]
    assert np.abs(banks).max() <= LIMIT
    assert np.abs(banks).max() > math.radians(25)  # the ownship's 25 deg does not bound them
    changes = np.count_nonzero(np.diff(banks))
    assert 300 / 20 - 1 <= changes <= 300 / 5 + 1  # one change per 5-20 s hold
    assert (banks > 0).any() and (banks < 0).any() and (banks == 0).any()
    assert np.all(cmds[:, 1] == 21.0)


def test_goal_seeking_turns_towards_its_goal() -> None:
    pilot = IntruderPilot(_spec("goal_seeking"), np.random.default_rng(0), SC)
    gx, gy = pilot.goal
    assert SC.world.x[0] <= gx <= SC.world.x[1] and SC.world.y[0] <= gy <= SC.world.y[1]
    far = (gx - 600.0, gy, 120.0)  # goal due east
    assert pilot.command(0.0, far, (0, 20, 0), 0.0)[0] == pytest.approx(LIMIT)  # heading N
    assert pilot.command(0.0, far, (0, -20, 0), math.pi)[0] == pytest.approx(-LIMIT)  # S
    assert pilot.command(0.0, far, (20, 0, 0), math.pi / 2)[0] == pytest.approx(0.0, abs=1e-9)
    small = pilot.command(0.0, far, (20, 0, 0), math.pi / 2 - 0.1)[0]
    assert 0.0 < small < LIMIT  # proportional near the bearing
    # reaching the goal draws the next one
    pilot.command(1.0, (gx + 10.0, gy, 120.0), (20, 0, 0), 0.0)
    assert pilot.goal != (gx, gy)


def test_behaviour_defaults_to_the_scenario_one() -> None:
    sc = default_scenario("d", intruders={"behaviour": "random_turns"})
    spec = IntruderSpec(x=0, y=0, h=100, heading_deg=0, speed_mps=20)
    assert IntruderPilot(spec, np.random.default_rng(0), sc).behaviour == "random_turns"


def test_make_pilots_repeats_for_a_seed_and_differs_between_seeds() -> None:
    specs = [_spec("random_turns"), _spec("random_turns"), _spec("goal_seeking")]

    def flown(seed: int) -> np.ndarray:
        return np.array([_commands(p, 120) for p in make_pilots(SC, specs, seed)])

    a, b, c = flown(5), flown(5), flown(6)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert not np.array_equal(a[0], a[1])  # each intruder has its own stream


def test_intruders_fly_their_own_aircrafts_bank_limit_not_the_ownships() -> None:
    assert math.isclose(LIMIT, math.radians(30.0))
    pilot = IntruderPilot(_spec("random_turns"), np.random.default_rng(0), SC)
    assert pilot.bank_limit_rad == LIMIT
    t = np.array([0.0, 10.0])
    line = SimpleNamespace(t=t, x=20.0 * t, y=0.0 * t, h=120.0 + 0.0 * t, vx=20.0 + 0.0 * t,
                           vy=0.0 * t, vh=0.0 * t)  # fmt: skip
    track = track_pilot(SC, line)
    assert track.bank_limit_rad == LIMIT
