"""Loiter orbit guidance (uavxai.dynamics.orbit) flown by the uav_fw in JSBSim (issue 12).

The guidance law runs as the loiter mode's outer loop: every 0.1 s of simulated time it reads
the aircraft's position and ground velocity and writes the bank command, which the autopilot
in the aircraft's XML holds. Radius errors are measured over three whole laps after capture.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from uavxai.dynamics.aircraft import Aircraft, wind_ne_from
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.orbit import OrbitGuidance, radius_for
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.units import FT, G

DT = 1.0 / 120.0  # JSBSim's rate in the scenarios
GUIDANCE_TICKS = 12  # 10 Hz
BANK_LIMIT = math.radians(30.0)
H = 120.0


@dataclass
class Flight:
    t: np.ndarray
    xy: np.ndarray  # local east, north, m
    h: np.ndarray
    bank: np.ndarray  # flown, rad
    bank_cmd: np.ndarray

    def distance(self, centre: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
        return np.hypot(self.xy[:, 0] - centre[0], self.xy[:, 1] - centre[1])


def fly_orbit(
    guidance: OrbitGuidance,
    start_xy: tuple[float, float],
    heading_deg: float,
    speed_mps: float,
    duration_s: float,
    wind_ne: tuple[float, float] = (0.0, 0.0),
    turbulence: str = "none",
) -> Flight:
    """One uav_fw started level at ``start_xy``, flown by ``guidance`` at 10 Hz."""
    frame = LocalFrame.from_origin(default_scenario("orbit-test").world.origin)
    a = Aircraft("uav_fw", frame, DT, seed=1)
    try:
        if wind_ne != (0.0, 0.0) or turbulence != "none":
            a.set_environment(wind_ne, turbulence, seed=3)
        a.set_limits(bank_limit_rad=BANK_LIMIT)
        assert a.start(*start_xy, H, math.radians(heading_deg), speed_mps)
        n = round(duration_s / (DT * GUIDANCE_TICKS))
        rows = np.empty((n, 6))
        for k in range(n):
            lat, lon, h_ft, ve, vn, _, phi, _, _, vt = a.raw_state()
            x, y, _ = frame.to_local(lat, lon, 0.0)
            bank = guidance.bank_command((x, y), (ve * FT, vn * FT), vt * FT)
            a.command(bank_cmd_rad=bank)
            rows[k] = (k * GUIDANCE_TICKS * DT, x, y, h_ft * FT, phi, bank)
            for _ in range(GUIDANCE_TICKS):
                a.run()
    finally:
        a.close()
    return Flight(rows[:, 0], rows[:, 1:3], rows[:, 3], rows[:, 4], rows[:, 5])


def laps_after(f: Flight, t0: float, laps: int, clockwise: bool) -> np.ndarray:
    """Mask of the samples from ``t0`` until ``laps`` whole turns about the centre are flown
    in the orbit's direction; fails if they are not."""
    bearing = np.unwrap(np.arctan2(f.xy[:, 0], f.xy[:, 1]))  # clockwise from north
    swept = (bearing - bearing[np.searchsorted(f.t, t0)]) * (1 if clockwise else -1)
    after = f.t >= t0
    done = np.nonzero(after & (swept >= laps * 2 * math.pi))[0]
    assert done.size, f"fewer than {laps} laps after t = {t0} s (swept {swept[-1]:.1f} rad)"
    return after & (f.t <= f.t[done[0]])


# ------------------------------------------------------------------------------ the law
def test_radius_for_leaves_a_bank_margin() -> None:
    r = radius_for(20.0, BANK_LIMIT)
    assert r == pytest.approx(20.0**2 / (G * math.tan(0.7 * BANK_LIMIT)))
    assert r == pytest.approx(106.3, abs=0.1)
    # Downwind the ground speed is V + W, which the radius must allow for.
    assert radius_for(20.0, BANK_LIMIT, wind_mps=5.0) == pytest.approx(r * (25 / 20) ** 2)
    assert radius_for(20.0, BANK_LIMIT, margin=1.0) < r


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"airspeed_mps": 0.0, "bank_limit_rad": BANK_LIMIT}, "airspeed_mps"),
        ({"airspeed_mps": 20.0, "bank_limit_rad": 0.0}, "bank_limit_rad"),
        ({"airspeed_mps": 20.0, "bank_limit_rad": BANK_LIMIT, "margin": 1.5}, "margin"),
        ({"airspeed_mps": 20.0, "bank_limit_rad": BANK_LIMIT, "wind_mps": -1}, "wind_mps"),
    ],
)
def test_radius_for_rejects_bad_input(kwargs: dict, field: str) -> None:
    with pytest.raises(UserError, match=field):
        radius_for(**kwargs)


