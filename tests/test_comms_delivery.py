"""Delivered service and orbit-averaged rates, against the channel equations worked directly."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest

from uavxai.comms.channel import ENVIRONMENTS, Channel, draw_users
from uavxai.comms.delivery import SERVICE_COLUMNS, USERS_COLUMNS, Delivery, rates_at
from uavxai.comms.mobility import UserMobility
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.service import orbit_rate
from uavxai.service.orbit_rate import orbit_average, orbit_points, orbit_position

C = 299_792_458.0


def f(v: float) -> str:
    """A float as the CSV files hold it: the shortest text that reads back exactly."""
    return repr(float(v))


def channel(access: str = "shared", fading: str = "none", k: int = 10, **comms) -> Channel:
    sc = default_scenario(
        comms={"access": access, "fading": fading, "users": {"count": k}, **comms}
    )
    return Channel.from_scenario(sc)


def rates_by_hand(ch: Channel, uav: np.ndarray, users: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Eqs (1)-(5) written out again, one sample: rates (K,) in bit/s."""
    a, b, eta_los, eta_nlos = ENVIRONMENTS[ch.environment]
    out = []
    for k in range(len(users)):
        d = math.dist(uav, users[k])
        theta = math.degrees(math.asin(uav[2] / d))
        p_los = 1.0 / (1.0 + a * math.exp(-b * (theta - a)))
        loss = 20 * math.log10(4 * math.pi * ch.carrier_hz * d / C)
        loss += p_los * eta_los + (1 - p_los) * eta_nlos
        g = 10 ** (-loss / 10)
        if ch.access == "shared":
            sinr = g * p[k] / (g * (p.sum() - p[k]) + ch.noise_w)
            bw = ch.bandwidth_hz
        else:
            sinr = g * p[k] / (ch.noise_w / len(users))
            bw = ch.bandwidth_hz / len(users)
        out.append(bw * math.log2(1 + sinr))
    return np.array(out)


# ---------------------------------------------------------------------- recompute from logs
@pytest.mark.parametrize("access", ["shared", "ofdma"])
def test_delivered_bits_recomputed_from_logged_positions(access):
    """users.csv + the ownship's trajectory + eqs (1)-(5) give Delivery's total to 1e-9."""
    ch = channel(access)
    rng = np.random.default_rng(1)
    power = rng.uniform(0.0, 0.2, ch.k)
    power[3] = 0.0  # one user not served
    walk = UserMobility(
        ch.users, {"x": [750, 1250], "y": [750, 1250]}, "random_waypoint", pause_s=(0, 5), seed=1
    )
    delivery = Delivery(ch, power, rng=np.random.default_rng(2))
    dt, centre, radius = 0.1, np.array([1000.0, 1000.0, 100.0]), 80.0
    users_log, traj_log, service_log = io.StringIO(), io.StringIO(), io.StringIO()
    uw, tw, sw = csv.writer(users_log), csv.writer(traj_log), csv.writer(service_log)
    uw.writerow(USERS_COLUMNS)
    tw.writerow(("t", "id", "x", "y", "h"))
    sw.writerow(SERVICE_COLUMNS)
    for n in range(600):  # a minute on station at 10 Hz, one lap of the orbit and a bit
        t = n * dt
        uav = orbit_position(centre, radius, 0.0, t, 20.0)
        users = walk.positions
        tw.writerow((f(t), "ownship", *map(f, uav)))
        uw.writerows((f(t), j, f(users[j, 0]), f(users[j, 1])) for j in range(ch.k))
        sw.writerows(delivery.sample(t, uav, users, dt))
        walk.advance(dt)
    summary = delivery.summary()

    # Recompute from the tables alone.
    traj = {
        float(r["t"]): np.array([float(r[c]) for c in "xyh"])
        for r in csv.DictReader(io.StringIO(traj_log.getvalue()))
    }
    users_at: dict[float, np.ndarray] = {}
    for r in csv.DictReader(io.StringIO(users_log.getvalue())):
        users_at.setdefault(float(r["t"]), np.zeros((ch.k, 3)))[int(r["user"])] = (
            float(r["x"]),
            float(r["y"]),
            0.0,
        )
    times = sorted(traj)
    per_user = np.zeros(ch.k)
    for t in times:
        per_user += rates_by_hand(ch, traj[t], users_at[t], power) * dt
    assert summary["delivered_bits"] == pytest.approx(per_user.sum(), rel=1e-9)
    np.testing.assert_allclose(summary["delivered_bits_per_user"], per_user, rtol=1e-9)
    assert summary["delivered_bits_per_user"][3] == 0.0
    # service.csv carries the same rates.
    rows = list(csv.DictReader(io.StringIO(service_log.getvalue())))
    assert len(rows) == len(times) * ch.k
    assert sum(float(r["rate_bps"]) for r in rows) * dt == pytest.approx(per_user.sum(), 1e-9)
    assert all(r["sinr_db"] == "-inf" for r in rows if r["user"] == "3")
    # The users did walk: the check is not a static one.
    assert np.abs(users_at[times[-1]] - users_at[times[0]]).max() > 5.0


