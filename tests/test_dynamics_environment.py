"""Wind and Milspec (Dryden) turbulence on the JSBSim aircraft: the property names JSBSim 1.3
reads, the wind triangle, determinism of the turbulence, and the autopilot in turbulence."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.dynamics.aircraft import (
    TURB_SEED,
    TURB_SEVERITY,
    TURB_TYPE,
    TURB_W20,
    WIND_EAST,
    WIND_NORTH,
    Aircraft,
    wind_ne_from,
)
from uavxai.dynamics.environment import EnvironmentConfig
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.sim.manoeuvres import DT, FRAME, flown
from uavxai.units import FT, KT


def test_wind_from_direction_convention():
    n, e = wind_ne_from(10.0, 270.0)  # from the west: blows towards the east
    assert n == pytest.approx(0.0, abs=1e-12) and e == pytest.approx(10.0)
    n, e = wind_ne_from(5.0, 0.0)  # from the north: blows south
    assert n == pytest.approx(-5.0) and e == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(UserError, match="speed_mps"):
        wind_ne_from(-1.0, 0.0)


def test_jsbsim_reads_back_the_weather_properties():
    a = Aircraft("uav_fw", FRAME, DT, seed=7)
    a.set_environment(wind_ne_from(10.0, 270.0), "moderate", seed=5)
    a.start(1000.0, 1000.0, 120.0, 0.0, 20.0)  # run_ic and the trim keep the wind
    f = a.fdm
    assert f[WIND_NORTH] == pytest.approx(0.0, abs=1e-9)
    assert f[WIND_EAST] * FT == pytest.approx(10.0)
    assert f["atmosphere/wind-mag-fps"] * FT == pytest.approx(10.0)
    assert f[TURB_TYPE] == 3 and f[TURB_SEVERITY] == 4
    assert f[TURB_W20] * FT == pytest.approx(30 * KT)
    assert f[TURB_SEED] == 5
    a.run()
    assert f["atmosphere/turb-north-fps"] != 0.0  # the Milspec model is running
    with pytest.raises(UserError, match="environment.turbulence"):
        a.set_environment((0.0, 0.0), "strong")
    a.close()


@pytest.mark.parametrize(
    "heading_deg,wind_from_deg", [(0.0, 270.0), (90.0, 0.0), (45.0, 270.0), (200.0, 150.0)]
)
def test_wind_triangle_crab_angle(heading_deg, wind_from_deg):
    """Wings level (the autopilot holds bank and airspeed, not a track) in a steady 10 m/s
    wind: the angle between heading and ground track is the wind triangle's, within 1 deg;
    ground velocity = air velocity along the heading + wind (what TrafficState.vel carries)."""
    wn, we = wind_ne_from(10.0, wind_from_deg)
    r = flown(heading_deg, (wn, we))[200:]  # settled: from 20 s on
    ve, vn = r[:, 3] * FT, r[:, 4] * FT
    psi, va = r[:, 8], r[:, 9] * FT
    track = np.arctan2(ve, vn)
    crab = np.degrees((track - psi + math.pi) % (2 * math.pi) - math.pi)
    expected = (
        np.degrees(np.arctan2(va * np.sin(psi) + we, va * np.cos(psi) + wn) - psi + math.pi) % 360
        - 180
    )
    assert np.abs(crab - expected).max() < 1.0
    # the crab is real (26.6 deg for a pure cross wind at 20 m/s)
    if wind_from_deg - heading_deg in (270.0, -90.0):
        assert abs(crab.mean()) == pytest.approx(math.degrees(math.atan2(10, 20)), abs=1.0)
    ground = np.column_stack([ve, vn])
    air_plus_wind = np.column_stack([va * np.sin(psi) + we, va * np.cos(psi) + wn])
    assert np.abs(ground - air_plus_wind).max() < 0.5
    assert np.abs(va - 20.0).max() < 0.3  # airspeed held, not ground speed
    assert np.abs(r[:, 2] * FT - 120.0).max() < 1.0


def test_turbulence_is_deterministic_for_a_seed():
    a = flown(30.0, (0.0, 5.0), "moderate", seed=11, seconds=20.0)
    b = flown(30.0, (0.0, 5.0), "moderate", seed=11, seconds=20.0)
    c = flown(30.0, (0.0, 5.0), "moderate", seed=12, seconds=20.0)
    calm = flown(30.0, (0.0, 5.0), "none", seed=11, seconds=20.0)
    assert np.array_equal(a, b)
    assert np.abs(a - c).max() > 0.01
    # turbulence moves the aircraft about: bank excursions are much larger than in calm air
    assert np.abs(a[:, 6]).max() > 10 * np.abs(calm[:, 6]).max()


def test_autopilot_survives_moderate_turbulence_for_a_minute():
    """Turns of +-30 deg and level flight in moderate turbulence with a 10 m/s wind."""
    banks = [(10.0, math.radians(30)), (25.0, math.radians(-30)), (40.0, 0.0)]
    r = flown(0.0, wind_ne_from(10.0, 300.0), "moderate", seed=3, banks=banks)
    h = r[:, 2] * FT
    va = r[:, 9] * FT
    phi, theta = np.degrees(r[:, 6]), np.degrees(r[:, 7])
    assert np.all(np.isfinite(r))
    assert np.abs(h - 120.0).max() < 15.0  # the height hold keeps up
    assert va.min() > 12.0 and va.max() < 30.0  # well inside 10.2 m/s stall, 33 m/s top
    assert np.abs(phi).max() < 45.0 and np.abs(theta).max() < 25.0
    # the commanded turns still happen: wings level at the end, turning while banked
    psi = np.unwrap(r[:, 8])
    assert psi[240] - psi[110] > math.radians(60)  # 13 s of right turn at ~30 deg
    assert psi[390] - psi[260] < -math.radians(60)  # then left


def test_turbulence_intensity_is_mil_f_8785c_low_altitude():
    """At 120 m above a sea-level origin the Milspec model's gust velocities have the
    MIL-F-8785C low-altitude intensities: sigma_w = 0.1 W20, sigma_u = sigma_v =
    sigma_w / (0.177 + 0.000823 h_ft)^0.4 (W20 = 30 kt for moderate). JSBSim evaluates the
    model at the height above *sea level* (see aircraft.py), so the origin is put there."""
    a = Aircraft("uav_fw", LocalFrame(34.1230, 108.8370, 0.0), DT, seed=7)
    a.set_environment((0.0, 0.0), "moderate", seed=4)
    a.start(1000.0, 1000.0, 120.0, 0.0, 20.0)
    props = ["atmosphere/turb-north-fps", "atmosphere/turb-east-fps", "atmosphere/turb-down-fps"]
    gusts = []
    for k in range(round(300.0 / DT)):
        a.run()
        if k % 12 == 0:
            gusts.append([a.fdm[p] * FT for p in props])
    a.close()
    std = np.array(gusts).std(axis=0)
    sigma_w = 0.1 * 30 * KT
    sigma_u = sigma_w / (0.177 + 0.000823 * 120 / FT) ** 0.4
    # a 300 s record of a process with a correlation time of ~20 s: about 15 % scatter
    assert math.hypot(std[0], std[1]) / math.sqrt(2) == pytest.approx(sigma_u, rel=0.25)
    assert std[2] == pytest.approx(sigma_w, rel=0.25)


def test_environment_config_for_both_dynamics():
    env = EnvironmentConfig(wind_speed_mps=10.0, wind_from_deg=270.0, turbulence="moderate")
    assert env.wind_enu == pytest.approx((10.0, 0.0, 0.0), abs=1e-12)  # blows towards the east
    assert env.crab_angle_rad(0.0, 20.0) == pytest.approx(math.atan2(10, 20))
    assert env.crab_angle_rad(math.pi / 2, 20.0) == pytest.approx(0.0, abs=1e-12)  # tail wind
    assert not env.calm and EnvironmentConfig().calm

    windy = default_scenario(environment={"wind": {"speed_mps": 4, "from_deg": 90},
                                          "turbulence": "light"})  # fmt: skip
    assert EnvironmentConfig.from_scenario(windy) == EnvironmentConfig(4.0, 90.0, "light")
    assert EnvironmentConfig.from_scenario(default_scenario()) == EnvironmentConfig()
    with pytest.raises(UserError, match="environment.turbulence"):
        EnvironmentConfig(turbulence="gusty")


@pytest.mark.parametrize("bank_deg", [0.0, 20.0])
def test_planner_model_predicts_the_jsbsim_flight_in_wind(bank_deg):
    """The planner's encounter model flies airspeed and heading through the wind it knows, so
    its 10 s prediction lands where JSBSim flew (a 10 m/s cross wind would put a model without
    it about 100 m off)."""
    from uavxai.avoidance.model import EncounterModel, Track, ownship_state
    from uavxai.avoidance.types import Ownship, PlannerConfig
    from uavxai.vocabulary import HOLD

    wn, we = wind_ne_from(10.0, 270.0)  # from the west, across a northbound aircraft
    bank = math.radians(bank_deg)
    r = flown(0.0, (wn, we), seconds=45.0, banks=[(15.0, bank)])
    lat, lon, h_ft, *_ = r[299]  # t = 30 s: settled in its turn
    x, y, h = FRAME.to_local(lat, lon, h_ft / FT)
    end_lat, end_lon, end_h_ft = r[399][:3]  # t = 40 s
    x1, y1, _ = FRAME.to_local(end_lat, end_lon, end_h_ft / FT)
    phi, psi, va = r[299][6], r[299][8], r[299][9] * FT
    own = ownship_state(Ownship(x, y, h, va, psi, bank=bank, phi=phi))
    errors = []
    for wind in ((we, wn), (0.0, 0.0)):
        model = EncounterModel(PlannerConfig(wind_mps=wind, x_bounds=(-1e5, 1e5),
                                             y_bounds=(-1e5, 1e5)))
        empty = Track.of(np.zeros((model.substeps(10.0) + 1, 0, 3)))
        seg = model.fly(own[None], np.array([HOLD]), np.array([1e9, 1e9, h]), 10.0, empty,
                        cull=False)
        errors.append(math.dist(seg.end[0][:2], (x1, y1)))
    with_wind, without = errors
    assert with_wind < 8.0, errors
    assert without > 80.0, errors  # the check can tell a model that ignores the wind


def test_planner_model_carries_the_ownship_in_its_gusts():
    """In moderate turbulence the gust of the moment (ground velocity less air velocity,
    2-4 m/s) carries the aircraft for many seconds. The planner's model, carried by the air
    the ownship measures (ownship_air), predicts each second of a turning flight 2 s ahead
    to about a metre; flying airspeed and heading alone it is several metres off."""
    from uavxai.avoidance.model import EncounterModel, Track, ownship_air, ownship_state
    from uavxai.avoidance.types import Ownship, PlannerConfig
    from uavxai.vocabulary import HOLD

    banks = [(10.0, math.radians(30)), (25.0, 0.0), (35.0, math.radians(-30)), (50.0, 0.0)]
    cfg = PlannerConfig(x_bounds=(-1e5, 1e5), y_bounds=(-1e5, 1e5), gusts=True)
    errors: dict[bool, list[float]] = {True: [], False: []}
    for seed in (2, 3):
        r = flown(0.0, (0.0, 0.0), "moderate", seed, banks=list(banks))
        pos = np.array([FRAME.to_local(row[0], row[1], row[2] * FT) for row in r])
        for i in range(9, len(r) - 21, 10):  # row i is t = (i + 1) / 10 s; 2 s later: i + 20
            t = (i + 1) * 0.1
            bank = [b for tb, b in [(0.0, 0.0), *banks] if tb <= t][-1]
            row = r[i]
            own = Ownship(*pos[i], row[9] * FT, row[8], bank=bank, phi=row[6],
                          ground_velocity=(row[3] * FT, row[4] * FT))  # fmt: skip
            for carried in (True, False):
                model = EncounterModel(cfg)
                if carried:
                    model.carry_ownship(ownship_air(own, cfg))
                empty = Track.of(np.zeros((model.substeps(2.0) + 1, 0, 3)))
                goal = np.array([1e9, 1e9, pos[i][2]])
                seg = model.fly(ownship_state(own)[None], np.array([HOLD]), goal, 2.0, empty)
                errors[carried].append(math.dist(seg.end[0][:2], pos[i + 20][:2]))
    assert np.median(errors[True]) < 2.0, np.median(errors[True])
    assert np.median(errors[False]) > 3.5, np.median(errors[False])  # the test can tell


def test_aircraft_start_trimmed_in_turbulence():
    """The trim is of the steady state: in moderate turbulence every start of the intruders'
    speeds and heights trims (it chased the gusts before, and mostly failed), and the start
    that a failed trim left with a NaN propeller (a newcomer of a 40-intruder campaign
    episode, seed 20) flies. The gusts are on once it flies."""
    from uavxai.dynamics.aircraft import heading_from_deg
    from uavxai.dynamics.world import jsbsim_seed

    rng = np.random.default_rng(0)
    starts = [(1739.580457935439, 0.0, 122.47603262247, 54.38051946736982, 29.257771815528546)]
    starts += [(1000.0, 1000.0, *rng.uniform((100, 0, 15), (140, 360, 30))) for _ in range(8)]
    for k, (x, y, h, heading_deg, speed) in enumerate(starts):
        a = Aircraft("uav_fw", FRAME, DT, jsbsim_seed(20, 104 + k))
        a.set_environment((0.0, 0.0), "moderate", jsbsim_seed(20, 104 + k))
        assert a.start(x, y, h, heading_from_deg(heading_deg), speed), (x, y, h, speed)
        first = a.raw_state()
        assert np.all(np.isfinite(first)) and first[9] * FT == pytest.approx(speed, abs=0.01)
        for _ in range(round(5.0 / DT)):
            a.run()
        gust = [a.fdm[p] for p in ("atmosphere/turb-north-fps", "atmosphere/turb-down-fps")]
        a.close()
        assert np.any(np.abs(gust) > 0.0)


def _drift_sigma_8s(dynamics: str, turbulence: str) -> float:
    """The per-axis RMS (m) of how far the ownship strayed from the planner's model of its own
    flight 8 s ahead, over an mcts_vertical episode among 20 random-turn intruders."""
    from uavxai.avoidance.model import model_drift
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.paths import scenarios_dir
    from uavxai.scenario import load_scenario
    from uavxai.sim.build import fly
    from uavxai.sim.observers import OwnPath
    from uavxai.sim.spec import episode_spec

    base = load_scenario(scenarios_dir() / "manoeuvring.yaml")
    env = base.environment.model_copy(update={"turbulence": turbulence})
    sc = base.model_copy(update={"environment": env}).with_seed(1001)
    cfg = PlannerConfig.from_scenario(sc)
    spec, path = episode_spec(sc, n_intruders=20, dynamics=dynamics), OwnPath()
    goal = spec.goal
    planner = make_planner("mcts_vertical", cfg)
    fly(spec, planner, observers=[path])
    drift = model_drift(cfg, path.own, path.actions, np.asarray(goal), (8,), every=2)[8]
    assert drift.size > 20, drift.size
    return float(np.sqrt(np.mean(drift**2) / 2))


# docs/results's measured value of avoidance.mcts.own_error_10s_m in moderate turbulence
# (benchmarks/studies/bench_own_model.py, seeds 1000-1003)
MODERATE_OWN_ERROR_10S_M = 20.2


def test_the_planners_own_error_is_what_jsbsim_flies():
    """The kinematic dynamics fly the planner's model (well under a metre 8 s ahead); the
    JSBSim aircraft strays from it, in moderate turbulence by about the documented sigma of
    ``avoidance.mcts.own_error_10s_m`` (20.2 m at 10 s, 14.5 m at 8 s as t^1.5; this one
    episode, another seed, within a factor of 2) and by more than in calm air."""
    assert _drift_sigma_8s("kinematic", "moderate") < 1.0
    expected = MODERATE_OWN_ERROR_10S_M * 0.8**1.5
    moderate = _drift_sigma_8s("jsbsim", "moderate")
    assert expected / 2 < moderate < 2 * expected, (moderate, expected)
    assert _drift_sigma_8s("jsbsim", "none") < moderate