def test_guidance_rejects_bad_orbit() -> None:
    with pytest.raises(UserError, match="radius_m"):
        OrbitGuidance((0, 0), 0.0)
    with pytest.raises(UserError, match="centre"):
        OrbitGuidance((math.nan, 0), 100.0)
    with pytest.raises(UserError, match="bank_limit_rad"):
        OrbitGuidance((0, 0), 100.0, bank_limit_rad=2.0)


@pytest.mark.parametrize("clockwise", [True, False])
def test_on_the_circle_the_command_is_the_coordinated_turn(clockwise: bool) -> None:
    r, v = 150.0, 20.0
    g = OrbitGuidance((10.0, -20.0), r, clockwise=clockwise, bank_limit_rad=BANK_LIMIT)
    # North of the centre: the tangent course is east (clockwise) or west.
    vel = (v, 0.0) if clockwise else (-v, 0.0)
    bank = g.bank_command((10.0, -20.0 + r), vel, v)
    assert bank == pytest.approx((1 if clockwise else -1) * math.atan(v * v / (G * r)))
    assert g.distance_error((10.0, -20.0 + r)) == pytest.approx(0.0)


def test_far_away_it_turns_towards_the_centre_within_the_bank_limit() -> None:
    g = OrbitGuidance((0.0, 0.0), 100.0, bank_limit_rad=BANK_LIMIT)
    # 1 km east of the centre flying north: the centre is on the left.
    assert g.bank_command((1000.0, 0.0), (0.0, 20.0), 20.0) == pytest.approx(-BANK_LIMIT)
    # Far away the field points (almost) at the centre; along it the wings are nearly level.
    chi = g.desired_course((1000.0, 0.0))
    assert math.degrees(chi) % 360 == pytest.approx(270.0, abs=5.0)
    vel = (20.0 * math.sin(chi), 20.0 * math.cos(chi))
    assert abs(g.bank_command((1000.0, 0.0), vel, 20.0)) < math.radians(1)
    # No ground speed (a head wind as strong as the airspeed): hold the circle's bank.
    assert g.bank_command((1000.0, 0.0), (0.0, 0.0), 20.0) > 0
    # A diverged state never becomes a NaN command.
    assert g.bank_command((math.nan, 0.0), (0.0, 20.0), 20.0) == 0.0


# -------------------------------------------------------------------------- in JSBSim
@pytest.mark.parametrize(
    ("speed", "clockwise"), [(12.0, True), (20.0, True), (20.0, False), (30.0, True)]
)
def test_orbit_holds_its_radius_in_calm_air(speed: float, clockwise: bool) -> None:
    r = radius_for(speed, BANK_LIMIT)
    g = OrbitGuidance((0.0, 0.0), r, clockwise=clockwise, bank_limit_rad=BANK_LIMIT)
    lap_s = 2 * math.pi * r / speed
    # Start on the circle flying its tangent, then three laps after a 10 s settling time.
    f = fly_orbit(g, (0.0, r), 90.0 if clockwise else 270.0, speed, 10 + 3.3 * lap_s)
    laps = laps_after(f, 10.0, 3, clockwise)
    err = (f.distance()[laps] - r) / r
    assert np.abs(err).max() < 0.10  # the requirement
    assert np.abs(err).max() < 0.02  # what the law does (measured: under 0.5 %)
    assert np.ptp(f.h[laps]) < 5.0  # the altitude hold is not disturbed
    assert np.abs(f.bank).max() <= BANK_LIMIT + math.radians(1)