# ---------------------------------------------------------------------- the accumulator
def test_single_sample_is_the_channel_at_that_point():
    ch = channel("shared")
    p = ch.equal_power()
    uav = np.array([1000.0, 950.0, 120.0])
    d = Delivery(ch, p, rng=np.random.default_rng(0))
    rows = d.sample(3.0, uav, ch.users, 0.5)
    link = ch.evaluate(uav, p)
    assert [r[:2] for r in rows] == [(3.0, j) for j in range(ch.k)]
    np.testing.assert_allclose([r[4] for r in rows], link.rate_bps, rtol=1e-12)
    np.testing.assert_allclose([r[3] for r in rows], link.sinr_db, rtol=1e-12)
    np.testing.assert_allclose(d.summary()["delivered_bits"], link.sum_rate_bps * 0.5)


def test_qos_share_and_jain_by_counting():
    ch = channel("ofdma", k=4)
    p = np.array([0.4, 0.3, 0.2, 0.0])
    d = Delivery(ch, p, qos_rate_bps=1.0, rng=np.random.default_rng(0))
    uav = np.array([1000.0, 1000.0, 100.0])
    d.sample([0.0, 1.0], [uav, uav], ch.users, [1.0, 3.0])
    s = d.summary()
    # Three of four users meet any QoS of 1 bit/s for all 4 s; the unserved one never.
    assert s["qos_user_seconds_share"] == pytest.approx(0.75)
    x = np.asarray(s["delivered_bits_per_user"])
    assert x[3] == 0.0
    assert s["jain_fairness"] == pytest.approx(x.sum() ** 2 / (4 * (x**2).sum()))
    assert s["service_time_s"] == 4.0
    # Now a QoS above what user 2 gets: its user-seconds drop out.
    r = d.last.rate_bps[0]
    d2 = Delivery(ch, p, qos_rate_bps=float(np.sort(r)[-2] + 1.0), rng=np.random.default_rng(0))
    d2.sample(0.0, uav, ch.users, 2.0)
    assert d2.summary()["qos_user_seconds_share"] == pytest.approx(0.25)


def test_jain_extremes():
    ch = channel("ofdma", k=5)
    uav = np.array([1000.0, 1000.0, 100.0])
    only_one = Delivery(ch, [1.0, 0, 0, 0, 0])
    only_one.sample(0.0, uav, ch.users, 1.0)
    assert only_one.summary()["jain_fairness"] == pytest.approx(1 / 5)
    # Users on a circle under the UAV all get the same: perfectly fair.
    ring = np.column_stack(
        [1000 + 50 * np.cos(np.arange(5)), 1000 + 50 * np.sin(np.arange(5)), np.zeros(5)]
    )
    same = Delivery(ch, np.full(5, 0.2))
    same.sample(0.0, uav, ring, 1.0)
    assert same.summary()["jain_fairness"] == pytest.approx(1.0, abs=1e-12)
    nothing = Delivery(ch, np.zeros(5))
    nothing.sample(0.0, uav, ring, 1.0)
    assert nothing.summary()["jain_fairness"] == 0.0


