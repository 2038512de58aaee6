"""A campaign's files: the columns of ``episodes.csv`` and ``results.csv``, a CSV written whole,
and a source campaign's rows read back and checked (for ``uavxai merge``).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from pathlib import Path

from uavxai.errors import UserError
from uavxai.outputs import csv_cell, write_output
from uavxai.vocabulary import OUTCOMES, avoidance_planners

RESULT_COLUMNS = (
    "method",
    "intruders",
    "episodes",
    "goal_rate",
    "collision_rate",
    "timeout_rate",
    "mean_steps",
    "mean_min_separation_m",
    "decision_ms_p50",
    "out_of_bounds_rate",
    "fdm_failure_rate",
    "nmac_rate",
    "nmac_rate_lo",
    "nmac_rate_hi",
    "collision_rate_lo",
    "collision_rate_hi",
    "risk_ratio",
    "risk_ratio_lo",
    "risk_ratio_hi",
    "collision_risk_ratio",
    "collision_risk_ratio_lo",
    "collision_risk_ratio_hi",
)
EPISODE_COLUMNS = (
    "method",
    "intruders",
    "episode",
    "seed",
    "outcome",
    "steps",
    "min_separation_m",
    "flight_time_s",
    "decision_ms_p50",
    "nmac",
    # The campaign's goal: one per campaign, written on every row so that pooled campaigns
    # (merge_campaigns) can check they flew the same encounters.
    "goal_x",
    "goal_y",
    "goal_h",
)
GOAL_COLUMNS = EPISODE_COLUMNS[-3:]
# Every episode's detect-and-avoid record (uavxai.sim.daa_record; docs/daa-metrics.md), weighted
# by the encounter's importance weight (1 for random traffic); per method the weighted DAA
# estimates of uavxai.daa_metrics.daa_summary against `none` on the same seeds. Campaigns
# written before random traffic carried them have none of these columns.
DAA_EPISODE_COLUMNS = ("weight", "hmd_m", "vmd_m", "lowc", "alert", "manoeuvre", "reversals")
# How each episode was flown (uavxai.sim.flight_quality), after the goal's columns; results
# gain their median / means. Files written before they existed are merged with them empty.
FLIGHT_COLUMNS = ("path_excess", "reversals_per_min", "bank_over_25_s")
FLIGHT_RESULTS = ("median_path_excess", "mean_reversals_per_min", "mean_bank_over_25_s")
DAA_RATES = (
    "nmac_prob", "nmac_risk_ratio", "induced_risk_ratio", "lowc_prob", "lowc_ratio",
    "alert_rate", "unnecessary_manoeuvre_rate",
)
DAA_COLUMNS = (
    *(f"{k}{end}" for k in DAA_RATES for end in ("", "_lo", "_hi")),
    "ci_check", "mean_reversals", "mean_path_excess",
)
# A fleet campaign's files (docs/fleet.md, "Fleet campaigns"), in place of episodes.csv and
# results.csv, whose columns are one ownship's transit to a goal: fleet_episodes.csv one row per
# episode (the fleet mission `uavxai run` flies at its seed; per-member cells space-separated in
# member order), fleet_results.csv one row per method and intruder count.
FLEET_EPISODES = "fleet_episodes.csv"
FLEET_RESULTS = "fleet_results.csv"
FLEET_EPISODE_COLUMNS = (
    "method", "intruders", "episode", "seed", "outcome", "completed", "member_outcomes",
    "flight_time_s", "delivered_bits", "member_delivered_bits", "qos_share", "jain_fairness",
    "energy_wh", "member_energy_wh", "member_min_separation_m", "member_collisions",
    "intruder_collisions", "member_nmacs", "intruder_nmacs", "closest_members_m",
    "closest_intruder_m", "departures", "leave_uav", "leave_t_s", "leave_qos_share_before",
    "leave_qos_share_after", "leave_crowd_qos_share_before", "leave_crowd_qos_share_after",
    "leave_recovered_after_s", "decision_ms_p50", "wall_s",
)
FLEET_RESULT_COLUMNS = (
    "method", "intruders", "episodes",
    *(f"{k}{end}" for k in ("completed_rate", "collision_rate", "member_nmac_rate",
                            "intruder_nmac_rate") for end in ("", "_lo", "_hi")),
    "timeout_rate", "out_of_bounds_rate", "fdm_failure_rate", "member_collisions",
    "intruder_collisions", "member_nmacs", "intruder_nmacs", "min_closest_members_m",
    "min_closest_intruder_m", "mean_delivered_bits", "min_delivered_bits", "mean_qos_share",
    "min_qos_share", "mean_jain_fairness", "min_jain_fairness", "mean_energy_wh",
    "max_energy_wh", "mean_leave_qos_share_before", "mean_leave_qos_share_after",
    "min_leave_qos_share_after", "leave_never_recovered", "max_leave_recovered_after_s",
    "mean_wall_s",
)  # fmt: skip
# The columns whose values depend on the machine, not on the seed.
TIMING_COLUMNS = ("decision_ms_p50", "wall_s", "mean_wall_s")


def has_daa_columns(r: dict) -> bool:
    """A row with the detect-and-avoid record (it has a weight): an encounter campaign's, or
    a random-traffic one written since it carried the record."""
    return str(r.get("weight", "")) != ""


def columns_of(rows: Sequence[dict]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The (episodes.csv, results.csv) columns of a campaign's rows: with the detect-and-avoid
    columns when every row has its record."""
    if rows and all(has_daa_columns(r) for r in rows):
        return (EPISODE_COLUMNS + FLIGHT_COLUMNS + DAA_EPISODE_COLUMNS,
                RESULT_COLUMNS + FLIGHT_RESULTS + DAA_COLUMNS)  # fmt: skip
    return EPISODE_COLUMNS + FLIGHT_COLUMNS, RESULT_COLUMNS + FLIGHT_RESULTS


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[dict]) -> None:
    """A CSV file written whole (temporary file + rename, never through a link); text cells a
    spreadsheet would run as a formula are made inert (:func:`uavxai.outputs.csv_cell`)."""
    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(columns)
    for r in rows:
        w.writerow([csv_cell(_cell(r[c])) for c in columns])
    write_output(path, buf.getvalue())


