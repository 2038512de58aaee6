"""A campaign's figures: rates against the intruder count (every campaign) and, for an
encounter campaign, its detect-and-avoid estimates with their intervals (docs/daa-metrics.md).

Written beside ``results.csv`` by ``uavxai evaluate`` and ``uavxai merge``; each figure is read
off the results rows alone, so a merged campaign draws the same figures as one flown whole.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from uavxai.outputs import cell_number, write_figure

PLOTS = (
    ("goal_rate", "goal rate", "goal_rate.png"),
    ("collision_rate", "collision rate", "collision_rate.png"),
    ("mean_steps", "mean steps (decisions)", "steps.png"),
)


# One look per method in every figure.
# One colour and marker per built-in planner, none shared, so a figure comparing any of them
# tells them apart (a plugin planner gets the next of matplotlib's cycle).
_STYLE = {
    "mcts": ("tab:blue", "o"),
    "mcts_fast": ("tab:orange", "s"),
    "mcts_vertical": ("tab:cyan", "*"),
    "mcts_daa": ("tab:olive", "X"),
    "mcts_route": ("goldenrod", "<"),
    "mcts_sep": ("tab:gray", "h"),
    "mcts_sep_daa": ("black", "d"),
    "mvp": ("tab:pink", "p"),
    "exhaustive": ("tab:green", "^"),
    "dqn": ("tab:purple", "v"),
    "safe_dqn": ("tab:brown", "P"),
    "none": ("tab:red", "D"),
}


def plot_campaign(results: Sequence[dict], out: Path, title: str = "") -> list[Path]:
    """Every figure of a campaign (its rates and its detect-and-avoid estimates)."""
    return plot_results(results, out, title) + plot_daa(results, out, title)


def plot_results(results: Sequence[dict], out: Path, title: str = "") -> list[Path]:
    """Goal rate, collision rate and steps against the intruder count, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(dict.fromkeys(r["method"] for r in results))
    paths = []
    for key, label, name in PLOTS:
        fig, ax = plt.subplots(figsize=(6.0, 4.0), dpi=120)
        for i, m in enumerate(methods):
            rs = sorted((r for r in results if r["method"] == m), key=lambda r: r["intruders"])
            colour, marker = _STYLE.get(m, (f"C{i % 10}", "o"))
            # Methods often tie (several at zero collisions): distinct markers and shrinking
            # sizes keep every one visible where lines lie on top of each other.
            ax.plot(
                [r["intruders"] for r in rs],
                [r[key] for r in rs],
                color=colour,
                marker=marker,
                markersize=9 - 1.0 * (i % 5),
                linewidth=2.2 - 0.25 * (i % 5),
                label=m,
            )
        ax.set_xlabel("intruders")
        ax.set_ylabel(label)
        if key.endswith("_rate"):
            ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        if title:
            ax.set_title(title, fontsize=9)
        fig.tight_layout()
        write_figure(out / name, fig)
        plt.close(fig)
        paths.append(out / name)
    return paths


# The encounter estimates drawn, and the goals issue 27 sets (point, upper bound; None: none).
DAA_PLOTTED = (
    ("nmac_risk_ratio", "NMAC risk ratio", (0.05, 0.1)),
    ("induced_risk_ratio", "induced NMAC risk ratio", (0.005, None)),
    ("lowc_ratio", "loss-of-well-clear ratio", None),
    ("alert_rate", "alert rate", None),
    ("unnecessary_manoeuvre_rate", "unnecessary-manoeuvre rate", None),
)
DAA_FIGURE = "daa_metrics.png"


def plot_daa(results: Sequence[dict], out: Path, title: str = "") -> list[Path]:
    """A campaign's detect-and-avoid estimates: one panel per metric, each method's (and
    intruder count's) weighted point
    estimate with its 95 % bootstrap interval, the goals dashed (point) and dotted (upper
    bound). Nothing when the results have no encounter estimates."""
    rows = [r for r in results if _finite(r.get("nmac_risk_ratio"))]
    if not rows:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(DAA_PLOTTED), 1, figsize=(6.5, 1.3 + 1.15 * len(DAA_PLOTTED)
                             * max(1, len(rows)) ** 0.5 / 1.6), dpi=120)  # fmt: skip
    counts = len({int(r["intruders"]) for r in rows}) > 1  # random traffic at several counts
    labels = [f"{r['method']}" + (f" @{int(r['intruders'])}" if counts else "")
              + f" (n={int(r['episodes'])})" for r in rows]
    for ax, (key, label, goal) in zip(axes, DAA_PLOTTED, strict=True):
        for y, r in enumerate(rows):
            if key.endswith("ratio") and r["method"] == "none":
                continue  # the reference: 1, and 0 induced, by definition
            colour, marker = _STYLE.get(r["method"], (f"C{y % 10}", "o"))
            v, lo, hi = (cell_number(r.get(key + end)) for end in ("", "_lo", "_hi"))
            if math.isfinite(lo) and math.isfinite(hi):
                ax.plot([lo, hi], [y, y], color=colour, linewidth=2.0)
            if math.isfinite(v):
                ax.plot([v], [y], color=colour, marker=marker, markersize=8)
        if goal is not None:
            ax.axvline(goal[0], color="black", linestyle="--", linewidth=1.0)
            if goal[1] is not None:
                ax.axvline(goal[1], color="black", linestyle=":", linewidth=1.0)
        ax.set_yticks(range(len(rows)), labels, fontsize=8)
        ax.set_ylim(-0.6, len(rows) - 0.4)
        ax.set_xlim(left=-0.02)
        ax.set_title(label, fontsize=9, loc="left")
        ax.grid(axis="x", alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = write_figure(out / DAA_FIGURE, fig)
    plt.close(fig)
    return [path]


def _finite(v) -> bool:
    return math.isfinite(cell_number(v))
