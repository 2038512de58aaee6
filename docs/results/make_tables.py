"""Markdown tables of campaign results: goal and collision rate per method against intruders.

    .venv/bin/python docs/results/make_tables.py docs/results/kinematic/results.csv
    .venv/bin/python docs/results/make_tables.py --daa KINEMATIC/results.csv [JSBSIM/results.csv]
    .venv/bin/python docs/results/make_tables.py --multi RESULTS.csv [RESULTS.csv ...]

The second form is the detect-and-avoid table of issue 27: every weighted metric with its 95 %
interval per method (and dynamics), then the kinematic and JSBSim NMAC risk ratios side by
side. The third is its multi-threat table (random traffic, one file per dynamics): the mission
(goal, out of bounds, time-out), the safety (collision with its Wilson interval, the NMAC risk
ratio and its induced part) and the flight (reversals per minute, median path excess) beside
LoWC and alerts. Prints to stdout; README.md in this folder pastes its output.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

ORDER = ("mcts", "mcts_fast", "exhaustive", "dqn", "safe_dqn", "none")
DAA_ORDER = ("none", "mvp", "mcts", "mcts_vertical", "mcts_daa")
# (label, results.csv column, digits): each with its _lo/_hi interval columns.
DAA_METRICS = (
    ("P(NMAC)", "nmac_prob", 3),
    ("NMAC risk ratio", "nmac_risk_ratio", 3),
    ("induced risk ratio", "induced_risk_ratio", 3),
    ("P(LoWC)", "lowc_prob", 3),
    ("LoWC ratio", "lowc_ratio", 3),
    ("alert rate", "alert_rate", 3),
    ("unnecessary manoeuvre", "unnecessary_manoeuvre_rate", 3),
)


def table(path: Path) -> str:
    with path.open() as f:
        rows = list(csv.DictReader(f))
    counts = sorted({int(r["intruders"]) for r in rows})
    methods = [m for m in ORDER if any(r["method"] == m for r in rows)]
    by = {(r["method"], int(r["intruders"])): r for r in rows}
    head = "| method | " + " | ".join(f"{n} intruders" for n in counts) + " |"
    lines = [head, "|---|" + "---|" * len(counts)]
    for m in methods:
        cells = []
        for n in counts:
            r = by.get((m, n))
            if r is None:
                cells.append("-")
                continue
            cells.append(
                f"{float(r['goal_rate']):.3f} / {float(r['collision_rate']):.3f} "
                f"({int(r['episodes'])})"
            )
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    detail = [
        "",
        "| method | intruders | episodes | goal | collision | time-out | out of bounds | "
        "mean steps | mean min sep m | decision ms p50 |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for m in methods:
        for n in counts:
            r = by.get((m, n))
            if r is None:
                continue
            detail.append(
                f"| {m} | {n} | {r['episodes']} | {float(r['goal_rate']):.3f} | "
                f"{float(r['collision_rate']):.3f} | {float(r['timeout_rate']):.3f} | "
                f"{float(r['out_of_bounds_rate']):.3f} | {float(r['mean_steps']):.1f} | "
                f"{float(r['mean_min_separation_m']):.0f} | {float(r['decision_ms_p50']):.2f} |"
            )
    return "\n".join(lines + detail)


def _rows(path: Path) -> dict[str, dict[str, str]]:
    with path.open() as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    order = [m for m in DAA_ORDER if m in rows] + sorted(set(rows) - set(DAA_ORDER))
    return {m: rows[m] for m in order}


def _ci(r: dict[str, str], col: str, digits: int) -> str:
    v, lo, hi = (float(r[c]) for c in (col, col + "_lo", col + "_hi"))
    return f"{v:.{digits}g} [{lo:.{digits}g}, {hi:.{digits}g}]"


def daa_table(paths: list[Path]) -> str:
    """Issue 27's table: one row per method and dynamics, every metric with its interval,
    then the risk ratios of the two dynamics side by side (when two files are given)."""
    by_file = [(p, _rows(p)) for p in paths]
    head = ("| method | file | encounters | " + " | ".join(m[0] for m in DAA_METRICS)
            + " | reversals / enc | path excess (mean) | interval check |")  # fmt: skip
    lines = [head, "|" + "---|" * (len(DAA_METRICS) + 6)]
    for path, rows in by_file:
        for m, r in rows.items():
            cells = [_ci(r, col, d) for _, col, d in DAA_METRICS]
            lines.append(
                f"| {m} | {path.parent.name} | {int(r['episodes']):,} | " + " | ".join(cells)
                + f" | {float(r['mean_reversals']):.2f} | "
                f"{100 * float(r['mean_path_excess']):.1f} % | {r['ci_check']} |"
            )  # fmt: skip
    if len(by_file) == 2:
        (pa, a), (pb, b) = by_file
        lines += ["", f"| method | NMAC risk ratio, {pa.parent.name} | NMAC risk ratio, "
                  f"{pb.parent.name} | encounters |", "|---|---|---|---|"]  # fmt: skip
        for m in [m for m in a if m in b]:
            lines.append(f"| {m} | {_ci(a[m], 'nmac_risk_ratio', 3)} | "
                         f"{_ci(b[m], 'nmac_risk_ratio', 3)} | {int(a[m]['episodes']):,} / "
                         f"{int(b[m]['episodes']):,} |")  # fmt: skip
    return "\n".join(lines)


def multi_threat_table(paths: list[Path]) -> str:
    """Issue 27's multi-threat table: one row per file (dynamics), method and intruder count."""
    lines = ["| method | file | intruders | episodes | goal | out of bounds | time-out | "
             "collision | NMAC risk ratio | induced | LoWC ratio | alert rate | reversals / min "
             "| median path excess |", "|" + "---|" * 14]  # fmt: skip
    for path in paths:
        with path.open() as f:
            rows = list(csv.DictReader(f))
        rank = {m: i for i, m in enumerate(DAA_ORDER)}
        rows.sort(key=lambda r: (int(r["intruders"]), rank.get(r["method"], len(rank))))
        for r in rows:
            lines.append(
                f"| {r['method']} | {path.parent.name} | {r['intruders']} | {r['episodes']} | "
                f"{float(r['goal_rate']):.3f} | {float(r['out_of_bounds_rate']):.3f} | "
                f"{float(r['timeout_rate']):.3f} | {_ci(r, 'collision_rate', 3)} | "
                f"{_ci(r, 'nmac_risk_ratio', 3)} | {_ci(r, 'induced_risk_ratio', 3)} | "
                f"{float(r['lowc_ratio']):.3g} | {float(r['alert_rate']):.3f} | "
                f"{float(r['mean_reversals_per_min']):.1f} | "
                f"{100 * float(r['median_path_excess']):.0f} % |"
            )  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--daa"]:
        print(daa_table([Path(a) for a in sys.argv[2:]]))
        sys.exit(0)
    if sys.argv[1:2] == ["--multi"]:
        print(multi_threat_table([Path(a) for a in sys.argv[2:]]))
        sys.exit(0)
    for arg in sys.argv[1:]:
        print(f"<!-- {arg} -->")
        print(table(Path(arg)))
        print()