@pytest.mark.parametrize("fading", ["rayleigh", "rician"])
def test_batch_equals_one_by_one_and_avoidance_does_not_shift_the_stream(fading):
    ch = channel("shared", fading)
    p = ch.equal_power()
    n = 50
    t = np.arange(n) * 0.1
    uav = orbit_position([1000, 1000, 100], 80.0, 0.0, t, 20.0)
    planned = orbit_position([1000, 1000, 100], 80.0, 0.3, t, 20.0)
    avoiding = (t > 2.0) & (t < 4.0)
    batch = Delivery(ch, p, rng=np.random.default_rng(5))
    rows_b = batch.sample(t, uav, ch.users, 0.1, planned_pos=planned, avoiding=avoiding)
    one = Delivery(ch, p, rng=np.random.default_rng(5))
    rows_1 = [
        r
        for i in range(n)
        for r in one.sample(t[i], uav[i], ch.users, 0.1, planned[i], bool(avoiding[i]))
    ]
    np.testing.assert_allclose(np.array(rows_b), np.array(rows_1), rtol=1e-12)
    sb, s1 = batch.summary(), one.summary()
    np.testing.assert_allclose(
        sb.pop("delivered_bits_per_user"), s1.pop("delivered_bits_per_user"), rtol=1e-12
    )
    assert sb == pytest.approx(s1, rel=1e-12)
    assert sb["avoidance_lost_bits"] != 0.0
    plain = Delivery(ch, p, rng=np.random.default_rng(5))
    rows_p = plain.sample(t, uav, ch.users, 0.1)
    np.testing.assert_array_equal(np.array(rows_p), np.array(rows_b))
    assert plain.summary()["avoidance_lost_bits"] == 0.0
    # Fading really is drawn: not the fading-free rates.
    free = Delivery(ch, p).sample(t, uav, ch.users, 0.1)
    assert np.abs(np.array(free)[:, 4] - np.array(rows_b)[:, 4]).max() > 1e3


def test_avoidance_loss_uses_the_same_fading_draw():
    ch = channel("ofdma", "rayleigh")
    p = ch.equal_power()
    centre = np.array([1000.0, 1000.0, 100.0])
    t = np.arange(100) * 0.1
    planned = orbit_position(centre, 80.0, 0.0, t, 20.0)
    flown = planned + np.array([400.0, 0.0, 40.0])  # the escape takes it well away
    d = Delivery(ch, p, rng=np.random.default_rng(3))
    d.sample(t, flown, ch.users, 0.1, planned_pos=planned, avoiding=True)
    s = d.summary()
    # The same fading at the planned points, by a twin accumulator with the same seed.
    twin = Delivery(ch, p, rng=np.random.default_rng(3))
    twin.sample(t, planned, ch.users, 0.1)
    expected = twin.summary()["delivered_bits"] - s["delivered_bits"]
    assert s["avoidance_lost_bits"] == pytest.approx(expected, rel=1e-12)
    assert s["avoidance_lost_bits"] > 0.1 * s["delivered_bits"]
    assert s["avoiding_s"] == pytest.approx(10.0)
    np.testing.assert_allclose(d.last.planned_rate_bps, twin.last.rate_bps, rtol=1e-12)
    # Flying the planned orbit while "avoiding" loses nothing, exactly, whatever the fading.
    same = Delivery(ch, p, rng=np.random.default_rng(3))
    same.sample(t, planned, ch.users, 0.1, planned_pos=planned, avoiding=True)
    assert same.summary()["avoidance_lost_bits"] == 0.0


def test_power_changes_on_replan_and_bad_power_is_refused():
    ch = channel("shared", k=3)
    uav = np.array([1000.0, 1000.0, 100.0])
    d = Delivery(ch, [0.1, 0.1, 0.1])
    d.sample(0.0, uav, ch.users, 1.0)
    d.set_power([0.0, 0.5, 0.0])
    rows = d.sample(1.0, uav, ch.users, 1.0)
    assert [r[2] for r in rows] == [0.0, 0.5, 0.0]
    assert rows[0][4] == 0.0 and rows[1][4] > 0.0
    with pytest.raises(UserError, match="3 finite powers"):
        d.set_power([0.1, 0.1])
    with pytest.raises(UserError, match="3 finite powers"):
        Delivery(ch, [0.1, -0.1, 0.1])
    with pytest.raises(UserError, match="K = 3"):
        rates_at(ch, uav, np.zeros((4, 3)), np.full(3, 0.1))


# ---------------------------------------------------------------------- orbit averages
def test_orbit_points_follow_the_heading_convention():
    pts = orbit_points([100.0, 200.0, 90.0], 50.0, n_points=4)
    np.testing.assert_allclose(
        pts, [[100, 250, 90], [150, 200, 90], [100, 150, 90], [50, 200, 90]], atol=1e-9
    )
    # Clockwise from north: a quarter lap later the aircraft is east of the centre.
    quarter = 0.5 * math.pi * 50.0 / 20.0
    np.testing.assert_allclose(
        orbit_position([100, 200, 90], 50, 0.0, quarter, 20.0), [150, 200, 90], atol=1e-9
    )
    np.testing.assert_allclose(
        orbit_position([100, 200, 90], 50, 0.0, quarter, 20.0, False), [50, 200, 90], atol=1e-9
    )
    assert orbit_rate.orbit_bearing([100, 200, 90], [150, 200, 90]) == pytest.approx(math.pi / 2)