@pytest.mark.parametrize("from_deg", [270.0, 45.0])
def test_orbit_holds_its_radius_in_5mps_wind(from_deg: float) -> None:
    speed, wind = 20.0, 5.0
    r = radius_for(speed, BANK_LIMIT, wind_mps=wind)  # 166 m
    g = OrbitGuidance((0.0, 0.0), r, bank_limit_rad=BANK_LIMIT)
    lap_s = 2 * math.pi * r / (speed - wind)
    f = fly_orbit(g, (0.0, r), 90.0, speed, 10 + 3.3 * lap_s, wind_ne_from(wind, from_deg))
    laps = laps_after(f, 10.0, 3, True)
    err = (f.distance()[laps] - r) / r
    # Stated tolerance 5 % (measured 0.7 %): the ground speed varies 15-25 m/s around the
    # orbit, and the law's feed-forward ignores the crab angle.
    assert np.abs(err).max() < 0.05
    # The wind-aware radius keeps the bank inside the margin's reach of the limit.
    assert np.abs(f.bank[laps]).max() < 0.8 * BANK_LIMIT


def test_orbit_in_wind_and_light_turbulence_stays_within_10_percent() -> None:
    # Light Dryden gusts on top of 5 m/s of wind, on the wind-aware radius (measured 2.5 %).
    # On the calm-air radius (106 m instead of 166 m) the downwind leg needs 31 deg of bank,
    # more than the 30 deg limit: the command saturates for 16 % of the time and the error
    # grows to 6 % without gusts and 18 % with them, which is why radius_for takes the wind.
    speed, wind = 20.0, 5.0
    r = radius_for(speed, BANK_LIMIT, wind_mps=wind)
    g = OrbitGuidance((0.0, 0.0), r, bank_limit_rad=BANK_LIMIT)
    lap_s = 2 * math.pi * r / (speed - wind)
    f = fly_orbit(g, (0.0, r), 90.0, speed, 10 + 3.3 * lap_s, wind_ne_from(wind, 270.0), "light")
    laps = laps_after(f, 10.0, 3, True)
    err = (f.distance()[laps] - r) / r
    assert np.abs(err).max() < 0.10
    assert np.sqrt(np.mean(err**2)) < 0.03


@pytest.mark.parametrize("heading_deg", [0.0, 270.0])
def test_aircraft_400m_away_captures_the_circle(heading_deg: float) -> None:
    # 400 m west of the centre, flying north (across) or west (straight away from it).
    speed = 20.0
    r = radius_for(speed, BANK_LIMIT)
    g = OrbitGuidance((0.0, 0.0), r, bank_limit_rad=BANK_LIMIT)
    f = fly_orbit(g, (-400.0, 0.0), heading_deg, speed, 90.0)
    err = (f.distance() - r) / r
    outside = np.nonzero(np.abs(err) >= 0.10)[0]
    capture_s = f.t[outside[-1] + 1]
    assert capture_s < 45.0  # measured 21 s across, 32 s flying away
    assert f.distance().min() > 0.9 * r  # no overshoot into the circle
    assert np.abs(err[f.t > capture_s + 20]).max() < 0.01


@pytest.mark.parametrize(("start", "heading_deg"), [((-250.0, 0.0), 270.0), ((0.0, 221.0), 0.0)])
def test_fly_predicts_the_laws_way_onto_the_circle_as_jsbsim_flies_it(start, heading_deg) -> None:
    """``OrbitGuidance.fly``, the orbit check's prediction of the law's way onto the circle
    (issue 32: fleet-mission.yaml seed 1's member 2 was handed back 221 m out heading away),
    against the uav_fw in JSBSim flown by the same law for 16 s (the planner's horizon) from
    off the circle heading away: within 5 % of the 320 m flown (measured 11 m), where flying
    straight on is 400 m off."""
    from uavxai.avoidance.types import PlannerConfig

    cfg = PlannerConfig.from_scenario(default_scenario("orbit-test"))
    g = OrbitGuidance((0.0, 0.0), 106.0, bank_limit_rad=BANK_LIMIT)
    f = fly_orbit(g, start, heading_deg, 20.0, 16.0 + 1e-6)
    psi = math.radians(heading_deg)
    roll = math.radians(cfg.roll_rate_limit_deg_s)
    way = g.fly(start, (20.0 * math.sin(psi), 20.0 * math.cos(psi)), 0.0, roll, 16.0, 0.1)
    assert way.shape == (161, 2)
    assert way[0] == pytest.approx(start)
    flown = f.t <= 16.0 + 1e-9
    predicted = way[np.round(f.t[flown] / 0.1).astype(int)]
    assert np.hypot(*(f.xy[flown] - predicted).T).max() < 0.05 * 20.0 * 16.0
    # it turned back towards the circle: the law's way, not the straight line on
    assert np.hypot(*way[-1]) < np.hypot(*start)
