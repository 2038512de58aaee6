"""Each episode's detect-and-avoid record among random traffic (uavxai.sim.daa_record): the
record of a kinematic flight among several intruders against the per-intruder metrics of the
same sampled tracks, and the baseline that neither alerts nor manoeuvres."""

from __future__ import annotations

import math

import numpy as np

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.daa_metrics import hmd_vmd, loss_of_well_clear, reversals
from uavxai.scenario import load_scenario
from uavxai.sim.build import fly
from uavxai.sim.daa_record import DaaObserver
from uavxai.sim.flight_quality import FlightQuality
from uavxai.sim.spec import episode_spec

SCENARIO = "scenarios/manoeuvring.yaml"


def _flown(method: str, seed: int, n: int = 8):
    sc = load_scenario(SCENARIO)
    spec = episode_spec(sc, seed, n_intruders=n)
    cfg = PlannerConfig.from_scenario(sc)
    quality = FlightQuality(((spec.start.x, spec.start.y, spec.start.h), spec.goal))
    daa = DaaObserver(cfg)
    r = fly(spec, make_planner(method, cfg), observers=[quality, daa])
    return sc, r, quality, daa, daa.record(quality, sc.avoidance.well_clear)


def test_the_record_among_many_intruders_is_the_worst_of_each_intruders() -> None:
    sc, r, quality, daa, rec = _flown("mcts_fast", seed=3)
    own, tracks = np.array(quality.own), daa.tracks()
    assert tracks.shape == (len(own), 8, 3)
    wc = sc.avoidance.well_clear
    per = [loss_of_well_clear(own, tracks[:, j], wc.horizontal_m, wc.vertical_m)
           for j in range(8)]  # fmt: skip
    assert rec.lowc == any(per)
    misses = [hmd_vmd(own, tracks[:, j]) for j in range(8)]
    assert rec.hmd_m == min(m[0] for m in misses)
    assert (rec.hmd_m, rec.vmd_m) in misses
    assert rec.reversals == reversals(quality.bank_cmd) and rec.weight == 1.0
    # the closest horizontal approach is no further than the closest 3-D one
    assert rec.hmd_m <= r.min_separation_m + 1e-6
    # a tree among 8 intruders in a 2 km box sees a conflict on its straight line at some point
    assert rec.alert and rec.manoeuvre


def test_the_baseline_never_alerts_nor_manoeuvres_and_absent_intruders_are_nan() -> None:
    _, _, _, daa, rec = _flown("none", seed=3, n=4)
    assert not rec.alert and not rec.manoeuvre and rec.reversals == 0
    daa.intruders.append(daa.intruders[-1][:2])  # a sample where two intruders have left
    tracks = daa.tracks()
    assert np.isnan(tracks[-1, 2:]).all() and np.isfinite(tracks[-1, :2]).all()
    assert math.isfinite(rec.hmd_m) and rec.hmd_m >= 0