@pytest.mark.parametrize("access", ["shared", "ofdma"])
def test_orbit_average_is_the_mean_over_the_circle(access):
    ch = channel(access)
    p = ch.equal_power()
    centre = np.array([990.0, 1010.0, 100.0])
    avg = orbit_average(ch, centre, 80.0, p, n_points=36)
    pts = orbit_points(centre, 80.0, 36)
    rates = np.array([rates_by_hand(ch, q, ch.users, p) for q in pts])
    np.testing.assert_allclose(avg.rate_bps, rates.mean(axis=0), rtol=1e-9)
    assert avg.sum_rate_bps == pytest.approx(rates.sum(axis=1).mean(), rel=1e-9)
    assert avg.objective == pytest.approx(ch.objective(rates.mean(axis=0)), rel=1e-9)
    assert avg.mean_objective == pytest.approx(ch.objective(rates).mean(), rel=1e-9)
    assert avg.min_sum_rate_bps == pytest.approx(rates.sum(axis=1).min(), rel=1e-9)
    # 36 points are enough: a 3600-point average agrees to 1e-4.
    fine = orbit_average(ch, centre, 80.0, p, n_points=3600)
    np.testing.assert_allclose(avg.rate_bps, fine.rate_bps, rtol=1e-4)
    # Radius 0 is the hover point.
    hover = orbit_average(ch, centre, 0.0, p)
    link = ch.evaluate(centre, p)
    np.testing.assert_allclose(hover.rate_bps, link.rate_bps, rtol=1e-12)
    assert hover.objective == pytest.approx(float(link.objective), rel=1e-12)


def test_orbit_average_vectorises_over_centres(monkeypatch):
    ch = channel("ofdma")
    rng = np.random.default_rng(0)
    centres = np.column_stack([rng.uniform(750, 1250, (25, 2)), rng.uniform(60, 300, 25)])
    powers = rng.dirichlet(np.ones(ch.k), size=25)
    monkeypatch.setattr(orbit_rate, "CHUNK_CENTRES", 7)  # several chunks, a ragged last one
    many = orbit_average(ch, centres, 80.0, powers)
    assert many.rate_bps.shape == (25, ch.k) and many.objective.shape == (25,)
    for i in (0, 6, 7, 24):
        one = orbit_average(ch, centres[i], 80.0, powers[i])
        np.testing.assert_allclose(many.rate_bps[i], one.rate_bps, rtol=1e-12)
        assert many.objective[i] == pytest.approx(float(one.objective), rel=1e-12)
    grid = orbit_average(ch, centres.reshape(5, 5, 3), 80.0, ch.equal_power())
    assert grid.sum_rate_bps.shape == (5, 5)


def test_circling_over_a_user_costs_it_rate():
    users = np.array([[1000.0, 1000.0, 0.0], [1400.0, 1000.0, 0.0]])
    sc = default_scenario(comms={"access": "ofdma", "fading": "none"})
    ch = Channel.from_scenario(sc, users)
    p = ch.equal_power()
    hover = orbit_average(ch, [1000.0, 1000.0, 100.0], 0.0, p).rate_bps
    orbit = orbit_average(ch, [1000.0, 1000.0, 100.0], 80.0, p).rate_bps
    assert orbit[0] < hover[0]  # the user underneath: 100 m becomes 128 m at low elevation
    assert orbit[1] > hover[1]  # the far user: half the lap is closer


def test_bad_orbit_arguments():
    ch = channel()
    with pytest.raises(UserError, match="radius_m"):
        orbit_average(ch, [0, 0, 100], -1.0, ch.equal_power())
    with pytest.raises(UserError, match="n_points"):
        orbit_average(ch, [0, 0, 100], 80.0, ch.equal_power(), n_points=0)
    with pytest.raises(UserError, match="centre"):
        orbit_average(ch, [0, 100], 80.0, ch.equal_power())
    with pytest.raises(UserError, match="power_w"):
        orbit_average(ch, [0, 0, 100], 80.0, np.ones(3))


def test_users_drawn_by_the_scenario_are_the_channels():
    sc = default_scenario(comms={"fading": "none"})
    np.testing.assert_array_equal(Channel.from_scenario(sc).users, draw_users(sc))
