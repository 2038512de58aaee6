"""The default viewer layout: the 3-D scene big on the left, the reasoning on the right.

Left: the 3-D world with, beside it, the map and the per-user rate bars; under them a grid of
metric plots (with the mission phase). Right: the mission status (phase, users at QoS) above
the search tree of the current decision and the explanations interleaved with phase changes.
Trails are logged as short segments; a visible time range from the start of the run to the
cursor makes the viewer draw them as one growing line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from uavxai.recording import entities as ent

_METRIC_TITLES = {
    "sum_rate_bps": "sum rate (bit/s)",
    "min_separation_m": "min separation (m)",
    "bank_deg": "bank (deg)",
    "airspeed_mps": "airspeed (m/s)",
    "decision_ms": "decision time (ms)",
}


# How far back the intruders' trails reach in the 3D view. Their whole history fills a dense
# or persistent-traffic run's box with a web of lines (hundreds of aircraft over a mission);
# the last 30 s show where each is heading, which is what a user reads the view for. The
# ownship's trail keeps the whole flight.
INTRUDER_TRAIL_S = 30


def _history(seconds: int | None = None) -> rrb.VisibleTimeRanges:
    """Up to the time cursor, on both timelines: from the start of the run, or only the last
    ``seconds`` (on the decision timeline as many decisions: 1 s apart by default)."""
    end = rrb.TimeRangeBoundary.cursor_relative()
    if seconds is None:
        sim_start = decision_start = rrb.TimeRangeBoundary.infinite()
    else:
        sim_start = rrb.TimeRangeBoundary.cursor_relative(seconds=-float(seconds))
        decision_start = rrb.TimeRangeBoundary.cursor_relative(seq=-int(seconds))
    return rrb.VisibleTimeRanges(
        [
            rrb.VisibleTimeRange(ent.SIM_TIME, start=sim_start, end=end),
            rrb.VisibleTimeRange(ent.DECISION, start=decision_start, end=end),
        ]
    )


def _eye(bounds: dict[str, tuple[float, float]]) -> rrb.EyeControls3D:
    """Look at the flight area from the south, above and a little west, all of it in view."""
    (x0, x1), (y0, y1), (h0, _) = bounds["x"], bounds["y"], bounds["h"]
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2 + 0.05 * (y1 - y0), h0])
    span = max(x1 - x0, y1 - y0)
    return rrb.EyeControls3D(
        kind="Orbital",
        position=centre + span * np.array([-0.1, -0.95, 0.6]),
        look_target=centre,
        eye_up=(0.0, 0.0, 1.0),
    )


def _scene(
    bounds: dict[str, tuple[float, float]] | None, member_trails: Sequence[str] = ()
) -> rrb.Spatial3DView:
    def trails(seconds: int | None = None) -> list:
        return [rr.LineStrips3D.from_fields().visualizer(), _history(seconds)]

    return rrb.Spatial3DView(
        name="world",
        origin=ent.WORLD,
        # 100 m cells: the default 1 m grid is solid grey at the scale of a flight area.
        line_grid=rrb.LineGrid3D(visible=True, spacing=100.0),
        overrides={
            ent.OWNSHIP_TRAIL: trails(),
            ent.INTRUDER_TRAILS: trails(INTRUDER_TRAIL_S),
            **{path: trails() for path in member_trails},  # a fleet's other members
        },
        eye_controls=_eye(bounds) if bounds is not None else None,
    )


def _map(bounds: dict[str, tuple[float, float]] | None) -> rrb.MapView:
    zoom = None
    if bounds is not None:
        # Web-map zoom at which the flight area spans about 200 px of the small map view
        # (156 km per px at zoom 0 on the equator; the latitude factor is left out: it only
        # zooms out a little). The view centres on the data, which may reach beyond the area.
        span = max(bounds["x"][1] - bounds["x"][0], bounds["y"][1] - bounds["y"][0], 1.0)
        zoom = float(np.clip(math.log2(156543.0 * 200.0 / span), 1.0, 19.0))
    return rrb.MapView(name="map", origin=ent.MAP, zoom=zoom)


def _rates() -> rrb.BarChartView:
    return rrb.BarChartView(
        name="rates Mbit/s, band=QoS",
        origin=ent.RATES,
        plot_legend=rrb.PlotLegend(visible=False),
    )


def _status() -> rrb.TextDocumentView:
    return rrb.TextDocumentView(name="mission", origin=ent.STATUS)


def _tree() -> rrb.GraphView:
    # Node positions come from our tree layout; the force simulation would scramble them.
    off = {"enabled": False}
    return rrb.GraphView(
        name="search tree (this decision)",
        origin=ent.TREE,
        force_link=rrb.archetypes.ForceLink(**off),
        force_many_body=rrb.archetypes.ForceManyBody(**off),
        force_position=rrb.archetypes.ForcePosition(**off),
        force_collision_radius=rrb.archetypes.ForceCollisionRadius(**off),
        force_center=rrb.archetypes.ForceCenter(**off),
    )


def _metrics() -> rrb.Grid:
    plots = [
        rrb.TimeSeriesView(
            name=_METRIC_TITLES.get(name, name),
            origin=ent.metric_path(name),
            plot_legend=rrb.PlotLegend(visible=False),
        )
        for name in ent.METRIC_NAMES
    ]
    # The legend carries the series name, which says what the numbers mean.
    plots.append(
        rrb.TimeSeriesView(
            name="mission phase",
            origin=ent.PHASE_METRIC,
            plot_legend=rrb.PlotLegend(corner="LeftTop", visible=True),
        )
    )
    return rrb.Grid(*plots, grid_columns=3)


def _explanations() -> rrb.TextLogView:
    return rrb.TextLogView(
        name="explanation and phase changes",
        origin="/",
        contents=[f"+ /{ent.EXPLANATION}", f"+ /{ent.PHASE}"],
        columns=rrb.TextLogColumns(
            timeline_columns=[rrb.components.TimelineColumn(ent.SIM_TIME)],
            text_log_columns=["body"],  # one entity and one level: those columns say nothing
        ),
    )


def default_blueprint(
    bounds: dict[str, tuple[float, float]] | None = None, member_trails: Sequence[str] = ()
) -> rrb.Blueprint:
    """The layout; with the flight-area ``bounds`` the 3-D camera starts framed on them;
    ``member_trails`` (a fleet's members' trail paths) drawn whole, as the ownship's."""
    side = rrb.Vertical(_map(bounds), _rates(), row_shares=[1, 1])
    top = rrb.Horizontal(_scene(bounds, member_trails), side, column_shares=[5, 2])
    left = rrb.Vertical(top, _metrics(), row_shares=[2, 1])
    right = rrb.Vertical(_status(), _tree(), _explanations(), row_shares=[1, 4, 3])
    return rrb.Blueprint(
        rrb.Horizontal(left, right, column_shares=[3, 2]),
        rrb.TimePanel(timeline=ent.SIM_TIME, state="collapsed"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
    )
