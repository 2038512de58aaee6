"""Simulated ADS-B and the onboard sensor: accuracy categories, latency, dropouts, the
non-cooperative share, determinism, and the ADSB_VEHICLE round trip through real pymavlink."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.surveillance.adsb import (
    NACP_EPU_M,
    NACV_HFOM_MPS,
    Report,
    Surveillance,
    SurveillanceConfig,
    adsb_fields,
    adsb_message,
    is_cooperative,
    nacp_sigmas,
    report_from_adsb,
)
from uavxai.surveillance.sensor import SensorConfig

DT = 0.1


def straight_traffic(n: int, t: float, heading_own: float = 0.0) -> TrafficState:
    """Ownship at (1000, 1000) and ``n`` intruders on straight lines, at time ``t``."""
    k = np.arange(1, n + 1)
    ang = 2 * math.pi * k / n
    p0 = np.stack([1000 + 600 * np.cos(ang), 1000 + 600 * np.sin(ang), 100 + k], axis=1)
    v = np.stack([15 * np.sin(ang + 1), 15 * np.cos(ang + 1), 0.2 * np.ones(n)], axis=1)
    pos = np.vstack([[1000.0, 1000.0, 120.0], p0 + v * t])
    vel = np.vstack([[0.0, 20.0, 0.0], v])
    att = np.zeros((n + 1, 3))
    att[0, 2] = heading_own
    return TrafficState(
        t=t,
        ids=("ownship", *(f"intruder-{i}" for i in k)),
        pos=pos,
        vel=vel,
        att=att,
        airspeed=np.full(n + 1, 20.0),
    )


def fly(surv: Surveillance, n: int, seconds: float) -> list[Report]:
    out = []
    for step in range(round(seconds / DT) + 1):
        out += surv.observe(straight_traffic(n, round(step * DT, 9)))
    return out


def truth_at(ident: str, t: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    s = straight_traffic(n, t)
    i = s.ids.index(ident)
    return s.pos[i], s.vel[i]


def test_sigma_conversion_gives_the_95_percent_radius():
    # per-axis sigma s of a circular Gaussian: P(r <= EPU) = 1 - exp(-EPU^2 / 2 s^2) = 0.95
    for nacp, epu in NACP_EPU_M.items():
        s, _ = nacp_sigmas(nacp)
        assert 1 - math.exp(-(epu**2) / (2 * s**2)) == pytest.approx(0.95, abs=1e-12)
    assert nacp_sigmas(10)[0] == pytest.approx(10 / 2.4477, rel=1e-4)
    assert nacp_sigmas(8)[0] == pytest.approx(92.6 / 2.4477, rel=1e-4)


@pytest.mark.parametrize("nacp,nacv", [(10, 2), (9, 1), (8, 3)])
def test_position_and_velocity_errors_match_their_category(nacp, nacv):
    """95 % of horizontal position errors within the EPU of the NACp, 95 % of horizontal
    velocity errors within the bound of the NACv (binomial 4-sigma bounds)."""
    n = 40
    cfg = SurveillanceConfig(nacp=nacp, nacv=nacv, latency_s=0.0, dropout=0.0)
    reports = fly(Surveillance(cfg, seed=3), n, 60.0)
    assert len(reports) >= 40 * 59
    dp, dv = [], []
    for r in reports:
        p, v = truth_at(r.id, r.t_measured, n)
        dp.append(math.hypot(*(r.pos[:2] - p[:2])))
        dv.append(math.hypot(*(r.vel[:2] - v[:2])))
    k = len(reports)
    bound = 4 * math.sqrt(0.95 * 0.05 / k)
    inside_p = np.mean(np.array(dp) <= NACP_EPU_M[nacp])
    inside_v = np.mean(np.array(dv) <= NACV_HFOM_MPS[nacv])
    assert abs(inside_p - 0.95) < bound, inside_p
    assert abs(inside_v - 0.95) < bound, inside_v


def test_reports_come_at_the_rate_and_are_delivered_latency_later():
    n, latency = 10, 0.7
    cfg = SurveillanceConfig(rate_hz=2.0, nacp=11, nacv=4, latency_s=latency, dropout=0.0)
    surv = Surveillance(cfg, seed=1)
    delivered: list[tuple[float, Report]] = []
    for step in range(round(30 / DT) + 1):
        t = round(step * DT, 9)
        delivered += [(t, r) for r in surv.observe(straight_traffic(n, t))]
    for t, r in delivered:
        # delivered time = measured time + latency, and handed over at that instant
        assert r.t_delivered == pytest.approx(r.t_measured + latency, abs=1e-9)
        assert t == pytest.approx(r.t_delivered, abs=1e-9)
        # the report describes the state at t_measured (NACp 11: sigma 1.2 m)
        p, _ = truth_at(r.id, r.t_measured, n)
        assert np.linalg.norm(r.pos[:2] - p[:2]) < 10.0
        p_now, _ = truth_at(r.id, t, n)
        assert np.linalg.norm(r.pos[:2] - p_now[:2]) > 5.0  # 15 m/s x 0.7 s ago, not now
    for k in range(1, n + 1):
        times = np.array([r.t_measured for _, r in delivered if r.id == f"intruder-{k}"])
        assert np.allclose(np.diff(times), 0.5, atol=1e-6)  # 2 Hz, no gaps without dropout
        assert len(times) in (58, 59)  # measured in [phase, 30 - 0.7]


def test_dropout_share_is_within_the_binomial_bound():
    n, p = 40, 0.2
    cfg = SurveillanceConfig(dropout=p, latency_s=0.0)
    surv = Surveillance(cfg, seed=11)
    reports = fly(surv, n, 100.0)
    assert surv.sent >= 40 * 99
    share = surv.lost / surv.sent
    assert abs(share - p) < 4 * math.sqrt(p * (1 - p) / surv.sent)
    assert len(reports) == surv.sent - surv.lost


def test_noncooperative_intruders_send_nothing_and_the_share_holds():
    ids = [f"intruder-{k}" for k in range(1, 2001)]
    coop = np.array([is_cooperative(i, 0.3, seed=5) for i in ids])
    assert abs((~coop).mean() - 0.3) < 4 * math.sqrt(0.3 * 0.7 / len(ids))
    # with no sensor, non-cooperative intruders are never reported
    n = 30
    cfg = SurveillanceConfig(noncooperative=0.3, dropout=0.0, sensor=None)
    reports = fly(Surveillance(cfg, seed=5), n, 10.0)
    heard = {r.id for r in reports}
    expected = {f"intruder-{k}" for k in range(1, n + 1) if is_cooperative(f"intruder-{k}", 0.3, 5)}
    assert heard == expected
    assert 0 < len(heard) < n


def test_the_onboard_sensor_sees_only_within_range_and_field_of_view():
    n = 24  # on a 600 m circle around the ownship, which heads north
    sensor = SensorConfig(range_m=700.0, fov_deg=100.0, sigma_m=5.0)
    cfg = SurveillanceConfig(noncooperative=1.0, sensor=sensor, dropout=0.0)
    reports = Surveillance(cfg, seed=2).observe(straight_traffic(n, 0.0))
    reports += fly(Surveillance(cfg, seed=2), n, 1.0)
    s = straight_traffic(n, 0.0)
    d = s.pos[1:] - s.pos[0]
    bearing = np.degrees(np.arctan2(d[:, 0], d[:, 1]))
    # bearings 15 deg apart, none near the 50 deg edge: 1 s of motion changes nothing
    visible = {s.ids[i + 1] for i in np.flatnonzero(np.abs(bearing) <= 50.0)}
    assert {r.id for r in reports} == visible
    assert all(r.source == "sensor" and r.vel is None for r in reports)
    assert all(r.t_delivered == r.t_measured for r in reports)  # onboard: no latency
    short = SurveillanceConfig(
        noncooperative=1.0, sensor=SensorConfig(range_m=500.0, fov_deg=360.0)
    )
    assert fly(Surveillance(short, seed=2), n, 2.0) == []  # all 600 m away: out of range


def test_truth_model_gives_exact_states_at_every_call():
    s = straight_traffic(5, 3.0)
    reports = Surveillance(SurveillanceConfig(model="truth"), seed=0).observe(s)
    assert [r.id for r in reports] == list(s.ids[1:])
    for i, r in enumerate(reports, start=1):
        assert np.array_equal(r.pos, s.pos[i]) and np.array_equal(r.vel, s.vel[i])
        assert r.t_measured == r.t_delivered == 3.0


def test_same_seed_same_reports_other_seed_other_reports():
    cfg = SurveillanceConfig(noncooperative=0.2)
    a = fly(Surveillance(cfg, seed=7), 10, 20.0)
    b = fly(Surveillance(cfg, seed=7), 10, 20.0)
    c = fly(Surveillance(cfg, seed=8), 10, 20.0)
    key = [(r.id, r.t_measured, *r.pos) for r in a]
    assert key == [(r.id, r.t_measured, *r.pos) for r in b]
    assert key != [(r.id, r.t_measured, *r.pos) for r in c]


def test_bad_settings_name_the_field():
    with pytest.raises(UserError, match="surveillance.nacp"):
        SurveillanceConfig(nacp=12)
    with pytest.raises(UserError, match="surveillance.nacv"):
        SurveillanceConfig(nacv=0)
    with pytest.raises(UserError, match="surveillance.dropout"):
        SurveillanceConfig(dropout=1.0)
    with pytest.raises(UserError, match="surveillance.model"):
        SurveillanceConfig(model="radar")
    with pytest.raises(UserError, match="surveillance.sensor.fov_deg"):
        SensorConfig(fov_deg=400)


def test_from_scenario_reads_what_is_there_and_defaults_the_rest():
    sc = default_scenario(surveillance={"nacp": 9, "latency_s": 1.0, "sensor": {"range_m": 2000}})
    cfg = SurveillanceConfig.from_scenario(sc)
    assert (cfg.nacp, cfg.latency_s, cfg.nacv, cfg.model) == (9, 1.0, 2, "adsb")
    assert cfg.sensor == SensorConfig(range_m=2000.0)
    assert SurveillanceConfig.from_scenario(default_scenario()) == SurveillanceConfig()


def test_adsb_vehicle_round_trip_through_pymavlink():
    """Report -> ADSB_VEHICLE bytes (real MAVLink 2 packing) -> parsed -> report: the
    precision lost is bounded by the message's units."""
    frame = LocalFrame(34.1230, 108.8370, 400.0)
    cfg = SurveillanceConfig(latency_s=0.5)
    sender = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    sender.robust_parsing = True
    receiver = mavlink.MAVLink(None)
    rng = np.random.default_rng(0)
    for k in range(1, 200):
        speed, course = rng.uniform(0.6, 40), rng.uniform(0, 2 * math.pi)
        r = Report(
            id=f"intruder-{k}",
            t_measured=10.0,
            t_delivered=10.5,
            pos=np.array([rng.uniform(-3000, 5000), rng.uniform(-3000, 5000), rng.uniform(0, 500)]),
            vel=np.array([speed * math.sin(course), speed * math.cos(course), rng.uniform(-5, 5)]),
            sigma_pos=cfg.sigma_pos,
            sigma_vel=cfg.sigma_vel,
            source="adsb",
        )
        raw = adsb_message(r, frame).pack(sender)
        msgs = receiver.parse_buffer(raw)
        assert len(msgs) == 1 and msgs[0].get_type() == "ADSB_VEHICLE"
        back = report_from_adsb(msgs[0], frame, t_received=10.5, config=cfg)
        assert back.id == r.id
        assert back.t_measured == pytest.approx(10.0)
        # degE7 is 1.1 cm in latitude, less in longitude; altitude in mm
        assert np.abs(back.pos[:2] - r.pos[:2]).max() < 0.02
        assert abs(back.pos[2] - r.pos[2]) <= 0.0005 + 1e-9
        # cm/s speed and 0.01 deg course: under 1 cm/s + speed x 0.005 deg
        tol = 0.005 + speed * math.radians(0.005) + 1e-9
        assert np.abs(back.vel[:2] - r.vel[:2]).max() < 2 * tol
        assert abs(back.vel[2] - r.vel[2]) <= 0.005 + 1e-9
        assert back.sigma_pos == cfg.sigma_pos


def test_adsb_fields_use_mavlink_units():
    frame = LocalFrame(34.0, 108.0, 400.0)
    r = Report("intruder-21", 0.0, 1.0, np.array([0.0, 0.0, 100.0]), np.array([10.0, 0, 1.5]),
               (1.0, 1.0), (1.0, 1.0), "adsb")  # fmt: skip
    f = adsb_fields(r, frame)
    assert f["lat"] == 340000000 and f["lon"] == 1080000000
    assert f["altitude"] == 500000  # mm MSL
    assert f["heading"] == 9000  # course east, cdeg
    assert f["hor_velocity"] == 1000 and f["ver_velocity"] == 150
    assert f["ICAO_address"] == 0xF00000 + 21 and f["tslc"] == 1
    assert f["flags"] & mavlink.ADSB_FLAGS_VALID_VELOCITY
