"""Row (f)'s comparison: `mcts` and `none` on encounters 3000-3999 from their committed 10^4
campaigns (docs/results/encounters/session41/kin-mcts-*, encounters/kinematic-none10k-*),
summarised by the campaign's own code (uavxai.campaign.statistics.summarise) as `evaluate`
would summarise them."""

from __future__ import annotations

import csv
import glob
from pathlib import Path

from uavxai.campaign.files import read_rows
from uavxai.campaign.statistics import summarise

R = Path(__file__).resolve().parents[3] / "encounters"
KEYS = (
    "method", "episodes", "nmac_risk_ratio", "nmac_risk_ratio_lo", "nmac_risk_ratio_hi",
    "induced_risk_ratio", "induced_risk_ratio_lo", "induced_risk_ratio_hi", "ci_check",
)  # fmt: skip


def rows(path: Path) -> list[dict]:
    with open(path) as f:
        columns = next(csv.reader(f))
    return read_rows(path, columns)


def main() -> None:
    shards = sorted(glob.glob(str(R / "session41/kin-mcts-*-episodes.csv")))
    sources = [R / "kinematic-none10k-episodes.csv", *map(Path, shards)]
    picked = [r for p in sources for r in rows(p) if 3000 <= int(r["seed"]) <= 3999]
    print({m: sum(1 for r in picked if r["method"] == m) for m in ("none", "mcts")})
    for row in summarise(picked):
        print({k: row[k] for k in KEYS})


if __name__ == "__main__":
    main()
