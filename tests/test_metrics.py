"""Campaign metrics: NMAC from trajectories, Wilson intervals, risk ratios (known values)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.errors import UserError
from uavxai.metrics import (
    NMAC_HORIZONTAL_M,
    NMAC_VERTICAL_M,
    nmac,
    rate,
    risk_ratio,
    wilson_interval,
)


def line(p0, p1, t=2):
    return np.linspace(np.asarray(p0, float), np.asarray(p1, float), t)


def test_nmac_cylinder_defaults_are_500_ft_by_100_ft():
    assert abs(NMAC_HORIZONTAL_M - 152.4) < 1e-9
    assert abs(NMAC_VERTICAL_M - 30.48) < 1e-9


def test_nmac_pass_through_between_samples():
    own = line((0, 0, 100), (0, 0, 100))  # hovering at the origin
    # both samples 1000 m away, the straight line between them passes through the ownship
    through = line((-1000, 0, 100), (1000, 0, 100))[:, None]
    assert nmac(own, through).tolist() == [True]


@pytest.mark.parametrize(
    ("offset", "dh", "expected"),
    [
        (150.0, 0.0, True),  # inside 152.4 m
        (155.0, 0.0, False),  # outside horizontally
        (0.0, 30.0, True),  # inside 30.48 m vertically
        (0.0, 31.0, False),  # outside vertically
        (0.0, -31.0, False),
    ],
)
def test_nmac_edges_of_the_cylinder(offset, dh, expected):
    own = line((0, 0, 100), (0, 400, 100), 5)
    intruder = line((offset, 400, 100 + dh), (offset, 0, 100 + dh), 5)[:, None]
    assert nmac(own, intruder)[0] == expected


def test_nmac_needs_both_conditions_at_once():
    own = line((0, 0, 100), (0, 0, 100))
    # horizontally inside only early in the piece (x from 0 to 1000 m: inside for s < 0.15),
    # vertically inside only late (h from 200 to 100 m: |dh| < 30.48 for s > 0.70)
    intruder = line((0, 0, 200), (1000, 0, 100))[:, None]
    assert nmac(own, intruder).tolist() == [False]
    # the same, but vertically inside from the start: an NMAC
    assert nmac(own, line((0, 0, 120), (1000, 0, 100))[:, None]).tolist() == [True]


def test_nmac_several_intruders_and_bad_shapes():
    own = line((0, 0, 100), (0, 200, 100), 3)
    near = line((100, 200, 110), (100, 0, 110), 3)
    far = line((900, 0, 100), (900, 200, 100), 3)
    missing = np.full((3, 3), np.nan)
    assert nmac(own, np.stack([near, far, missing], axis=1)).tolist() == [True, False, False]
    with pytest.raises(UserError, match="same T instants"):
        nmac(own, np.zeros((4, 1, 3)))
    # one own piece per intruder (a pair restarted on a replaced row): each row as alone
    far_own = line((900, 0, 100), (900, 0, 100), 3)  # standing where `far` starts
    pieces = np.stack([own, far_own, own], axis=1)
    both = np.stack([near, far, missing], axis=1)
    assert nmac(pieces, both).tolist() == [True, True, False]
    with pytest.raises(UserError, match=r"\(T, N, 3\)"):
        nmac(pieces[:, :2], both)


def test_wilson_interval_known_values():
    # textbook values (e.g. Newcombe 1998; Brown, Cai & DasGupta 2001)
    assert wilson_interval(0, 10) == pytest.approx((0.0, 0.27753), abs=1e-5)
    assert wilson_interval(5, 10) == pytest.approx((0.23659, 0.76341), abs=1e-5)
    assert wilson_interval(1, 100) == pytest.approx((0.001767, 0.054489), abs=1e-5)
    assert wilson_interval(10, 10) == pytest.approx((0.72247, 1.0), abs=1e-5)
    assert all(math.isnan(v) for v in wilson_interval(0, 0))
    with pytest.raises(UserError):
        wilson_interval(3, 2)


def test_rate_counts_events():
    r = rate([True, False, False, False])
    assert (r.k, r.n, r.rate) == (1, 4, 0.25)
    assert r.lo < 0.25 < r.hi
    assert "1/4" in str(r)


def test_risk_ratio_katz_known_value():
    n = 100
    method = np.zeros(n, bool)
    method[:10] = True
    baseline = np.zeros(n, bool)
    baseline[:20] = True
    rr = risk_ratio(method, baseline, interval="katz")
    assert rr.ratio == pytest.approx(0.5)
    # se = sqrt(1/10 - 1/100 + 1/20 - 1/100) = sqrt(0.13)
    se = math.sqrt(0.13)
    assert rr.lo == pytest.approx(0.5 * math.exp(-1.959964 * se), rel=1e-5)
    assert rr.hi == pytest.approx(0.5 * math.exp(1.959964 * se), rel=1e-5)


def test_risk_ratio_bootstrap_is_paired_and_seeded():
    rng = np.random.default_rng(1)
    baseline = rng.random(400) < 0.4
    method = baseline & (rng.random(400) < 0.25)  # removes about 3 in 4 baseline events
    a = risk_ratio(method, baseline, seed=3)
    b = risk_ratio(method, baseline, seed=3)
    assert a == b  # same seed, same interval
    assert a.ratio == pytest.approx(method.sum() / baseline.sum())
    assert a.lo < a.ratio < a.hi
    # pairing: the method's events are a subset of the baseline's, so the paired interval is
    # narrower than Katz's, which treats the samples as independent
    katz = risk_ratio(method, baseline, interval="katz")
    assert a.hi - a.lo < katz.hi - katz.lo
    # identical outcomes: every resample gives exactly 1
    same = risk_ratio(baseline, baseline)
    assert (same.ratio, same.lo, same.hi) == (1.0, 1.0, 1.0)


def test_risk_ratio_of_few_events_never_gives_nan():
    # 3 encounters: many resamples hold no baseline event (ratio inf), none may turn nan
    rr = risk_ratio([True, False, False], [True, False, False], seed=1)
    assert rr.ratio == 1.0 and rr.lo == 1.0 and not math.isnan(rr.hi)


def test_risk_ratio_zero_counts():
    baseline = np.array([True] * 30 + [False] * 70)
    none_hit = risk_ratio(np.zeros(100, bool), baseline)
    assert (none_hit.ratio, none_hit.lo) == (0.0, 0.0)
    assert none_hit.hi == pytest.approx(3.0 / 30)  # rule of three over the baseline's events
    katz = risk_ratio(np.zeros(100, bool), baseline, interval="katz")
    assert katz.ratio == 0.0 and 0.0 < katz.hi < 1.0
    undefined = risk_ratio(baseline, np.zeros(100, bool))
    assert math.isnan(undefined.ratio) and math.isnan(undefined.hi)
    with pytest.raises(UserError, match="same encounters"):
        risk_ratio(baseline, baseline[:50])
