"""A campaign's figures: rates against the intruder count (every campaign) and, for an
encounter campaign, its detect-and-avoid estimates with their intervals (docs/daa-metrics.md).

Written beside ``results.csv`` by ``uavxai evaluate`` and ``uavxai merge``; each figure is read
off the results rows alone, so a merged campaign draws the same figures as one flown whole.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from uavxai.campaign.files import FLEET_EPISODE_COLUMNS, FLEET_RESULT_COLUMNS, FLEET_TEXT_COLUMNS
from uavxai.errors import UserError
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
    labels = _row_labels(rows)
    for ax, (key, label, goal) in zip(axes, DAA_PLOTTED, strict=True):
        for y, r in enumerate(rows):
            if key.endswith("ratio") and r["method"] == "none":
                continue  # the reference: 1, and 0 induced, by definition
            v, lo, hi = (cell_number(r.get(key + end)) for end in ("", "_lo", "_hi"))
            _point_and_range(ax, y, _look(r["method"], y), v, lo, hi)
        if goal is not None:
            ax.axvline(goal[0], color="black", linestyle="--", linewidth=1.0)
            if goal[1] is not None:
                ax.axvline(goal[1], color="black", linestyle=":", linewidth=1.0)
        _rows_axis(ax, labels, label)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = write_figure(out / DAA_FIGURE, fig)
    plt.close(fig)
    return [path]


def _finite(v) -> bool:
    return math.isfinite(cell_number(v))


def _look(method: str, i: int) -> tuple[str, str]:
    """A method's colour and marker (a plugin planner's: matplotlib's cycle at ``i``)."""
    return _STYLE.get(method, (f"C{i % 10}", "o"))


def _row_labels(rows: Sequence[dict]) -> list[str]:
    """One label per results row: its method, its intruder count when the rows have several,
    and its episodes."""
    counts = len({int(r["intruders"]) for r in rows}) > 1  # random traffic at several counts
    return [f"{r['method']}" + (f" @{int(r['intruders'])}" if counts else "")
            + f" (n={int(r['episodes'])})" for r in rows]  # fmt: skip


def _point_and_range(ax, y: float, look: tuple[str, str], v: float, lo: float, hi: float) -> None:
    """A point estimate on row ``y`` with its interval (or its range to the worst case) as a
    line; what is not defined (nan) is not drawn."""
    colour, marker = look
    if math.isfinite(lo) and math.isfinite(hi):
        ax.plot([lo, hi], [y, y], color=colour, linewidth=2.0)
    if math.isfinite(v):
        ax.plot([v], [y], color=colour, marker=marker, markersize=8)


def _rows_axis(ax, labels: Sequence[str], title: str) -> None:
    """A panel of one row per results row, from zero."""
    ax.set_yticks(range(len(labels)), labels, fontsize=8)
    ax.set_ylim(-0.6, len(labels) - 0.4)
    ax.set_xlim(left=-0.02)
    ax.set_title(title, fontsize=9, loc="left")
    ax.grid(axis="x", alpha=0.3)


# A fleet campaign's headline figures (fleet_results.csv; docs/fleet.md, "Fleet campaigns"):
# (column, panel title, its interval's kind). "wilson": the rate with its 95 % Wilson interval
# (`_lo`, `_hi`); a column name: the mean drawn to that worst case (hollow marker at it);
# "pairs": the member-member (filled) and member-intruder (hollow) pair counts.
FLEET_PLOTTED = (
    ("completed_rate", "completed rate (every member done), 95 % Wilson", "wilson"),
    ("collision_rate", "collision rate (episodes), 95 % Wilson", "wilson"),
    ("member_nmac_rate", "member-member NMAC rate (episodes), 95 % Wilson", "wilson"),
    ("intruder_nmac_rate", "member-intruder NMAC rate (episodes), 95 % Wilson", "wilson"),
    ("member_collisions", "collision pairs: member-member (filled), member-intruder (hollow)",
     "pairs"),
    ("mean_delivered_bits", "delivered Mbit: mean, worst (hollow)", "min_delivered_bits"),
    ("mean_qos_share", "QoS share: mean, worst (hollow)", "min_qos_share"),
    ("mean_jain_fairness", "Jain fairness: mean, worst (hollow)", "min_jain_fairness"),
    ("mean_energy_wh", "energy Wh (all members): mean, worst (hollow)", "max_energy_wh"),
)  # fmt: skip
FLEET_RESULTS_FIGURE = "fleet_results.png"
# Per episode (fleet_episodes.csv): (column, panel title, scale); the leave's panel is added
# when an episode has a departure.
FLEET_EPISODE_PLOTTED = (
    ("delivered_bits", "delivered Mbit per episode", 1e-6),
    ("qos_share", "QoS share per episode", 1.0),
    ("jain_fairness", "Jain fairness per episode", 1.0),
    ("energy_wh", "energy Wh per episode (all members)", 1.0),
    ("closest_members_m", "closest members m per episode", 1.0),
    ("closest_intruder_m", "closest member-intruder m per episode", 1.0),
)
FLEET_EPISODES_FIGURE = "fleet_episodes.png"


