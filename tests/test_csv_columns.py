"""Each CSV the tool writes has its columns declared once, beside its writer; the README's
table of outputs is the contract users read, so it must name the same columns in the same
order (a renamed or added column that the README does not follow fails here)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from uavxai.campaign import (
    DAA_COLUMNS,
    DAA_EPISODE_COLUMNS,
    EPISODE_COLUMNS,
    FLEET_EPISODE_COLUMNS,
    FLEET_RESULT_COLUMNS,
    FLIGHT_COLUMNS,
    FLIGHT_RESULTS,
    RESULT_COLUMNS,
)
from uavxai.comms.delivery import SERVICE_COLUMNS, USERS_COLUMNS
from uavxai.sim.observers import TRAJECTORY_FIELDS

README = Path(__file__).resolve().parents[1] / "README.md"


def _readme_row(name: str) -> str:
    rows = [ln for ln in README.read_text().splitlines() if ln.startswith(f"| `{name}`")]
    assert len(rows) == 1, f"README: one row of the outputs table for {name}"
    return rows[0]


def _column_lists(text: str) -> list[tuple[str, ...]]:
    """The code spans of ``text`` that are lists of column names, ``a, b, c``."""
    spans = re.findall(r"`([a-z_0-9]+(?:, [a-z_0-9]+)+)`", text)
    return [tuple(s.split(", ")) for s in spans]


@pytest.mark.parametrize(
    ("name", "columns"),
    [("trajectory.csv", TRAJECTORY_FIELDS), ("users.csv", USERS_COLUMNS),
     ("service.csv", SERVICE_COLUMNS)],
)  # fmt: skip
def test_the_readme_lists_each_run_csv_as_declared(name, columns):
    assert _column_lists(_readme_row(name)) == [columns]


def test_the_readme_lists_the_campaign_csvs_as_declared():
    # episodes.csv: the per-episode columns, then the goal's
    listed = _column_lists(_readme_row("episodes.csv"))
    assert tuple(c for cols in listed for c in cols) == (EPISODE_COLUMNS + FLIGHT_COLUMNS
                                                         + DAA_EPISODE_COLUMNS)
    # results.csv: its leading list, then the named interval and ratio columns in prose
    row = _readme_row("results.csv")
    head = _column_lists(row)[0]
    n = len(head)
    assert head == RESULT_COLUMNS[:n]
    for column in RESULT_COLUMNS[n:] + FLIGHT_RESULTS + DAA_COLUMNS:
        base = re.sub(r"_(lo|hi)$", "", column)
        assert f"`{base}`" in row, column


@pytest.mark.parametrize(
    ("name", "columns"),
    [("fleet_episodes.csv", FLEET_EPISODE_COLUMNS), ("fleet_results.csv", FLEET_RESULT_COLUMNS)],
)
def test_the_readme_lists_the_fleet_campaign_csvs_as_declared(name, columns):
    assert _column_lists(_readme_row(name)) == [columns]
