"""DAA metrics: well-clear and NMAC cylinders, miss distances, weighted estimators (coverage
on an importance-sampled population), paired risk ratios, the interval check, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.daa_metrics import (
    CHECKED_RATIOS,
    WELL_CLEAR_HORIZONTAL_M,
    WELL_CLEAR_VERTICAL_M,
    alert_rate,
    ci_check,
    daa_summary,
    hmd_vmd,
    induced_risk_ratio,
    loss_of_well_clear,
    lowc_ratio,
    lowc_severity,
    path_excess,
    reversals,
    unnecessary_manoeuvre_rate,
    weighted_prob,
    weighted_risk_ratio,
)
from uavxai.errors import UserError
from uavxai.metrics import NMAC_HORIZONTAL_M, NMAC_VERTICAL_M, nmac

HOVER = np.array([[0.0, 0.0, 100.0], [0.0, 0.0, 100.0]])  # the ownship still at the origin


def crossing(offset: float, dz: float) -> np.ndarray:
    """Two samples 10 km apart; the straight line between them passes ``offset`` m beside and
    ``dz`` m above the hovering ownship, half-way (never near it at a sample)."""
    return np.array([[-5000.0, offset, 100.0 + dz], [5000.0, offset, 100.0 + dz]])


# ------------------------------------------------------------------------------ cylinders
def test_cylinder_sizes_are_the_documented_ones():
    assert abs(WELL_CLEAR_HORIZONTAL_M - 609.6) < 1e-9  # 2000 ft
    assert abs(WELL_CLEAR_VERTICAL_M - 76.2) < 1e-9  # 250 ft
    assert abs(NMAC_HORIZONTAL_M - 152.4) < 1e-9  # 500 ft
    assert abs(NMAC_VERTICAL_M - 30.48) < 1e-9  # 100 ft


@pytest.mark.parametrize(
    ("offset", "dz", "lowc", "is_nmac"),
    [
        (0.0, 0.0, True, True),  # straight through, between the two samples
        (609.0, 0.0, True, False),  # just inside well clear horizontally
        (610.0, 0.0, False, False),  # just outside horizontally
        (0.0, 76.0, True, False),  # just inside vertically
        (0.0, -76.4, False, False),  # just outside vertically (below)
        (152.0, 30.3, True, True),  # just inside the NMAC cylinder
        (153.0, 0.0, True, False),  # just outside NMAC horizontally
        (0.0, 30.6, True, False),  # just outside NMAC vertically
    ],
)
def test_lowc_and_nmac_between_samples(offset, dz, lowc, is_nmac):
    intr = crossing(offset, dz)
    assert loss_of_well_clear(HOVER, intr) is lowc
    assert nmac(HOVER, intr[:, None, :]).tolist() == [is_nmac]


def test_lowc_needs_both_dimensions_at_the_same_time():
    # horizontally inside early (but 200 m above), vertically inside late (but 2 km away)
    own = np.zeros((3, 3))
    intr = np.array([[0.0, 0.0, 200.0], [0.0, 0.0, 200.0], [2000.0, 0.0, 0.0]])
    assert loss_of_well_clear(own, intr) is False
    with pytest.raises(UserError):
        loss_of_well_clear(own, intr[:2])


def test_lowc_severity_is_the_deepest_penetration():
    assert lowc_severity(HOVER, crossing(0.0, 0.0)) == pytest.approx(1.0, abs=1e-9)
    assert lowc_severity(HOVER, crossing(WELL_CLEAR_HORIZONTAL_M / 2, 0.0)) == pytest.approx(
        0.5, abs=1e-9
    )
    # vertical is the shallower dimension: 3/4 of 76.2 m above, straight through horizontally
    assert lowc_severity(HOVER, crossing(0.0, 0.75 * WELL_CLEAR_VERTICAL_M)) == pytest.approx(
        0.25, abs=1e-9
    )
    assert lowc_severity(HOVER, crossing(700.0, 0.0)) == 0.0
    # the closest point a fifth of the way along the piece, not at a sample nor half-way
    skew = np.array([[-2000.0, 152.4, 100.0], [8000.0, 152.4, 100.0]])
    assert lowc_severity(HOVER, skew) == pytest.approx(0.75, abs=1e-9)


def test_hmd_vmd_at_the_closest_horizontal_approach_between_samples():
    own = np.zeros((2, 3))
    intr = np.array([[-1000.0, 100.0, 0.0], [1000.0, 100.0, 40.0]])  # climbing through
    hmd, vmd = hmd_vmd(own, intr)
    assert hmd == pytest.approx(100.0)
    assert vmd == pytest.approx(20.0)  # half-way up, where the horizontal approach is closest


def test_path_excess_and_reversals():
    straight = np.array([[0.0, 0.0, 100.0], [500.0, 0.0, 100.0], [1000.0, 0.0, 100.0]])
    detour = np.array([[0.0, 0.0, 100.0], [500.0, 500.0, 100.0], [1000.0, 0.0, 100.0]])
    assert path_excess(straight, straight) == pytest.approx(0.0)
    assert path_excess(detour, straight) == pytest.approx(math.sqrt(2) - 1)
    assert reversals([0, 5, 5, 0, -5, -5, 5]) == 2  # right, (level), left, right
    assert reversals([0, 0, 0]) == 0
    assert reversals([1, -1, 10, -10], deadband=2) == 1  # +-1 inside the deadband


# ---------------------------------------------------------------- weighted estimators
P_TRUE = 0.01  # nominal: x ~ U(0, 10), event x < 0.1


def importance_sample(seed: int, n: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Events and weights from a proposal half concentrated on U(0, 0.2), half nominal."""
    rng = np.random.default_rng(seed)
    near = rng.random(n) < 0.5
    x = np.where(near, 0.2 * rng.random(n), 10.0 * rng.random(n))
    proposal = 0.5 * 5.0 * (x < 0.2) + 0.5 * 0.1
    return x < 0.1, 0.1 / proposal


