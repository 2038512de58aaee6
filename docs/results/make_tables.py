"""Markdown tables of campaign results: goal and collision rate per method against intruders.

    .venv/bin/python docs/results/make_tables.py docs/results/kinematic/results.csv

Prints to stdout; README.md in this folder pastes its output.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

ORDER = ("mcts", "mcts_fast", "exhaustive", "dqn", "safe_dqn", "none")


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


if __name__ == "__main__":
    for arg in sys.argv[1:]:
        print(f"<!-- {arg} -->")
        print(table(Path(arg)))
        print()
