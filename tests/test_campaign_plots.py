"""A campaign's figures (uavxai.campaign.plots): an encounter campaign draws its detect-and-
avoid estimates with their intervals; a campaign without encounters does not; a fleet
campaign draws its headline figures and its episodes (round 12's files, issue 32), and rows
that are not a fleet campaign's are a clear UserError."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib.image
import pytest

from uavxai.campaign.files import FLEET_RESULT_COLUMNS
from uavxai.campaign.plots import (
    _STYLE,
    DAA_FIGURE,
    DAA_PLOTTED,
    FLEET_EPISODE_PLOTTED,
    FLEET_EPISODES_FIGURE,
    FLEET_PLOTTED,
    FLEET_RESULTS_FIGURE,
    plot_campaign,
    plot_daa,
    plot_fleet,
)
from uavxai.errors import UserError
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


def _read(name: str) -> list[dict]:
    with open(RESULTS / "fleet" / name, encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _image(path: Path):
    assert path.stat().st_size > 0
    return matplotlib.image.imread(path)


def test_a_fleet_campaign_draws_its_results_and_its_episodes(tmp_path: Path) -> None:
    """Round 12's two campaigns (seeds 60-64; the second with a member leaving): one row of
    panels per method and intruder count, the leave's panel only where an episode has one."""
    results, episodes = [], []
    for name in ("round12_seeds60-64", "round12_leave_seeds60-64"):
        for r in _read(f"{name}_results.csv"):
            results.append({**r, "method": "mcts" if "leave" not in name else "mcts_sep"})
        episodes += [{**e, "method": "mcts" if "leave" not in name else "mcts_sep"}
                     for e in _read(f"{name}_episodes.csv")]  # fmt: skip
    paths = plot_fleet(results, episodes, tmp_path, "round 12")
    assert paths == [tmp_path / FLEET_RESULTS_FIGURE, tmp_path / FLEET_EPISODES_FIGURE]
    image = _image(tmp_path / FLEET_RESULTS_FIGURE)
    assert image.shape[0] > 100 * len(FLEET_PLOTTED) and image.shape[1] > 400
    assert image.std() > 0.01  # not a blank page
    with_leave = _image(tmp_path / FLEET_EPISODES_FIGURE)
    assert with_leave.std() > 0.01
    # without a departure, one panel fewer: a shorter figure
    alone = [e for e in episodes if e["method"] == "mcts"]
    assert not any(e["leave_qos_share_before"] for e in alone)
    (tmp_path / "alone").mkdir()
    plot_fleet(results[:1], alone, tmp_path / "alone")
    assert _image(tmp_path / "alone" / FLEET_EPISODES_FIGURE).shape[0] < with_leave.shape[0]


@pytest.mark.parametrize("key", [k for k, _, _ in FLEET_PLOTTED])
def test_every_fleet_figure_is_a_results_column(key: str) -> None:
    worst = {k: w for k, _, w in FLEET_PLOTTED}[key]
    assert key in FLEET_RESULT_COLUMNS
    assert worst in ("wilson", "pairs") or worst in FLEET_RESULT_COLUMNS
    if worst == "wilson":
        assert {key + "_lo", key + "_hi"} <= set(FLEET_RESULT_COLUMNS)


def test_fleet_episode_figures_are_episode_columns() -> None:
    from uavxai.campaign.files import FLEET_EPISODE_COLUMNS

    assert {k for k, _, _ in FLEET_EPISODE_PLOTTED} <= set(FLEET_EPISODE_COLUMNS)


def test_rows_that_are_no_fleet_campaigns_are_refused_by_name(tmp_path: Path) -> None:
    results, episodes = _read("round12_seeds60-64_results.csv"), _read(
        "round12_seeds60-64_episodes.csv")  # fmt: skip
    with pytest.raises(UserError, match="fleet_results: no rows to plot"):
        plot_fleet([], episodes, tmp_path)
    with pytest.raises(UserError, match="fleet_episodes: no rows to plot"):
        plot_fleet(results, [], tmp_path)
    broken = [{**results[0], "mean_qos_share": "lots"}]
    with pytest.raises(UserError, match=r"fleet_results row 1: mean_qos_share 'lots' is not a"):
        plot_fleet(broken, episodes, tmp_path)
    nameless = [{k: v for k, v in e.items() if k != "method"} for e in episodes]
    with pytest.raises(UserError, match="fleet_episodes row 1: no method or intruders"):
        plot_fleet(results, nameless, tmp_path)
    assert not list(tmp_path.iterdir())  # nothing drawn from them


def test_fleet_figures_draw_counts_as_counts_and_name_what_is_not_defined(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The collision pairs panel draws two counts as two markers, not a line between them that
    reads as an interval, on a whole-number axis from 0 (all zeros drew -0.02 to 0.05); a row
    whose every value is not defined says so (it was an empty row); intruder and episode
    counts that are not whole numbers are refused by name (they crashed the labels)."""
    from uavxai.campaign import plots

    figures: dict = {}  # each figure drawn, by file name, to read its panels
    write = plots.write_figure

    def keep(path: Path, fig) -> Path:  # the figure, then its file
        figures[Path(path).name] = fig
        return write(path, fig)

    monkeypatch.setattr(plots, "write_figure", keep)
    results, episodes = _read("round12_seeds60-64_results.csv"), _read(
        "round12_seeds60-64_episodes.csv")  # fmt: skip
    assert results[0]["member_collisions"] == results[0]["intruder_collisions"] == "0"
    unserved = {**results[0], "method": "none", "mean_qos_share": "", "min_qos_share": ""}
    crashed = {**results[0], "method": "mcts_sep", "intruder_collisions": "2"}
    rows = [results[0], unserved, crashed]
    plot_fleet(rows, [*episodes, *({**e, "method": "none", "qos_share": ""} for e in episodes),
                      *({**e, "method": "mcts_sep"} for e in episodes)], tmp_path)  # fmt: skip
    panels = figures[FLEET_RESULTS_FIGURE].axes
    pairs = panels[[k for k, _, _ in FLEET_PLOTTED].index("member_collisions")]
    assert pairs.get_xlim() == (-0.5, 2.5)  # 0 and 2 pairs, whole numbers, from 0
    assert all(len(set(line.get_xdata())) == 1 for line in pairs.get_lines())
    assert [t.get_text() for t in pairs.texts] == []
    qos = panels[[k for k, _, _ in FLEET_PLOTTED].index("mean_qos_share")]
    assert [(t.get_text(), t.xy[1]) for t in qos.texts] == [("not defined", 1)]
    per_episode = figures[FLEET_EPISODES_FIGURE].axes
    qos = per_episode[[k for k, _, _ in FLEET_EPISODE_PLOTTED].index("qos_share")]
    assert [(t.get_text(), t.xy[1]) for t in qos.texts] == [("not defined", 1)]
    # all zeros: from 0 to 1, not -0.02 to 0.05
    plot_fleet(results, episodes, tmp_path)
    pairs = figures[FLEET_RESULTS_FIGURE].axes[[k for k, _, _ in FLEET_PLOTTED].index(
        "member_collisions")]  # fmt: skip
    assert pairs.get_xlim() == (-0.5, 1.5)
    for column, bad in (("intruders", "20.5"), ("episodes", "five")):
        with pytest.raises(UserError, match=rf"fleet_results row 1: {column} '{bad}' is not a "
                                            "whole number"):  # fmt: skip
            plot_fleet([{**results[0], column: bad}], episodes, tmp_path / "no")