def plot_fleet(results: Sequence[dict], episodes: Sequence[dict], out: Path,
               title: str = "") -> list[Path]:  # fmt: skip
    """A fleet campaign's figures: ``fleet_results.png`` (per method and intruder count, its
    rates with their Wilson intervals and each mean with its worst case) and
    ``fleet_episodes.png`` (every episode's numbers, one dot each, and the first departure's
    QoS share before -> after). Read off the rows alone, so a merged campaign draws the figures
    of the campaign flown whole. Rows that are not a fleet campaign's: a UserError."""
    _check_plotted(results, FLEET_RESULT_COLUMNS[3:], "fleet_results")
    _check_plotted(episodes, FLEET_EPISODE_COLUMNS[7:], "fleet_episodes")
    import matplotlib

    matplotlib.use("Agg")
    return [_fleet_results_figure(results, out, title),
            _fleet_episodes_figure(results, episodes, out, title)]  # fmt: skip


def _check_plotted(rows: Sequence[dict], columns: Sequence[str], what: str) -> None:
    """Rows a fleet figure can be drawn from: some, every number a number or empty, and the
    intruder and episode counts the labels name whole numbers."""
    if not rows:
        raise UserError(f"{what}: no rows to plot (a campaign with no episodes?); fly at least "
                        "one episode, or merge campaigns that have some.")  # fmt: skip
    for i, r in enumerate(rows, start=1):
        for c in (c for c in columns if c not in FLEET_TEXT_COLUMNS):
            try:
                cell_number(r.get(c, ""))
            except (TypeError, ValueError):
                raise UserError(f"{what} row {i}: {c} {str(r.get(c))[:40]!r} is not a number; "
                                "cannot plot it.") from None  # fmt: skip
        if "method" not in r or "intruders" not in r:
            raise UserError(f"{what} row {i}: no method or intruders; not a fleet campaign's.")
        for c in ("intruders", "episodes") if "episodes" in r else ("intruders",):
            try:
                int(str(r[c]))
            except ValueError:
                raise UserError(f"{what} row {i}: {c} {str(r[c])[:40]!r} is not a whole number; "
                                "cannot label it.") from None  # fmt: skip


def _figure(panels: int, rows: int):
    import matplotlib.pyplot as plt

    return plt.subplots(panels, 1, figsize=(6.5, 1.3 + 1.15 * panels * max(1, rows) ** 0.5
                                            / 1.6), dpi=120, squeeze=False)  # fmt: skip


def _save_figure(fig, path: Path, title: str) -> Path:
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    write_figure(path, fig)
    plt.close(fig)
    return path