def test_weighted_estimate_covers_the_truth_and_the_unweighted_one_does_not():
    covered = {"self": 0, "plain": 0, "unweighted": 0}
    for rep in range(100):
        e, w = importance_sample(rep)
        ests = {
            "self": weighted_prob(e, w, n_boot=500, seed=rep),
            "plain": weighted_prob(e, w, self_normalized=False, n_boot=500, seed=rep),
            "unweighted": weighted_prob(e, np.ones_like(w), n_boot=500, seed=rep),
        }
        for k, est in ests.items():
            covered[k] += est.lo <= P_TRUE <= est.hi
    assert covered["self"] >= 90, covered
    assert covered["plain"] >= 90, covered
    assert covered["unweighted"] <= 10, covered  # ~0.255: the proposal's own event rate


def test_weighted_prob_zero_events_uses_the_effective_sample_size():
    est = weighted_prob(np.zeros(4, bool), [1.0, 1.0, 1.0, 3.0])
    assert (est.value, est.lo) == (0.0, 0.0)
    assert est.hi == pytest.approx(3.0 / (36.0 / 12.0))  # n_eff = (sum w)^2 / sum w^2 = 3
    assert weighted_prob(np.zeros(2, bool), [1.0, 1.0]).hi == 1.0  # capped at 1


# ------------------------------------------------------------------ paired risk ratios
def paired_population(seed: int = 0, n: int = 400):
    rng = np.random.default_rng(seed)
    none = rng.random(n) < 0.3
    w = rng.uniform(0.2, 3.0, n)
    return none, w


def test_method_equal_to_none_gives_one_with_a_narrow_interval():
    none, w = paired_population()
    rr = weighted_risk_ratio(none, none, w)
    assert rr.value == pytest.approx(1.0)
    assert rr.hi - rr.lo < 1e-12  # paired: every resample gives exactly 1
    assert ci_check(rr.value, rr.lo, rr.hi) == "ok"


def test_method_without_events_gives_zero_and_a_finite_upper_bound():
    none, w = paired_population()
    rr = weighted_risk_ratio(np.zeros_like(none), none, w)
    assert (rr.value, rr.lo) == (0.0, 0.0)
    n_eff = w[none].sum() ** 2 / (w[none] ** 2).sum()
    assert rr.hi == pytest.approx(3.0 / n_eff)
    assert 0 < rr.hi < 1
    assert 3.0 / n_eff > 3.0 / none.sum()  # unequal weights widen the rule of three
    ones = weighted_risk_ratio(np.zeros_like(none), none, np.ones_like(w))
    assert ones.hi == pytest.approx(3.0 / none.sum())  # equal weights: metrics.risk_ratio's


def test_baseline_without_events_gives_nan():
    none = np.zeros(50, bool)
    for f in (weighted_risk_ratio, induced_risk_ratio, lowc_ratio):
        est = f(~none, none, np.ones(50))
        assert all(math.isnan(x) for x in (est.value, est.lo, est.hi))


