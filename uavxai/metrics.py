"""Campaign metrics as the detect-and-avoid field defines them (pure functions).

* **NMAC** (near mid-air collision): a loss of separation inside a cylinder around the
  ownship, by default 500 ft horizontally and 100 ft vertically (the DAA MOPS / ACAS X
  definition). :func:`nmac` decides it from two sampled trajectories, exactly between samples
  (both aircraft move linearly from one sample to the next).
* **Rates with a 95 % interval**: :func:`rate` with the Wilson score interval, which stays
  inside [0, 1] and is sensible at 0 or n events (the plain normal interval is not).
* **Risk ratio** of a method against the ``none`` baseline on the *same* encounters:
  :func:`risk_ratio`. The point estimate is events(method) / events(none); the interval is a
  paired percentile bootstrap over encounters (resampling whole encounters keeps each
  method's outcome beside the baseline's on it) with a seeded generator, or the Katz log
  interval (``method="katz"``, which treats the two samples as independent: wider than needed
  for paired data). Zero counts: with no baseline events the ratio is undefined (nan, nan,
  nan); with no method events the ratio is 0 and the upper bound is the one-sided 95 % bound
  of a zero count, 3 events ("rule of three"), over the baseline's events; Katz adds 0.5 to
  every cell when a count is zero (Haldane-Anscombe).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uavxai.errors import UserError
from uavxai.units import FT

NMAC_HORIZONTAL_M = 500 * FT  # 152.4 m
NMAC_VERTICAL_M = 100 * FT  # 30.48 m
Z95 = 1.959963984540054  # two-sided 95 % normal quantile


# ------------------------------------------------------------------------------------ NMAC
def nmac(
    own: np.ndarray,
    intruders: np.ndarray,
    horizontal_m: float = NMAC_HORIZONTAL_M,
    vertical_m: float = NMAC_VERTICAL_M,
) -> np.ndarray:
    """(N,) bool: does intruder ``j`` come inside the NMAC cylinder around the ownship?

    ``own`` (T, 3), or (T, N, 3) with one own track per intruder, and ``intruders`` (T, N, 3)
    are positions (x, y, h) at the same T instants; between instants both move linearly, so
    an intrusion between two samples counts. On each piece the horizontal condition holds on
    an interval of the piece (a quadratic in the piece's fraction s) and the vertical one on
    another (linear in s): an NMAC is a piece where both intervals overlap. NaN positions (an
    intruder not present) never count.
    """
    own = np.asarray(own, dtype=float)
    intruders = np.asarray(intruders, dtype=float)
    if intruders.ndim == 2:
        intruders = intruders[:, None, :]
    # (T, N, 3) own: the ownship's own piece for each intruder (a pair that restarts on a
    # replaced row, :func:`uavxai.sim.judge.pieces_since_last_sample`)
    per_row = own.ndim == 3 and own.shape == intruders.shape
    if not per_row and (own.ndim != 2 or own.shape[1] != 3 or intruders.shape[::2] != own.shape):
        raise UserError(
            f"nmac: own must be (T, 3) or (T, N, 3) and intruders (T, N, 3) at the same T "
            f"instants, got {own.shape} and {intruders.shape}"
        )
    if not (horizontal_m > 0 and vertical_m > 0):
        raise UserError("nmac: horizontal_m and vertical_m must be > 0")
    rel = intruders - (own if per_row else own[:, None, :])  # (T, N, 3)
    if rel.shape[0] == 1:  # one instant: no pieces
        r = rel[0]
        return (np.hypot(r[:, 0], r[:, 1]) < horizontal_m) & (np.abs(r[:, 2]) < vertical_m)
    r0, dr = rel[:-1], np.diff(rel, axis=0)  # (T-1, N, 3)
    # horizontal: |r0 + s dr|^2 < H^2  <=>  a s^2 + b s + c < 0
    a = dr[..., 0] ** 2 + dr[..., 1] ** 2
    b = 2.0 * (r0[..., 0] * dr[..., 0] + r0[..., 1] * dr[..., 1])
    c = r0[..., 0] ** 2 + r0[..., 1] ** 2 - horizontal_m**2
    with np.errstate(invalid="ignore", divide="ignore"):
        disc = b * b - 4.0 * a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        moving = a > 1e-12
        h_lo = np.where(moving, (-b - root) / (2.0 * a), np.where(c < 0, -np.inf, np.inf))
        h_hi = np.where(moving, (-b + root) / (2.0 * a), np.where(c < 0, np.inf, -np.inf))
        h_hi = np.where(moving & (disc <= 0), -np.inf, h_hi)  # never strictly inside
        # vertical: |z0 + s dz| < V
        z0, dz = r0[..., 2], dr[..., 2]
        climbing = np.abs(dz) > 1e-12
        t1 = (-vertical_m - z0) / np.where(climbing, dz, 1.0)
        t2 = (vertical_m - z0) / np.where(climbing, dz, 1.0)
        inside_v = np.abs(z0) < vertical_m
        v_lo = np.where(climbing, np.minimum(t1, t2), np.where(inside_v, -np.inf, np.inf))
        v_hi = np.where(climbing, np.maximum(t1, t2), np.where(inside_v, np.inf, -np.inf))
    lo = np.maximum(np.maximum(h_lo, v_lo), 0.0)
    hi = np.minimum(np.minimum(h_hi, v_hi), 1.0)
    hit = lo < hi  # an open overlap inside the piece (touching the boundary is no NMAC)
    hit &= np.isfinite(r0).all(axis=2) & np.isfinite(dr).all(axis=2)
    return hit.any(axis=0)


# ----------------------------------------------------------------------------------- rates
@dataclass(frozen=True)
class Rate:
    """``k`` events in ``n`` trials: the rate and its 95 % Wilson score interval."""

    k: int
    n: int
    rate: float
    lo: float
    hi: float

    def __str__(self) -> str:
        return f"{self.rate:.3f} [{self.lo:.3f}, {self.hi:.3f}] ({self.k}/{self.n})"


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion ``k / n`` (nan, nan for n = 0)."""
    if n < 0 or k < 0 or k > n:
        raise UserError(f"wilson_interval: need 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return math.nan, math.nan
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    # at k = 0 (k = n) the bound is exactly 0 (1); rounding must not put it a hair off
    return (0.0 if k == 0 else centre - half), (1.0 if k == n else centre + half)


def rate(events: Sequence[bool] | np.ndarray) -> Rate:
    """The rate of ``events`` (one bool per episode) with its 95 % Wilson interval."""
    e = np.asarray(events, dtype=bool)
    k, n = int(e.sum()), int(e.size)
    lo, hi = wilson_interval(k, n)
    return Rate(k, n, k / n if n else math.nan, lo, hi)


# ------------------------------------------------------------------------------ risk ratio
@dataclass(frozen=True)
class RiskRatio:
    """events(method) / events(baseline) on the same encounters, with a 95 % interval."""

    ratio: float
    lo: float
    hi: float
    method_events: int
    baseline_events: int
    n: int
    interval: str  # "bootstrap" or "katz"

    def __str__(self) -> str:
        return f"{self.ratio:.3f} [{self.lo:.3f}, {self.hi:.3f}]"


def risk_ratio(
    method: Sequence[bool] | np.ndarray,
    baseline: Sequence[bool] | np.ndarray,
    *,
    interval: str = "bootstrap",
    n_boot: int = 4000,
    seed: int = 0,
) -> RiskRatio:
    """Risk ratio of ``method`` against ``baseline``: per-encounter events (bools) of both on
    the same encounters, in the same order. See the module docstring for the interval and
    for zero counts."""
    m = np.asarray(method, dtype=bool)
    b = np.asarray(baseline, dtype=bool)
    if m.shape != b.shape or m.ndim != 1:
        raise UserError(
            "risk_ratio: method and baseline need one event per encounter, the same "
            f"encounters in the same order; got shapes {m.shape} and {b.shape}"
        )
    if interval not in ("bootstrap", "katz"):
        raise UserError(f"risk_ratio: interval must be 'bootstrap' or 'katz', got {interval!r}")
    n, km, kb = int(m.size), int(m.sum()), int(b.sum())
    nan = math.nan
    if n == 0 or kb == 0:
        return RiskRatio(nan, nan, nan, km, kb, n, interval)
    ratio = km / kb
    if interval == "katz":
        if km == 0:  # Haldane-Anscombe: 0.5 in every cell
            a, c, n1, n2 = km + 0.5, kb + 0.5, n + 1.0, n + 1.0
        else:
            a, c, n1, n2 = float(km), float(kb), float(n), float(n)
        se = math.sqrt(1 / a - 1 / n1 + 1 / c - 1 / n2)
        centre = math.log((a / n1) / (c / n2))
        lo, hi = math.exp(centre - Z95 * se), math.exp(centre + Z95 * se)
        return RiskRatio(ratio, 0.0 if km == 0 else lo, hi, km, kb, n, interval)
    if km == 0:
        return RiskRatio(0.0, 0.0, min(3.0 / kb, math.inf), km, kb, n, interval)
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, n, size=(n_boot, n))
    sm = m[idx].sum(axis=1).astype(float)
    sb = b[idx].sum(axis=1).astype(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        boot = np.where(sb > 0, sm / np.where(sb > 0, sb, 1.0), np.inf)
    # resamples without a baseline event give inf; order statistics (no interpolation)
    # keep that an honest inf instead of a nan
    lo, hi = np.quantile(boot, [0.025, 0.975], method="inverted_cdf")
    return RiskRatio(ratio, float(lo), float(hi), km, kb, n, interval)
