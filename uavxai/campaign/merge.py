"""`uavxai merge`: campaigns of one scenario pooled into one, every results row computed again
from the pooled episodes.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from pathlib import Path

from uavxai.campaign.files import (
    DAA_EPISODE_COLUMNS,
    EPISODE_COLUMNS,
    FLEET_EPISODES,
    FLIGHT_COLUMNS,
    GOAL_COLUMNS,
    RESULT_COLUMNS,
    checked_row,
    columns_of,
    has_daa_columns,
    read_rows,
    write_csv,
)
from uavxai.campaign.plots import plot_campaign
from uavxai.campaign.statistics import summarise
from uavxai.errors import UserError
from uavxai.outputs import cell_number
from uavxai.processes import interrupts_deferred


def _episodes_file(src: Path) -> Path:
    """A source campaign's episodes.csv; a fleet campaign's folder refused by name (its files
    are not these)."""
    if (src / FLEET_EPISODES).is_file() and not (src / "episodes.csv").exists():
        raise UserError(
            f"{src}: a fleet campaign ({FLEET_EPISODES}); merge pools one-ownship campaigns "
            "only. Pooling fleet campaigns is not built: fly one campaign with every seed, "
            "or read the sources' fleet_episodes.csv together (docs/fleet.md)."
        )
    return src / "episodes.csv"


def merge_campaigns(sources: Sequence[str | Path], out: str | Path, title: str = "") -> list[dict]:
    """One campaign from several of the same scenario and dynamics: other methods, other
    intruder counts, or more seeds of the same ones (a campaign extended later, or split over
    machines). The episodes are pooled and every ``results.csv`` row is computed again from
    them, so a risk ratio pairs a method with ``none`` on every seed both flew, whichever source
    flew it. The same (method, intruders, seed) in two sources is an error: it would count twice.

    ``decision_ms_p50`` is the source's when one source flew the whole row; a pooled row has
    only each episode's median to go on and takes the median of those."""
    out = Path(out)
    episodes: list[dict] = []
    flown_by: dict[tuple[str, int, int], Path] = {}
    p50: dict[tuple[str, int], float] = {}
    goals: dict[tuple[str, ...], Path] = {}
    for src in map(Path, sources):
        # files written before the goal was recorded lack its columns, and are taken on trust
        rows = read_rows(_episodes_file(src), EPISODE_COLUMNS[: -len(GOAL_COLUMNS)])
        rows = [checked_row(r, src / "episodes.csv", i) for i, r in enumerate(rows, start=2)]
        for i, r in enumerate(rows, start=2):
            try:
                if has_daa_columns(r):  # the detect-and-avoid record's columns
                    if not 0 < float(r["weight"]) < math.inf:
                        raise ValueError
                    for column in DAA_EPISODE_COLUMNS[1:]:
                        cell_number(r.get(column))
            except (TypeError, ValueError):
                raise UserError(
                    f"{src / 'episodes.csv'} line {i}: in a detect-and-avoid record "
                    f"{', '.join(DAA_EPISODE_COLUMNS)} must be numbers, the weight > 0."
                ) from None
        for r in rows:
            for column in FLIGHT_COLUMNS:  # not in files written before they existed
                r.setdefault(column, "")
            key = (r["method"], r["intruders"], r["seed"])
            if key in flown_by:
                raise UserError(
                    f"{key[0]} at {key[1]} intruders, seed {key[2]}: flown in both "
                    f"{flown_by[key]} and {src}; merge campaigns of different seeds, methods or "
                    "intruder counts."
                )
            flown_by[key] = src
            goal = tuple(r[k] for k in GOAL_COLUMNS)
            if any(g != "" for g in goal):
                goals.setdefault(goal, src)
        episodes.extend(rows)
        for r in read_rows(src / "results.csv", RESULT_COLUMNS):
            # garbage timing: nothing to keep, the row's own median of medians stands
            with contextlib.suppress(ValueError, OverflowError):
                ms = float(r["decision_ms_p50"] or "nan")
                if math.isfinite(ms) and ms >= 0:
                    p50[(r["method"], int(r["intruders"]))] = ms
    if len({has_daa_columns(r) for r in episodes}) > 1:
        raise UserError(
            "these campaigns mix episodes with the detect-and-avoid record (episodes.csv with "
            "weight, hmd_m, ...) and episodes without it (a random-traffic campaign written "
            "before it was recorded); merge campaigns of the same scenario flown by the same "
            "version, or fly the older one again."
        )
    if len(goals) > 1:
        what = "; ".join(f"{src}: ({', '.join(map(str, g))})" for g, src in goals.items())
        raise UserError(
            f"these campaigns flew to different goals ({what}), so the same seed is not the same "
            "encounter; a scenario without ownship.goal flies to the service point of its "
            "file's seed (`uavxai evaluate --seed N` keeps it; a campaign written before that, "
            "or run from Python on a scenario whose seed was changed, has another)."
        )
    sources_of: dict[tuple[str, int], set[Path]] = {}
    for (m, n, _), src in flown_by.items():
        sources_of.setdefault((m, n), set()).add(src)
    results = summarise(episodes)
    for r in results:
        if len(sources_of[(r["method"], r["intruders"])]) == 1:
            r["decision_ms_p50"] = p50.get((r["method"], r["intruders"]), r["decision_ms_p50"])
    with interrupts_deferred():  # a signal now waits for the files: they end whole
        out.mkdir(parents=True, exist_ok=True)
        episode_columns, result_columns = columns_of(episodes)
        write_csv(out / "results.csv", result_columns, results)
        write_csv(out / "episodes.csv", episode_columns, episodes)
        plot_campaign(results, out, title)
    return results