def _cell(v):
    if isinstance(v, float):
        if math.isnan(v):
            return ""  # not defined (e.g. a risk ratio without `none` flown)
        return f"{v:.6g}" if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    return v


def as_written(rows: Iterable[dict], columns: Sequence[str]) -> list[dict]:
    """``rows`` as :func:`write_csv` writes their ``columns`` (numbers to six digits): a
    summary computed from them is the one computed again from the file (``uavxai merge``)."""
    return [{c: "" if r[c] is None else _cell(r[c]) for c in columns} for r in rows]


MAX_STEPS = 10**7  # decisions in one episode: far beyond any scenario's max_steps
MAX_SEED = 2**31 - 1
MAX_INTRUDERS = 10_000


class _Cells:
    """One row of a source campaign's file, read cell by cell: each value within what a
    campaign writes, or a UserError naming the file, the line, the column and what it allows."""

    def __init__(self, r: dict, path: Path, line: int) -> None:
        self.r, self.path, self.line = r, path, line

    def bad(self, column: str, allowed: str) -> UserError:
        value = str(self.r.get(column))
        shown = value if len(value) <= 40 else value[:37] + "..."
        return UserError(
            f"{self.path} line {self.line}: {column} {shown!r} is not allowed; {column} must be "
            f"{allowed}. The file was not written by `uavxai evaluate` as it stands."
        )

    def number(self, column: str, lo: float, hi: float, allowed: str, empty=None, whole=False):
        text = (self.r.get(column) or "").strip()
        if text == "" and empty is not None:
            return empty
        try:
            v = float(text)
        except ValueError:
            raise self.bad(column, allowed) from None
        if math.isnan(v) or not lo <= v <= hi or (whole and v != int(v)):
            raise self.bad(column, allowed)
        return int(v) if whole else v

    def keys(self) -> dict:
        """The row with its method, outcome, intruder count, episode and seed checked, typed."""
        r, out = self.r, dict(self.r)
        if r.get("method") not in avoidance_planners():
            raise self.bad("method", f"a planner name, one of {', '.join(avoidance_planners())}")
        if r.get("outcome") not in OUTCOMES:
            raise self.bad("outcome", f"one of {', '.join(OUTCOMES)}")
        out["intruders"] = self.number("intruders", 0, MAX_INTRUDERS,
                                       f"a whole number from 0 to {MAX_INTRUDERS}",
                                       whole=True)  # fmt: skip
        out["episode"] = self.number("episode", 0, MAX_SEED, "a whole number >= 0", whole=True)
        out["seed"] = self.number("seed", 0, MAX_SEED, f"a whole number from 0 to {MAX_SEED}",
                                  whole=True)  # fmt: skip
        return out


