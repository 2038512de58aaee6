"""The trade between collisions and the mission for mcts_vertical's settings: collision rate
(95 % Wilson interval) against the share of episodes that reach the goal, per dynamics and
intruder count, from the episodes.csv files beside this script. Writes tradeoff.png.

    .venv/bin/python docs/results/manoeuvring/tradeoff.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from uavxai.metrics import wilson_interval  # noqa: E402

HERE = Path(__file__).parent
SETTINGS = {  # label: (kinematic files, JSBSim files)
    "reach 3 s (earlier default)": (
        ["kinematic-preroll200"],
        ["jsbsim-preroll", "jsbsim-seeds30"],
    ),
    "reach 4 s (default)": (["kinematic-reach4-200"], ["jsbsim-reach4", "jsbsim-reach4-seeds60"]),
    "reach 5 s": (["kinematic-reach5-200"], ["jsbsim-reach5", "jsbsim-reach5-seeds30"]),
    "own error 20.2 m": ([], ["jsbsim-own-error"]),
}


def episodes(stems: list[str], intruders: int) -> list[dict]:
    rows = []
    for stem in stems:
        with open(HERE / f"{stem}-episodes.csv") as f:
            rows += [
                r
                for r in csv.DictReader(f)
                if r["method"] == "mcts_vertical" and int(r["intruders"]) == intruders
            ]
    return rows


def main() -> None:
    fig, axes = plt.subplots(1, 4, figsize=(16, 4.2), sharey=True)
    panels = [(d, n) for d in ("kinematic", "JSBSim") for n in (20, 40)]
    for ax, (dynamics, n) in zip(axes, panels, strict=True):
        for k, (label, files) in enumerate(SETTINGS.items()):
            rows = episodes(files[dynamics == "JSBSim"], n)
            if not rows:
                continue
            hits = sum(r["outcome"] == "collision" for r in rows)
            goal = sum(r["outcome"] == "goal" for r in rows) / len(rows)
            lo, hi = wilson_interval(hits, len(rows))
            rate = hits / len(rows)
            ax.errorbar(
                goal,
                rate,
                yerr=[[rate - lo], [hi - rate]],
                fmt="o",
                capsize=4,
                color=f"C{k}",
                label=f"{label} ({hits}/{len(rows)})",
            )
        ax.axhline(0.02 if n == 20 else 0.05, color="grey", ls="--", lw=1, label="goal")
        ax.set_title(f"{dynamics}, {n} intruders")
        ax.set_xlabel("goal reached (share of episodes)")
        ax.set_xlim(0, 1)
        ax.legend(fontsize=7, loc="upper left")
    axes[0].set_ylabel("collision rate [95 % CI]")
    fig.suptitle("mcts_vertical among random-turn traffic: safer settings cost the mission")
    fig.tight_layout()
    fig.savefig(HERE / "tradeoff.png", dpi=110)


if __name__ == "__main__":
    main()
