"""stress.png: the default planner (mcts_vertical) on harder traffic than it was tuned on,
kinematic, seeds 0-99, beside the default scenario on the same seeds. Run from the repository
root: python docs/results/manoeuvring/stress/stress.py"""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from uavxai.campaign import summarise  # noqa: E402

HERE = Path(__file__).parent
DEFAULT = HERE.parent / "kinematic-reach4-200-episodes.csv"
VARIANTS = ("noncooperative", "poor-adsb", "co-altitude", "goal-seeking", "poor-adsb-horizon8")


def rows(path: Path) -> list[dict]:
    with path.open() as f:
        return [r for r in csv.DictReader(f) if int(r["seed"]) < 100]


def main() -> None:
    cases = [("default", rows(DEFAULT))] + [
        (v, rows(HERE / f"kinematic-{v}-episodes.csv")) for v in VARIANTS
    ]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), dpi=120, sharey=False)
    width = 0.14
    for k, (name, rs) in enumerate(cases):
        for r in summarise(rs):
            if r["method"] != "mcts_vertical":
                continue
            x = [20, 40].index(r["intruders"]) + (k - 2.5) * width
            axes[0].bar(x, r["collision_rate"], width, color=f"C{k}",
                        label=name if r["intruders"] == 20 else None)  # fmt: skip
            axes[0].errorbar(x, r["collision_rate"], color="k", capsize=2, yerr=[
                [r["collision_rate"] - r["collision_rate_lo"]],
                [r["collision_rate_hi"] - r["collision_rate"]]])  # fmt: skip
            axes[1].bar(x, r["goal_rate"], width, color=f"C{k}")
    for ax, title in zip(axes, ("collision rate (95 % interval)", "goal rate"), strict=True):
        ax.set_xticks([0, 1], ["20 intruders", "40 intruders"])
        ax.set_title(title, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0].axhline(0.02, color="grey", ls="--", lw=1)
    axes[0].axhline(0.05, color="grey", ls=":", lw=1)
    axes[0].legend(fontsize=8)
    fig.suptitle(
        "mcts_vertical on harder traffic, kinematic, seeds 0-99 "
        "(40 intruders flown for the default and non-cooperative only)",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(HERE / "stress.png")


if __name__ == "__main__":
    main()