def checked_row(r: dict, path: Path, line: int) -> dict:
    """One ``episodes.csv`` row of a source campaign, every value within what a campaign
    writes, typed (so that the merged files hold numbers, not the source's text)."""
    cells = _Cells(r, path, line)
    number = cells.number
    out = cells.keys()
    out["steps"] = number("steps", 0, MAX_STEPS, f"a whole number from 0 to {MAX_STEPS}",
                          whole=True)  # fmt: skip
    out["min_separation_m"] = number(
        "min_separation_m", 0, math.inf, "a distance >= 0 in metres ('inf': no intruder)"
    )
    out["flight_time_s"] = number("flight_time_s", 0, 1e9, "a time >= 0 in seconds")
    out["nmac"] = number("nmac", 0, 1, "0 or 1", whole=True)
    out["decision_ms_p50"] = number(
        "decision_ms_p50", 0, 1e9, "a time >= 0 in milliseconds, or empty", empty=math.nan
    )
    for column in GOAL_COLUMNS:  # files written before the goal was recorded lack it
        out[column] = number(column, -1e7, 1e7, "a coordinate in metres, or empty", empty="")
    return out


# fleet_episodes.csv's text cells (one value per member, space-separated); every other cell
# but the keys is a number or empty (not defined)
FLEET_TEXT_COLUMNS = ("member_outcomes", "member_delivered_bits", "member_energy_wh",
                      "member_min_separation_m")  # fmt: skip


MAX_COUNT = 10**9  # events, departures or bits a row counts: far beyond any mission's
MAX_BITS = 10**18
# Each fleet_episodes.csv number column after ``completed`` as a campaign writes it (fleet_row):
# (lowest, highest, what it allows, whether empty is allowed, whether whole). A count is never
# empty (summarise_fleet sums it); a share is 0-1 or empty (not defined); a closest approach is
# 'inf' when nothing came near.
_FLEET_NUMBERS: dict[str, tuple[float, float, str, bool, bool]] = {
    "flight_time_s": (0, 1e9, "a time >= 0 in seconds", False, False),
    "delivered_bits": (0, MAX_BITS, "a whole number of bits >= 0", False, True),
    "qos_share": (0, 1, "a share from 0 to 1, or empty", True, False),
    "jain_fairness": (0, 1, "a fairness from 0 to 1, or empty", True, False),
    "energy_wh": (0, 1e9, "an energy >= 0 in Wh, or empty", True, False),
    **{k: (0, MAX_COUNT, f"a whole number from 0 to {MAX_COUNT}", False, True) for k in (
        "member_collisions", "intruder_collisions", "member_nmacs", "intruder_nmacs",
        "departures")},
    **{k: (0, math.inf, "a distance >= 0 in metres ('inf': none came near)", False, False)
       for k in ("closest_members_m", "closest_intruder_m")},
    "leave_uav": (0, MAX_COUNT, "a member's index (a whole number >= 0), or empty", True, True),
    "leave_t_s": (0, 1e9, "a time >= 0 in seconds, or empty", True, False),
    **{f"leave_{k}": (0, 1, "a share from 0 to 1, or empty", True, False) for k in (
        "qos_share_before", "qos_share_after", "crowd_qos_share_before",
        "crowd_qos_share_after")},
    "leave_recovered_after_s": (0, 1e9, "a time >= 0 in seconds, or empty", True, False),
    "decision_ms_p50": (0, 1e9, "a time >= 0 in milliseconds, or empty", True, False),
    "wall_s": (0, 1e9, "a time >= 0 in seconds, or empty", True, False),
}  # fmt: skip


def checked_fleet_row(r: dict, path: Path, line: int) -> dict:
    """One ``fleet_episodes.csv`` row of a source campaign: its keys checked and typed, its
    ``completed`` 0 or 1, every other number within what a campaign writes (``_FLEET_NUMBERS``).
    The numbers are kept as the file's text: written again, the merged file holds them as the
    source did, and :func:`summarise_fleet` reads them as numbers."""
    cells = _Cells(r, path, line)
    out = cells.keys()
    out["completed"] = cells.number("completed", 0, 1, "0 or 1", whole=True)
    for column, (lo, hi, allowed, empty, whole) in _FLEET_NUMBERS.items():
        cells.number(column, lo, hi, allowed, empty="" if empty else None, whole=whole)
    return out


def read_rows(path: Path, columns: Sequence[str]) -> list[dict]:
    """A campaign file's rows, refused with a clear message if it is not one."""
    if not path.is_file():
        raise UserError(f"{path}: no such file; is {path.parent} a campaign folder?")
    try:
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            rows = list(reader)
            missing = [c for c in columns if c not in (reader.fieldnames or ())]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UserError(f"{path}: cannot read it as a campaign file ({exc}).") from None
    if missing:
        raise UserError(
            f"{path}: not a campaign file of this uavxai, it lacks the columns "
            f"{', '.join(missing)}."
        )
    return rows
