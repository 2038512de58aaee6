"""A campaign's figures (uavxai.campaign.plots): an encounter campaign draws its detect-and-
avoid estimates with their intervals; a campaign without encounters does not."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib.image
import pytest

from uavxai.campaign.plots import _STYLE, DAA_FIGURE, DAA_PLOTTED, plot_campaign, plot_daa
from uavxai.vocabulary import AVOIDANCE_PLANNERS

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results"


def _rows(*files: str) -> list[dict]:
    rows: dict[str, dict] = {}
    for f in files:
        with open(RESULTS / f, encoding="utf-8") as fh:
            for r in csv.DictReader(fh):
                rows[r["method"]] = r  # each file carries its own `none` row: one is kept
    return list(rows.values())


def test_an_encounter_campaign_draws_one_panel_per_estimate(tmp_path: Path) -> None:
    rows = _rows("encounters/kinematic-daa50-results.csv",
                 "encounters/kinematic-vertical50-results.csv")  # fmt: skip
    paths = plot_campaign(rows, tmp_path, "encounters")
    assert tmp_path / DAA_FIGURE in paths
    image = matplotlib.image.imread(tmp_path / DAA_FIGURE)
    assert image.shape[0] > 200 * len(DAA_PLOTTED) // 2 and image.shape[1] > 400
    assert image.std() > 0.01  # not a blank page


def test_a_campaign_without_encounters_has_no_estimates_to_draw(tmp_path: Path) -> None:
    rows = _rows("kinematic/results.csv")
    assert plot_daa(rows, tmp_path) == []
    assert not (tmp_path / DAA_FIGURE).exists()
    assert plot_campaign(rows, tmp_path)  # its rate figures


@pytest.mark.parametrize("key", [k for k, _, _ in DAA_PLOTTED])
def test_every_plotted_estimate_is_a_results_column(key: str) -> None:
    from uavxai.campaign import DAA_COLUMNS

    assert {key, key + "_lo", key + "_hi"} <= set(DAA_COLUMNS)


def test_every_built_in_planner_has_a_style_of_its_own() -> None:
    """A figure comparing any built-in planners tells them apart: no planner falls back to the
    colour cycle (whose first colours are the table's own), no two share a colour or marker."""
    assert set(_STYLE) == set(AVOIDANCE_PLANNERS)
    colours, markers = zip(*_STYLE.values(), strict=True)
    assert len(set(colours)) == len(colours)
    assert len(set(markers)) == len(markers)
