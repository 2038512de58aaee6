"""The tree's conflict cylinder (`avoidance.conflict_volume: cylinder`): separation in the
cylinder's norm, exact on every sub-step; the sphere stays the default. Culling with the
cylinder: tests/test_avoidance_prediction.py."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from uavxai.avoidance.lines import chord_distances
from uavxai.avoidance.model import COLLISION, NONE, EncounterModel, ownship_state
from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import Ownship, PlannerConfig
from uavxai.errors import UserError
from uavxai.geometry import closest_on_pieces_cylinder

NMAC = (152.4, 30.48)
SPHERE = PlannerConfig(d_min_m=math.hypot(*NMAC))  # mcts_daa's sphere: it holds the NMAC
CYLINDER = PlannerConfig(d_min_m=NMAC[0], conflict_volume="cylinder",
                         conflict_half_height_m=NMAC[1])  # fmt: skip
HOLD = 4


def level_pass(cfg: PlannerConfig, intruder_xyz) -> tuple[int, float]:
    """(event, min_sep) of 4 s flown north at 20 m/s from (1000, 1000, 120) past a hovering
    intruder, exactly."""
    model = EncounterModel(cfg)
    own = Ownship(1000.0, 1000.0, 120.0, 20.0, 0.0)
    track = model.predict(np.array([intruder_xyz], float), np.zeros((1, 3)), 4.0)
    seg = model.fly(ownship_state(own)[None], np.array([HOLD]), np.array([1000.0, 1900, 120]),
                    4.0, track, cull=False, exact=True)  # fmt: skip
    return int(seg.event[0]), float(seg.min_sep[0])


def test_a_line_40_m_above_an_intruder_clears_the_cylinder_not_the_sphere():
    below = (1000.0, 1040.0, 80.0)  # the ownship passes right over it, 40 m above
    assert level_pass(SPHERE, below)[0] == COLLISION
    event, sep = level_pass(CYLINDER, below)
    assert event == NONE
    # the cylinder's norm: 40 m up is 40 * 152.4 / 30.48 = 200 horizontal-equivalent metres
    assert sep == pytest.approx(40.0 * NMAC[0] / NMAC[1], abs=1e-6)


def test_a_line_100_m_beside_an_intruder_conflicts_with_both():
    beside = (1100.0, 1040.0, 120.0)  # inside both from the start: counted to the first sub-step
    sphere, cylinder = level_pass(SPHERE, beside), level_pass(CYLINDER, beside)
    assert sphere[0] == cylinder[0] == COLLISION
    # level with it, the cylinder's norm is the distance: 100 m across, 10 m along at 0.5 s
    assert sphere[1] == pytest.approx(math.hypot(100.0, 30.0), abs=1e-6)
    assert cylinder[1] == pytest.approx(sphere[1], abs=1e-9)


def test_the_cylinder_norm_on_a_piece_matches_dense_sampling():
    rng = np.random.default_rng(5)
    r0 = rng.uniform(-200, 200, (500, 3))
    dr = rng.uniform(-60, 60, (500, 3))
    dr[:50, 2] = 0.0  # level pieces: the vertical candidate's division by zero
    dr[50:100, :2] = 0.0  # purely vertical ones
    aspect = 5.0
    got, s = closest_on_pieces_cylinder(r0, dr, aspect)
    t = np.linspace(0.0, 1.0, 20001)[:, None, None]
    p = r0 + t * dr
    dense = np.maximum(np.hypot(p[..., 0], p[..., 1]), aspect * np.abs(p[..., 2]))
    assert np.all(got <= dense.min(axis=0) + 1e-9)  # never above the true minimum ...
    assert np.all(got >= dense.min(axis=0) - 0.05)  # ... and not below it (sampling's step)
    at = r0 + s[:, None] * dr  # and s is where it is
    np.testing.assert_allclose(
        np.maximum(np.hypot(at[:, 0], at[:, 1]), aspect * np.abs(at[:, 2])), got, atol=1e-9
    )


def test_lines_are_measured_in_the_cylinder_norm():
    own = np.array([[0.0, 0.0, 40.0], [0.0, 10.0, 40.0]])  # 40 m over the intruder
    intruder = np.zeros((2, 1, 3))
    sphere, _ = chord_distances(own, intruder)
    cyl, _ = chord_distances(own, intruder, CYLINDER.cylinder_aspect)
    assert sphere[0, 0] == pytest.approx(40.0)
    assert cyl[0, 0] == pytest.approx(200.0)


def test_the_sphere_is_the_default_and_mcts_daa_keeps_it():
    cfg = PlannerConfig()
    assert cfg.conflict_volume == "sphere" and cfg.cylinder_aspect is None
    assert cfg.cull_m == cfg.d_min_m and cfg.cull_factor == 1.0
    daa = make_planner("mcts_daa", cfg).config
    assert daa.d_min_m == math.hypot(*cfg.nmac_m) and daa.conflict_volume == "sphere"
    assert daa.conflict_half_height_m is None


def test_mcts_daa_with_the_cylinder_holds_the_nmac_and_the_collision_sphere():
    daa = make_planner("mcts_daa", PlannerConfig(conflict_volume="cylinder")).config
    assert daa.d_min_m == 152.4  # the NMAC radius
    assert daa.conflict_half_height_m == 50.0  # d_min_m (collision) beats the NMAC's 30.48
    # 60 m over an intruder: clear of mcts_daa's cylinder, inside its sphere
    over = (1000.0, 1040.0, 60.0)
    assert level_pass(daa, over)[0] == NONE
    assert level_pass(make_planner("mcts_daa", PlannerConfig()).config, over)[0] == COLLISION


def test_a_bad_conflict_volume_is_refused():
    allowed = r"PlannerConfig\.conflict_volume' = 'cone': Input should be 'sphere' or 'cylinder'"
    with pytest.raises(UserError, match=allowed):
        PlannerConfig(conflict_volume="cone")
    with pytest.raises(UserError, match="conflict_half_height_m must be > 0"):
        PlannerConfig(conflict_volume="cylinder", conflict_half_height_m=0.0)


def test_the_scenario_setting_is_validated(tmp_path: Path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: bad\navoidance:\n  conflict_volume: cone\n")
    proc = subprocess.run([sys.executable, "-m", "uavxai", "validate", str(bad)],
                          capture_output=True, text=True)  # fmt: skip
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    said = proc.stderr + proc.stdout
    assert "conflict_volume" in said and "sphere" in said and "cylinder" in said
    good = tmp_path / "good.yaml"
    good.write_text("name: good\navoidance:\n  conflict_volume: cylinder\n")
    proc = subprocess.run([sys.executable, "-m", "uavxai", "validate", str(good)],
                          capture_output=True, text=True)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