def _fleet_results_figure(results: Sequence[dict], out: Path, title: str) -> Path:
    fig, axes = _figure(len(FLEET_PLOTTED), len(results))
    for ax, (key, label, kind) in zip(axes[:, 0], FLEET_PLOTTED, strict=True):
        scale = 1e-6 if key.endswith("bits") else 1.0
        for y, r in enumerate(results):
            look = _look(r["method"], y)
            v = cell_number(r.get(key)) * scale
            if kind == "wilson":
                lo, hi = (cell_number(r.get(key + end)) for end in ("_lo", "_hi"))
                _point_and_range(ax, y, look, v, lo, hi)
                continue
            other = cell_number(r.get("intruder_collisions" if kind == "pairs" else kind)) * scale
            # a mean to its worst case is a range; two counts of other pairs are not one
            _point_and_range(ax, y, look, v, *(sorted((v, other)) if kind != "pairs"
                                               else (math.nan, math.nan)))  # fmt: skip
            if math.isfinite(other):
                ax.plot([other], [y], color=look[0], marker=look[1], markersize=8,
                        markerfacecolor="none")  # fmt: skip
            if not math.isfinite(v) and not math.isfinite(other):
                _undefined(ax, y)
        _rows_axis(ax, _row_labels(results), label)
        _fit(ax, "rate" if kind == "wilson" else kind if kind == "pairs" else key)
    return _save_figure(fig, out / FLEET_RESULTS_FIGURE, title)


def _fleet_episodes_figure(results: Sequence[dict], episodes: Sequence[dict], out: Path,
                           title: str) -> Path:  # fmt: skip
    groups = [[e for e in episodes if e["method"] == r["method"]
               and int(e["intruders"]) == int(r["intruders"])] for r in results]  # fmt: skip
    leave = any(math.isfinite(cell_number(e.get("leave_qos_share_before"))) for e in episodes)
    plotted = [*FLEET_EPISODE_PLOTTED, *([("leave", "the departure's users: QoS share before "
                                          "-> after (hollow)", 1.0)] if leave else [])]  # fmt: skip
    fig, axes = _figure(len(plotted), len(results))
    for ax, (key, label, scale) in zip(axes[:, 0], plotted, strict=True):
        for y, (r, group) in enumerate(zip(results, groups, strict=True)):
            colour, marker = _look(r["method"], y)
            drawn = False
            for k, e in enumerate(group):
                # the episodes spread over the row's height, in their order: each one seen
                at = y + (0.0 if len(group) == 1 else 0.6 * (k / (len(group) - 1) - 0.5))
                if key != "leave":
                    v = cell_number(e.get(key)) * scale
                    if math.isfinite(v):
                        ax.plot([v], [at], color=colour, marker=marker, markersize=5, alpha=0.8)
                        drawn = True
                    continue
                before, after = (cell_number(e.get(f"leave_qos_share_{w}"))
                                 for w in ("before", "after"))  # fmt: skip
                if math.isfinite(before) and math.isfinite(after):
                    ax.plot([before, after], [at, at], color=colour, linewidth=1.0)
                    ax.plot([before], [at], color=colour, marker=marker, markersize=5)
                    ax.plot([after], [at], color=colour, marker=marker, markersize=5,
                            markerfacecolor="none")  # fmt: skip
                    drawn = True
            if not drawn:
                _undefined(ax, y)
        _rows_axis(ax, _row_labels(results), label)
        _fit(ax, key)
    return _save_figure(fig, out / FLEET_EPISODES_FIGURE, title)


def _undefined(ax, y: float) -> None:
    """Say so on a row with nothing to draw (every episode's value not defined: e.g. no
    departure, or no user served), rather than leave it empty."""
    ax.annotate("not defined", (0.01, y), xycoords=("axes fraction", "data"), fontsize=7,
                va="center", color="0.4")  # fmt: skip


def _fit(ax, key: str) -> None:
    """A share or a rate from 0 to 1; pair counts from 0 in whole numbers (at least to 1, so
    that zeros do not draw an axis of -0.02 to 0.05); any other number from 0 with room for
    the largest marker."""
    if any(w in key for w in ("rate", "share", "fairness", "leave")):
        ax.set_xlim(-0.02, 1.02)
        return
    if key == "pairs":
        from matplotlib.ticker import MaxNLocator

        drawn = [float(x) for line in ax.get_lines() for x in line.get_xdata()]
        ax.set_xlim(-0.5, max([1.0, *(x for x in drawn if math.isfinite(x))]) + 0.5)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        return
    lo, hi = ax.get_xlim()
    ax.set_xlim(lo, hi + 0.04 * (hi - lo))