def test_induced_ratio_counts_only_method_only_events():
    none = np.array([1, 1, 0, 0, 0, 1], bool)
    method = np.array([1, 0, 1, 0, 1, 0], bool)
    w = np.array([1.0, 2.0, 4.0, 8.0, 0.5, 3.0])
    induced = induced_risk_ratio(method, none, w, n_boot=200)
    assert induced.value == pytest.approx((4.0 + 0.5) / (1.0 + 2.0 + 3.0))
    assert induced.events == 2
    rr = weighted_risk_ratio(method, none, w, n_boot=200)
    assert rr.value == pytest.approx((1.0 + 4.0 + 0.5) / 6.0)
    assert induced.lo <= induced.value <= induced.hi


def test_unnecessary_manoeuvres_are_those_where_none_stayed_well_clear():
    lowc_none = np.array([1, 1, 0, 0, 0], bool)
    manoeuvre = np.array([1, 0, 1, 0, 1], bool)
    w = np.array([5.0, 1.0, 1.0, 2.0, 3.0])
    est = unnecessary_manoeuvre_rate(manoeuvre, lowc_none, w, n_boot=200)
    assert est.value == pytest.approx((1.0 + 3.0) / (1.0 + 2.0 + 3.0))
    assert alert_rate(manoeuvre, w, n_boot=200).value == pytest.approx(9.0 / 12.0)


def test_ci_check_half_width_rule():
    assert ci_check(0.05, 0.04, 0.07) == "ok"  # half-width 0.015 <= 0.025
    assert ci_check(0.05, 0.01, 0.12) == "wide"  # half-width 0.055 > 0.025
    assert ci_check(0.0, 0.0, 0.3) == "wide"
    assert ci_check(math.nan, math.nan, math.nan) == "wide"
    assert ci_check(0.5, 0.3, math.inf) == "wide"


def test_same_seed_same_intervals_and_another_seed_differs():
    none, w = paired_population()
    method = none & (np.arange(none.size) % 3 == 0)
    a = weighted_risk_ratio(method, none, w, seed=7)
    b = weighted_risk_ratio(method, none, w, seed=7)
    c = weighted_risk_ratio(method, none, w, seed=8)
    assert (a.lo, a.hi) == (b.lo, b.hi)
    assert (a.lo, a.hi) != (c.lo, c.hi)


def test_daa_summary_columns_and_checks():
    none, w = paired_population(n=600)
    rng = np.random.default_rng(1)
    lowc_none = none | (rng.random(none.size) < 0.3)
    cols_none = {"nmac": none, "lowc": lowc_none, "alert": np.zeros_like(none),
                 "manoeuvre": np.zeros_like(none), "reversals": np.zeros(none.size),
                 "path_excess": np.zeros(none.size)}  # fmt: skip
    good = {"nmac": none & (rng.random(none.size) < 0.5), "lowc": lowc_none,
            "alert": np.ones_like(none), "manoeuvre": lowc_none | (rng.random(none.size) < 0.1),
            "reversals": np.full(none.size, 2.0)}  # fmt: skip
    rare = {**good, "nmac": np.zeros_like(none)}
    out = daa_summary({"none": cols_none, "good": good, "rare": rare}, w, n_boot=300)
    names = ["nmac_prob", "nmac_risk_ratio", "induced_risk_ratio", "lowc_prob", "lowc_ratio",
             "alert_rate", "unnecessary_manoeuvre_rate"]  # fmt: skip
    for row in out.values():
        for name in names:
            assert row[f"{name}_lo"] <= row[name] <= row[f"{name}_hi"]
    assert out["none"]["nmac_risk_ratio"] == pytest.approx(1.0)
    assert out["none"]["ci_check"] == "ok"
    assert out["good"]["ci_check"] == "ok"  # ~0.5 on ~90 baseline NMACs: a tight interval
    assert out["good"]["reversals"] == pytest.approx(2.0)
    assert math.isnan(out["good"]["path_excess"])
    assert out["good"]["alert_rate"] == pytest.approx(1.0)
    assert out["rare"]["nmac_risk_ratio"] == 0.0
    assert out["rare"]["ci_check"] == "wide"  # zero NMACs cannot state the ratio
    assert CHECKED_RATIOS == ("nmac_risk_ratio", "lowc_ratio")
    with pytest.raises(UserError):
        daa_summary({"good": good}, w)
    with pytest.raises(UserError):
        weighted_prob(none, np.where(np.arange(none.size) == 0, 0.0, w))
