"""A vertical margin of its own (`avoidance.mcts.vertical_reach_mps`, issue 31, sep32): the
tree's sphere of d_min + margin becomes a spheroid as tall as d_min + the intruder's vertical
reach and vertical track error, so a track passing overhead far enough above no longer
fences off a level line, and with no vertical advantage nothing changes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.avoidance import Intruder, Ownship, PlannerConfig
from uavxai.avoidance.mcts import predict_levels
from uavxai.avoidance.model import COLLISION, EncounterModel, track_sigma, vertical_margin
from uavxai.avoidance.planners import make_planner
from uavxai.cli import main
from uavxai.errors import UserError

GOAL = (500.0, 1900.0, 120.0)
OWN = Ownship(x=500.0, y=500.0, h=120.0, speed=20.0, heading=0.0)  # due north


def _overhead(dz: float) -> Intruder:
    """Head-on, ``dz`` above, passing straight over the ownship 3.5 s from now (exact track)."""
    return Intruder(id=1, x=500.0, y=640.0, h=120.0 + dz, vx=0.0, vy=-20.0)


def _level_collisions(cfg: PlannerConfig, dz: float) -> int:
    """How many of the tree's first-level lines that hold the height conflict with the track."""
    d = make_planner("mcts_sep", cfg).plan(OWN, [_overhead(dz)], GOAL)
    tree = d.tree
    first = (tree.depth == 1) & (tree.action < 9)  # the paper's nine: the height held
    return int(np.sum(tree.terminal[first] == COLLISION))


def test_the_vertical_margin_is_the_reach_plus_k_sigma_of_the_vertical_error() -> None:
    t = np.array([0.0, 2.0, 4.0, 8.0, 16.0])
    sh, svh = np.array([4.0]), np.array([0.75])
    assert vertical_margin(PlannerConfig(), sh, svh) is None  # off: the sphere
    cfg = PlannerConfig(vertical_reach_mps=2.5)
    got = vertical_margin(cfg, sh, svh)(t)[:, 0]
    want = 2.5 * np.minimum(t, cfg.reach_horizon_s) + 2.0 * track_sigma(cfg, 1, sh, svh)(t)[:, 0]
    np.testing.assert_allclose(got, want)
    assert got[-1] < 40.0  # against the sphere's 100-170 m of horizontal margin (docs/results)


def test_tracks_carry_the_stretch_only_with_the_setting() -> None:
    intr = [Intruder(id=1, x=800.0, y=800.0, h=130.0, vx=-15.0, vy=0.0, sigma_m=4.0,
                     sigma_v=2.5, sigma_h_m=4.0, sigma_vh=0.75),
            # a fleet member's track, with the fleet's clearance: no stretch without the
            # setting either (the keep is no vertical margin of its own)
            Intruder(id="ownship-2", x=900.0, y=1200.0, h=160.0, vx=0.0, vy=-18.0,
                     keep_m=30.0)]  # fmt: skip
    for cfg in (PlannerConfig(), PlannerConfig(vertical_reach_mps=2.5)):
        model = EncounterModel(cfg)
        tracks = predict_levels(model, intr, cfg.depth, cfg.action_hold_s)
        if cfg.vertical_reach_mps is None:
            assert all(tr.vscale is None for tr in tracks)
            continue
        for tr in tracks:
            assert tr.vscale.shape == tr.margin.shape and np.all(tr.vscale >= 1.0)
        # the spheroid's half-height (d_min + margin) / stretch is d_min + the vertical margin
        last = tracks[-1]
        tall = (cfg.d_min_m + last.margin) / last.vscale - cfg.d_min_m
        assert np.all(tall < last.margin) and tall[-1, 0] < 40.0 < last.margin[-1, 0]


def test_a_track_passing_overhead_fences_the_level_lines_only_with_the_sphere() -> None:
    # 70 m above: inside d_min + the turn cover (about 85 m at 3.5 s) as a sphere, outside
    # d_min + the climb-rate limit's reach (2.5 m/s x 3.5 s) as the spheroid
    sphere = _level_collisions(PlannerConfig(), 70.0)
    spheroid = _level_collisions(PlannerConfig(vertical_reach_mps=2.5), 70.0)
    assert sphere > 0 and spheroid == 0
    # 40 m above it is inside the collision distance itself: every level line still meets it
    assert _level_collisions(PlannerConfig(vertical_reach_mps=2.5), 40.0) == 9


def test_no_vertical_advantage_changes_nothing() -> None:
    # a vertical reach at least the horizontal margin's: the stretch is 1, the same tree
    def tree(cfg):
        return make_planner("mcts_sep", cfg).plan(OWN, [_overhead(70.0)], GOAL).tree

    a, b = tree(PlannerConfig()), tree(PlannerConfig(vertical_reach_mps=50.0))
    for name in ("terminal", "visits", "value_sum", "min_sep"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_the_setting_needs_the_sphere_and_the_margin(tmp_path, capsys) -> None:
    with pytest.raises(UserError, match="vertical_reach_mps"):
        PlannerConfig(vertical_reach_mps=2.5, conflict_volume="cylinder")
    path = tmp_path / "s.yaml"
    path.write_text(
        "avoidance:\n  conflict_volume: cylinder\n  mcts:\n    vertical_reach_mps: 2.5\n"
    )
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "vertical_reach_mps needs" in err
    path.write_text("avoidance:\n  mcts:\n    vertical_reach_mps: -1\n")
    assert main(["validate", str(path)]) == 2
    assert "vertical_reach_mps" in capsys.readouterr().err
    assert math.isfinite(PlannerConfig(vertical_reach_mps=0.0).vertical_reach_mps)
