"""A campaign's results: one ``results.csv`` row per (method, intruders) from its episodes'
rows, with Wilson intervals on the rates, paired risk ratios against ``none`` and, for an
encounter campaign, the weighted detect-and-avoid estimates (docs/daa-metrics.md).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

from uavxai.campaign.files import DAA_COLUMNS, FLIGHT_COLUMNS, has_daa_columns
from uavxai.errors import UserError
from uavxai.outputs import cell_number


def summarise(rows: Iterable[dict]) -> list[dict]:
    """One ``results.csv`` row per (method, intruders), in first-seen order.

    Rates come with their 95 % Wilson interval; the risk ratio is NMAC(method) / NMAC(none)
    on the same encounters (the detect-and-avoid field's figure of merit), with a paired
    bootstrap interval; ``collision_risk_ratio`` the same for collisions. Both are empty
    (nan) when ``none`` was not flown at that intruder count."""
    rows = list(rows)
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["method"], int(r["intruders"])), []).append(r)
    out = [_summary_row(method, n, rs, groups.get(("none", n))) for (method, n), rs in
           groups.items()]  # fmt: skip
    if rows and all(has_daa_columns(r) for r in rows):
        for row in out:
            n = row["intruders"]
            row.update(_daa_row(row["method"], groups[(row["method"], n)], groups.get(("none", n))))
    return out


def _daa_row(method: str, rs: list[dict], baseline: list[dict] | None) -> dict:
    """The weighted DAA columns of one method against ``none`` on the encounters (seeds) both
    flew (uavxai.daa_metrics.daa_summary); nan (and ci_check empty) without ``none``."""
    from uavxai.daa_metrics import daa_summary

    row: dict = {k: math.nan for k in DAA_COLUMNS}
    row["ci_check"] = ""
    if baseline is None:
        return row

    def by_seed(group: list[dict]) -> dict[int, dict]:
        return {int(r["seed"]): r for r in group}

    mine, base = by_seed(rs), by_seed(baseline)
    seeds = sorted(set(mine) & set(base))
    if not seeds:
        return row

    def columns(group: dict[int, dict]) -> dict[str, np.ndarray]:
        def col(key: str) -> np.ndarray:
            return np.array([cell_number(group[s][key]) for s in seeds])

        cols = {k: col(k) > 0.5 for k in ("nmac", "lowc", "alert", "manoeuvre")}
        cols.update(reversals=col("reversals"), path_excess=col("path_excess"))
        return cols

    weights = np.array([float(base[s]["weight"]) for s in seeds])
    theirs = np.array([float(mine[s]["weight"]) for s in seeds])
    if not np.allclose(weights, theirs, rtol=1e-6, atol=0.0):
        raise UserError(
            f"{method}: its encounters' weights differ from none's on the same seeds; these "
            "episodes were not flown on the same encounters (another scenario?)."
        )
    per = {"none": columns(base)}
    if method != "none":
        per[method] = columns(mine)
    est = daa_summary(per, weights)[method]
    row.update({k: est[k] for k in DAA_COLUMNS if k in est})
    row["mean_reversals"], row["mean_path_excess"] = est["reversals"], est["path_excess"]
    return row


def _events(rs: Sequence[dict], key: str) -> dict[int, bool]:
    """Per encounter (seed): did it happen? ``key`` 'collision' or 'nmac'."""
    if key == "collision":
        return {int(r["seed"]): r["outcome"] == "collision" for r in rs}
    return {int(r["seed"]): bool(int(float(r.get("nmac", 0)))) for r in rs}


def _summary_row(method: str, n: int, rs: list[dict], baseline: list[dict] | None) -> dict:
    from uavxai.metrics import rate, risk_ratio

    outcomes = [r["outcome"] for r in rs]
    seps = [float(r["min_separation_m"]) for r in rs]
    seps = [s for s in seps if math.isfinite(s)]
    ms = [m for r in rs for m in r.get("decision_ms", ())]
    if not ms:  # rows read back from episodes.csv carry only their own median
        ms = [float(r["decision_ms_p50"]) for r in rs]
    k = len(rs)
    row = {
        "method": method,
        "intruders": n,
        "episodes": k,
        "goal_rate": outcomes.count("goal") / k,
        "collision_rate": outcomes.count("collision") / k,
        "timeout_rate": outcomes.count("timeout") / k,
        "mean_steps": float(np.mean([int(r["steps"]) for r in rs])),
        "mean_min_separation_m": float(np.mean(seps)) if seps else math.nan,
        "decision_ms_p50": float(np.nanmedian(ms)) if ms else math.nan,
        "out_of_bounds_rate": outcomes.count("out_of_bounds") / k,
        "fdm_failure_rate": outcomes.count("fdm_failure") / k,
    }
    for key, prefix in (("collision", "collision_rate"), ("nmac", "nmac_rate")):
        r = rate(list(_events(rs, key).values()))
        row[prefix], row[f"{prefix}_lo"], row[f"{prefix}_hi"] = r.rate, r.lo, r.hi
    for key, prefix in (("nmac", "risk_ratio"), ("collision", "collision_risk_ratio")):
        row[prefix] = row[f"{prefix}_lo"] = row[f"{prefix}_hi"] = math.nan
        if baseline is not None:
            mine, base = _events(rs, key), _events(baseline, key)
            seeds = sorted(set(mine) & set(base))  # the same encounters only
            rr = risk_ratio([mine[s] for s in seeds], [base[s] for s in seeds])
            row[prefix], row[f"{prefix}_lo"], row[f"{prefix}_hi"] = rr.ratio, rr.lo, rr.hi
    row.update(_flight_results(rs))
    return row


def _flight_results(rs: list[dict]) -> dict:
    """The median path excess (over the episodes that made progress) and the mean reversal
    rate and steep-bank time of one results row; nan where no episode has the number."""

    def finite(key: str) -> np.ndarray:
        v = np.array([cell_number(r.get(key)) for r in rs])
        return v[np.isfinite(v)]

    excess, per_min, steep = (finite(k) for k in FLIGHT_COLUMNS)
    return {
        "median_path_excess": float(np.median(excess)) if excess.size else math.nan,
        "mean_reversals_per_min": float(per_min.mean()) if per_min.size else math.nan,
        "mean_bank_over_25_s": float(steep.mean()) if steep.size else math.nan,
    }
