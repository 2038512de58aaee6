"""Detect-and-avoid (DAA) metrics on importance-weighted pairwise encounters (pure functions).

Each encounter ``i`` of a campaign is flown once per method, the same encounter every time:
with ``none`` (the unequipped ownship, the baseline) and with each avoidance method. It carries
an importance weight ``w_i`` = nominal density / proposal density of the drawn encounter
(uavxai.encounters.pairing), so that weighted sums estimate what the nominal encounter
population would give. This module has two halves:

* **per-encounter events** from sampled trajectories: :func:`loss_of_well_clear` (and its
  depth :func:`lowc_severity`), :func:`hmd_vmd`, :func:`path_excess`, :func:`reversals`; NMAC
  is uavxai.metrics.nmac. Trajectories are positions (x, y, h) in metres at the same instants,
  moving linearly from one sample to the next.
* **weighted estimates** over encounters, each with a 95 % bootstrap interval:
  :func:`weighted_prob`, :func:`weighted_risk_ratio`, :func:`induced_risk_ratio`,
  :func:`lowc_ratio`, :func:`alert_rate`, :func:`unnecessary_manoeuvre_rate`, the interval
  check :func:`ci_check` and the per-method table :func:`daa_summary`.

Every estimate is one weighted ratio ``R = sum_i a_i / sum_i b_i`` (``a`` and ``b`` are weights
times event indicators, see each function). Its interval is a paired percentile bootstrap:
``n_boot`` resamples of the encounters with replacement (a resampled encounter brings all its
columns with it, so a method's outcome stays beside the baseline's on the same encounter),
``R`` on each, the 2.5 % and 97.5 % order statistics (a resample with ``sum b = 0`` gives
``inf``, kept as an honest infinite bound). The generator is ``numpy.random.default_rng(seed)``:
the same seed and the same number of encounters resample the same encounters for every
estimate, so the intervals of one campaign are computed on the same resamples.

Zero counts (as uavxai.metrics.risk_ratio, weighted): with ``sum b = 0`` (no baseline events)
the ratio is undefined: nan, nan, nan. With ``sum a = 0`` (no method events) the ratio is 0 and
its upper bound the weighted "rule of three": 3 / n_eff, where n_eff = (sum b)^2 / sum b^2 is
Kish's effective number of the denominator's events. With equal weights n_eff is the baseline's
event count k and the bound is 3 / k, the existing rule; unequal weights make n_eff < k and the
bound wider.

Source: MIT Lincoln Laboratory DEGAS (``mit-ll/degas-core``, code/metrics_code/metrics_calc/
computeMetric.m, calcRiskRatio.m, calcLowcRatio.m; metrics_check/checkRiskRatio.m,
checkLowcRatio.m). Departures are listed in docs/daa-metrics.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from uavxai.errors import UserError
from uavxai.metrics import nmac
from uavxai.units import FT

WELL_CLEAR_HORIZONTAL_M = 2000 * FT  # 609.6 m, small-UAS well clear (FAA draft AC 90-WLCLR)
WELL_CLEAR_VERTICAL_M = 250 * FT  # 76.2 m
N_BOOT = 2000
CI_CHECK_THRESHOLD = 0.5  # DEGAS CICheckThresh
RULE_OF_THREE = 3.0  # one-sided 95 % upper bound of a zero Poisson count
BASELINE = "none"
# The ratios whose interval ci_check judges in daa_summary: DEGAS checks these two
# (calcRiskRatio -> checkRiskRatio, calcLowcRatio -> checkLowcRatio), not the induced part.
CHECKED_RATIOS = ("nmac_risk_ratio", "lowc_ratio")
ArrayLike = Sequence[float] | Sequence[bool] | np.ndarray


# ----------------------------------------------------------------- per-encounter events
def _pair(own: ArrayLike, intr: ArrayLike, name: str) -> tuple[np.ndarray, np.ndarray]:
    o = np.asarray(own, dtype=float)
    i = np.asarray(intr, dtype=float)
    if o.ndim != 2 or o.shape[1] != 3 or i.shape != o.shape or o.shape[0] == 0:
        raise UserError(
            f"{name}: own and intr must be (T, 3) positions at the same T >= 1 instants, got "
            f"{o.shape} and {i.shape}"
        )
    return o, i


def loss_of_well_clear(
    own: ArrayLike,
    intr: ArrayLike,
    horizontal_m: float = WELL_CLEAR_HORIZONTAL_M,
    vertical_m: float = WELL_CLEAR_VERTICAL_M,
) -> bool:
    """Does the intruder come inside the well-clear cylinder around the ownship?

    A loss of well clear (LoWC) is a horizontal distance < ``horizontal_m`` *and* a vertical
    distance < ``vertical_m`` at the same instant (small-UAS well clear: 2000 ft / 250 ft,
    FAA draft AC 90-WLCLR; Weinert et al., J. Air Transportation 26(3)). Decided exactly
    between samples: the NMAC cylinder test of uavxai.metrics.nmac with the well-clear sizes.
    """
    o, i = _pair(own, intr, "loss_of_well_clear")
    return bool(nmac(o, i[:, None, :], horizontal_m, vertical_m)[0])


def _penetration(r0: np.ndarray, dr: np.ndarray, s: np.ndarray, h: float, v: float) -> np.ndarray:
    r = r0 + s[:, None] * dr
    return np.minimum(1.0 - np.hypot(r[:, 0], r[:, 1]) / h, 1.0 - np.abs(r[:, 2]) / v)


def lowc_severity(
    own: ArrayLike,
    intr: ArrayLike,
    horizontal_m: float = WELL_CLEAR_HORIZONTAL_M,
    vertical_m: float = WELL_CLEAR_VERTICAL_M,
) -> float:
    """Severity of the loss of well clear in [0, 1]: the deepest penetration of the cylinder,

        max over t of  max(0, min(1 - r_h(t) / H, 1 - |dz(t)| / V)),

    0 when well clear was never lost (or only touched), 1 when the two aircraft are at the same
    point. On each linear piece the penetration is concave in time (a minimum of two concave
    functions), so a vectorised ternary search finds its maximum between samples (to ~1e-12).
    A simpler measure than DEGAS's SLoWC (RTCA SC-228: 1 - FG(FG(range pen., HMD pen.), vertical
    pen.) with the Fernandez-Gausti norm and the tau_mod-enlarged range): the small-UAS well
    clear has no time threshold, and the min keeps the value the depth in the dimension where
    the intruder is least inside.
    """
    o, i = _pair(own, intr, "lowc_severity")
    rel = i - o
    r0, dr = (rel, np.zeros_like(rel)) if rel.shape[0] == 1 else (rel[:-1], np.diff(rel, axis=0))
    ok = np.isfinite(r0).all(axis=1) & np.isfinite(dr).all(axis=1)
    r0, dr = r0[ok], dr[ok]
    if len(r0) == 0:
        return 0.0
    lo, hi = np.zeros(len(r0)), np.ones(len(r0))
    for _ in range(70):  # (2/3)^70 ~ 5e-13
        m1, m2 = lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0
        left = _penetration(r0, dr, m1, horizontal_m, vertical_m) < _penetration(
            r0, dr, m2, horizontal_m, vertical_m
        )
        lo, hi = np.where(left, m1, lo), np.where(left, hi, m2)
    best = _penetration(r0, dr, 0.5 * (lo + hi), horizontal_m, vertical_m)
    ends = np.maximum(
        _penetration(r0, dr, np.zeros(len(r0)), horizontal_m, vertical_m),
        _penetration(r0, dr, np.ones(len(r0)), horizontal_m, vertical_m),
    )
    return float(max(0.0, np.max(np.maximum(best, ends))))


def hmd_vmd(own: ArrayLike, intr: ArrayLike) -> tuple[float, float]:
    """Horizontal miss distance and the vertical separation at that instant, (m, m).

    HMD = min over t of r_h(t) = |(x, y)_intr(t) - (x, y)_own(t)|, exactly between samples
    (on a linear piece the closest point is at s* = clip(-r0.dr / |dr|^2, 0, 1)); VMD =
    |h_intr - h_own| at the time of that closest horizontal approach (the first one on a tie).
    Pieces with NaN positions are skipped; (nan, nan) when none is left.
    """
    o, i = _pair(own, intr, "hmd_vmd")
    rel = i - o
    r0, dr = (rel, np.zeros_like(rel)) if rel.shape[0] == 1 else (rel[:-1], np.diff(rel, axis=0))
    ok = np.isfinite(r0).all(axis=1) & np.isfinite(dr).all(axis=1)
    if not ok.any():
        return math.nan, math.nan
    r0, dr = r0[ok], dr[ok]
    a = dr[:, 0] ** 2 + dr[:, 1] ** 2
    b = r0[:, 0] * dr[:, 0] + r0[:, 1] * dr[:, 1]
    s = np.where(a > 1e-12, np.clip(-b / np.where(a > 1e-12, a, 1.0), 0.0, 1.0), 0.0)
    r = r0 + s[:, None] * dr
    d = np.hypot(r[:, 0], r[:, 1])
    k = int(np.argmin(d))
    return float(d[k]), float(abs(r[k, 2]))


def path_length(track: ArrayLike) -> float:
    """Length (m) of a (T, 3) polyline, pieces with NaN positions skipped."""
    p = np.asarray(track, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise UserError(f"path_length: track must be (T, 3), got {p.shape}")
    seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
    return float(seg[np.isfinite(seg)].sum())


def path_excess(own_flown: ArrayLike, own_unequipped: ArrayLike) -> float:
    """Extra path the avoidance cost: L(flown) / L(unequipped) - 1 (3-D polyline lengths, the
    ownship's track of this method and of ``none`` on the same encounter, the same duration).
    0 for no deviation; nan when the unequipped path has no length (a hovering ownship)."""
    base = path_length(own_unequipped)
    return path_length(own_flown) / base - 1.0 if base > 0 else math.nan


def reversals(bank_cmd: ArrayLike, deadband: float = 0.0) -> int:
    """Number of turn-direction reversals in one encounter's commanded bank angles.

    Each command is read as a direction: +1 when bank > deadband, -1 when bank < -deadband,
    none otherwise (wings level or inside the deadband, and NaN, are skipped, so
    right - level - left counts once). A reversal is a change between consecutive directions.
    ``deadband`` is in the unit of ``bank_cmd``.
    """
    b = np.asarray(bank_cmd, dtype=float).ravel()
    if not deadband >= 0:
        raise UserError(f"reversals: deadband must be >= 0, got {deadband}")
    d = np.where(b > deadband, 1, np.where(b < -deadband, -1, 0))
    d = d[d != 0]
    return int(np.count_nonzero(d[1:] != d[:-1]))


# ------------------------------------------------------------------ weighted estimates
@dataclass(frozen=True)
class Estimate:
    """A weighted estimate with its 95 % interval over ``n`` encounters; ``events`` is the
    number of encounters counted in the numerator (unweighted)."""

    value: float
    lo: float
    hi: float
    n: int
    events: int

    def __str__(self) -> str:
        return f"{self.value:.4g} [{self.lo:.4g}, {self.hi:.4g}] ({self.events}/{self.n})"


def _events(x: ArrayLike, n: int | None, name: str) -> np.ndarray:
    e = np.asarray(x)
    if e.ndim != 1 or (n is not None and e.size != n):
        raise UserError(
            f"{name}: one value per encounter, the same encounters in the same order; got "
            f"shape {e.shape}" + ("" if n is None else f" for {n} encounters")
        )
    return e.astype(bool)


def _weights(weights: ArrayLike, n: int) -> np.ndarray:
    w = np.asarray(weights, dtype=float)
    if w.shape != (n,):
        raise UserError(f"weights: need one weight per encounter ({n}), got shape {w.shape}")
    if not (np.isfinite(w).all() and (w > 0).all()):
        raise UserError("weights: every weight must be finite and > 0 (as DEGAS requires)")
    return w


def _boot_sums(cols: Sequence[np.ndarray], n_boot: int, seed: int) -> np.ndarray:
    """(n_boot, k) sums of the k arrays ``cols`` (n,) each over encounters resampled with
    replacement, the same resamples for all k; chunks keep the index matrix near 4 M entries
    for large campaigns."""
    n = cols[0].size
    rng = np.random.default_rng(seed)
    chunk = max(1, (1 << 22) // max(n, 1))
    out = []
    for start in range(0, n_boot, chunk):
        idx = rng.integers(0, n, size=(min(chunk, n_boot - start), n), dtype=np.int64)
        out.append(np.stack([c[idx].sum(axis=1) for c in cols], axis=1))
    return np.concatenate(out, axis=0)


def _ratio(a: np.ndarray, b: np.ndarray, events: int, n_boot: int, seed: int,
           cap: float = math.inf) -> Estimate:
    """sum a / sum b with the paired bootstrap interval and the zero-count rules."""
    n = int(a.size)
    if n_boot < 1:
        raise UserError(f"n_boot must be >= 1, got {n_boot}")
    sa, sb = float(a.sum()), float(b.sum())
    if n == 0 or sb <= 0:
        return Estimate(math.nan, math.nan, math.nan, n, events)
    if sa <= 0:
        n_eff = sb * sb / float((b * b).sum())
        return Estimate(0.0, 0.0, min(RULE_OF_THREE / n_eff, cap), n, events)
    sums = _boot_sums([a, b], n_boot, seed)
    with np.errstate(divide="ignore", invalid="ignore"):
        num, den = sums[:, 0], sums[:, 1]
        boot = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.inf)
    lo, hi = np.quantile(boot, [0.025, 0.975], method="inverted_cdf")
    return Estimate(sa / sb, float(lo), float(hi), n, events)


def weighted_prob(
    events: ArrayLike,
    weights: ArrayLike,
    *,
    self_normalized: bool = True,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> Estimate:
    """Probability of an event in the nominal population, from importance-weighted encounters.

    ``self_normalized`` (default, DEGAS computeMetric's ``pmetric``): P = sum w e / sum w, a
    ratio estimator, consistent even when the weights are known only up to a constant.
    Otherwise P = sum w e / n, exactly unbiased when w is nominal / proposal density (mean 1).
    Interval: the bootstrap of the module docstring; no event: 0 with the upper bound
    3 / n_eff, n_eff = (sum w)^2 / sum w^2 (n without normalisation), at most 1.
    """
    e = _events(events, None, "weighted_prob")
    w = _weights(weights, e.size)
    b = w if self_normalized else np.ones_like(w)
    return _ratio(w * e, b, int(e.sum()), n_boot, seed, cap=1.0)


def weighted_risk_ratio(
    events_method: ArrayLike,
    events_none: ArrayLike,
    weights: ArrayLike,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> Estimate:
    """Risk ratio RR = P(event | method) / P(event | unequipped) = sum w e_m / sum w e_none,
    both on the same encounters (DEGAS computeMetric ``ratio``; the sum w cancels). Paired
    bootstrap interval; no baseline event: nan; no method event: 0 [0, 3 / n_eff(none)]."""
    m = _events(events_method, None, "weighted_risk_ratio")
    b = _events(events_none, m.size, "weighted_risk_ratio")
    w = _weights(weights, m.size)
    return _ratio(w * m, w * b, int(m.sum()), n_boot, seed)


def induced_risk_ratio(
    events_method: ArrayLike,
    events_none: ArrayLike,
    weights: ArrayLike,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> Estimate:
    """Induced risk ratio = sum w (e_m and not e_none) / sum w e_none: the part of RR from
    events the method caused on encounters that were clear unequipped (DEGAS computeMetric
    ``ratio_induced``: induced = max(metric - metricNom, 0)). Same interval and zero rules."""
    m = _events(events_method, None, "induced_risk_ratio")
    b = _events(events_none, m.size, "induced_risk_ratio")
    w = _weights(weights, m.size)
    induced = m & ~b
    return _ratio(w * induced, w * b, int(induced.sum()), n_boot, seed)


def lowc_ratio(
    lowc_method: ArrayLike,
    lowc_none: ArrayLike,
    weights: ArrayLike,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> Estimate:
    """LoWC ratio = sum w lowc_m / sum w lowc_none (DEGAS calcLowcRatio): the risk ratio with
    loss of well clear as the event."""
    return weighted_risk_ratio(lowc_method, lowc_none, weights, n_boot=n_boot, seed=seed)


def alert_rate(
    alerts: ArrayLike, weights: ArrayLike, *, n_boot: int = N_BOOT, seed: int = 0
) -> Estimate:
    """Weighted probability that the method alerts in an encounter (``alert``: it issued at
    least one avoidance command, a resolution that departs from the ownship's nominal
    command); :func:`weighted_prob`, self-normalised."""
    return weighted_prob(alerts, weights, n_boot=n_boot, seed=seed)


def unnecessary_manoeuvre_rate(
    manoeuvre_method: ArrayLike,
    lowc_none: ArrayLike,
    weights: ArrayLike,
    *,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> Estimate:
    """Weighted probability of a manoeuvre when none was needed:

        P(manoeuvre | unequipped stays well clear) = sum w m (1 - lowc_none) / sum w (1 - lowc_none)

    ``manoeuvre``: the method's ownship flew a command other than its nominal one at least
    once in the encounter; "needed" is judged by the same encounter flown with ``none``: had
    the ownship done nothing, it would not have lost well clear. A conditional rate, paired
    bootstrap interval; no such manoeuvre: 0 [0, 3 / n_eff(clear encounters)]."""
    m = _events(manoeuvre_method, None, "unnecessary_manoeuvre_rate")
    clear = ~_events(lowc_none, m.size, "unnecessary_manoeuvre_rate")
    w = _weights(weights, m.size)
    unnecessary = m & clear
    return _ratio(w * unnecessary, w * clear, int(unnecessary.sum()), n_boot, seed, cap=1.0)


def ci_check(ratio: float, lo: float, hi: float, threshold: float = CI_CHECK_THRESHOLD) -> str:
    """"ok" when the interval's half-width (hi - lo) / 2 is at most ``threshold`` x ratio,
    else "wide": the sample is too small to state the ratio (MIT LL DEGAS checkRiskRatio /
    checkLowcRatio, CICheckThresh 0.5). An undefined ratio or bound (nan, inf) is "wide"; so
    is a ratio of 0 with a positive upper bound. DEGAS bounds each side separately
    (ratio - lo and hi - ratio each <= 0.5 ratio), a stricter rule for a skewed interval;
    this is the half-width rule of docs/daa-metrics.md."""
    if not all(math.isfinite(x) for x in (ratio, lo, hi)):
        return "wide"
    return "ok" if (hi - lo) / 2.0 <= threshold * ratio else "wide"


def _weighted_mean(x: ArrayLike, w: np.ndarray) -> float:
    v = np.asarray(x, dtype=float)
    ok = np.isfinite(v)
    return float((w[ok] * v[ok]).sum() / w[ok].sum()) if ok.any() else math.nan


def daa_summary(
    per_encounter: Mapping[str, Mapping[str, ArrayLike]],
    weights: ArrayLike,
    *,
    baseline: str = BASELINE,
    n_boot: int = N_BOOT,
    seed: int = 0,
) -> dict[str, dict[str, float | str]]:
    """Per method, the weighted DAA columns of docs/daa-metrics.md "In campaigns".

    ``per_encounter[method]`` maps ``nmac``, ``lowc``, ``alert``, ``manoeuvre`` (bools) and
    optionally ``reversals``, ``path_excess`` (numbers) to one value per encounter, the same
    encounters in the same order for every method; ``baseline`` (``none``) must be there.
    Returns ``{method: {column: value}}`` with ``nmac_prob``, ``nmac_risk_ratio``,
    ``induced_risk_ratio``, ``lowc_prob``, ``lowc_ratio``, ``alert_rate``,
    ``unnecessary_manoeuvre_rate`` (each with ``_lo`` and ``_hi``), ``ci_check`` ("ok" when
    the intervals of CHECKED_RATIOS pass :func:`ci_check`), and the weighted means
    ``reversals`` and ``path_excess`` (nan when not given). The baseline's own row compares
    it with itself (ratios 1). Every estimate uses the same ``seed``: the same resamples.
    """
    if baseline not in per_encounter:
        raise UserError(f"daa_summary: the baseline {baseline!r} is missing")
    base = per_encounter[baseline]
    n = _events(base["nmac"], None, "daa_summary").size
    w = _weights(weights, n)
    kw = {"n_boot": n_boot, "seed": seed}
    out: dict[str, dict[str, float | str]] = {}
    for method, cols in per_encounter.items():
        est = {
            "nmac_prob": weighted_prob(cols["nmac"], w, **kw),
            "nmac_risk_ratio": weighted_risk_ratio(cols["nmac"], base["nmac"], w, **kw),
            "induced_risk_ratio": induced_risk_ratio(cols["nmac"], base["nmac"], w, **kw),
            "lowc_prob": weighted_prob(cols["lowc"], w, **kw),
            "lowc_ratio": lowc_ratio(cols["lowc"], base["lowc"], w, **kw),
            "alert_rate": alert_rate(cols["alert"], w, **kw),
            "unnecessary_manoeuvre_rate": unnecessary_manoeuvre_rate(
                cols["manoeuvre"], base["lowc"], w, **kw
            ),
        }
        row: dict[str, float | str] = {}
        for name, e in est.items():
            row[name], row[f"{name}_lo"], row[f"{name}_hi"] = e.value, e.lo, e.hi
        checks = [ci_check(est[k].value, est[k].lo, est[k].hi) for k in CHECKED_RATIOS]
        row["ci_check"] = "ok" if all(c == "ok" for c in checks) else "wide"
        for key in ("reversals", "path_excess"):
            row[key] = _weighted_mean(cols[key], w) if key in cols else math.nan
        out[method] = row
    return out
