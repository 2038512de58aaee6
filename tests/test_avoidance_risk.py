"""Risk as a probability (issue 31, `avoidance.mcts.risk: probability`): the chance of losing
separation against Monte Carlo, its shape, the search weighing it, the words quoting it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from uavxai.avoidance import Intruder, MCTSPlanner, Ownship, PlannerConfig
from uavxai.avoidance.model import EncounterModel, _closest_on_chords
from uavxai.avoidance.risk import edge_loss, loss_probabilities, loss_probability
from uavxai.cli import main
from uavxai.errors import UserError

SAMPLES = 100_000
# The quadrature's accuracy (risk.py: the Bessel factor's, ~2e-7): differences below it are
# rounding, not a trend.
ACCURACY = 1e-6


def _straight_pass_mc(miss: float, radius: float, sigma: float, seed: int) -> tuple[float, float]:
    """Monte Carlo of a straight pass: the ownship flies the x axis from -800 m to +800 m, a
    stationary intruder predicted at (0, miss, 0) is really there plus a Gaussian error of
    ``sigma`` per axis. The closest approach of the whole straight path to each sample is
    solved exactly (the foot of the perpendicular, clamped to the path's ends). Returns the
    share of samples that come within ``radius`` and its standard error."""
    rng = np.random.default_rng(seed)
    e = rng.normal(0.0, sigma, (SAMPLES, 3))
    along = e[:, 0] - np.clip(e[:, 0], -800.0, 800.0)
    hit = np.sqrt(along**2 + (miss + e[:, 1]) ** 2 + e[:, 2] ** 2) < radius
    p = hit.mean()
    return float(p), math.sqrt(max(p * (1 - p), 1.0 / SAMPLES) / SAMPLES)


PASSES = [(60.0, 50.0, 20.0), (100.0, 50.0, 100.0), (20.0, 50.0, 30.0), (150.0, 50.0, 60.0),
          (0.0, 50.0, 200.0), (80.0, 70.0, 5.0)]  # fmt: skip


@pytest.mark.parametrize(("miss", "radius", "sigma"), PASSES)
def test_the_chance_matches_monte_carlo_on_a_straight_pass(miss, radius, sigma):
    p_mc, se = _straight_pass_mc(miss, radius, sigma, seed=int(miss + sigma))
    assert abs(loss_probability(miss, radius, sigma) - p_mc) < 3 * se


@pytest.mark.parametrize(("miss", "radius", "sigma"), PASSES)
def test_an_edge_of_the_model_quotes_its_closest_approach_chance(miss, radius, sigma):
    """The search's per-edge number (edge_loss) on a straight pass flown by the encounter
    model, sampled at its sub-steps, against the same Monte Carlo: the closest approach
    falls inside a sub-step, which the exact chords find."""
    model = EncounterModel(PlannerConfig(intruder_model="cv"))
    duration = 64.0
    n = model.substeps(duration)
    own = np.array([[-800.0, 0.0, 0.0, 25.0, 0.5 * math.pi, 0.0, 0.0, 0.0]])
    track = model.predict(np.array([[3.3, miss, 0.0]]), np.zeros((1, 3)), duration)
    seg = model.fly(own, np.array([4]), np.array([5000.0, 0.0, 0.0]), duration, track,
                    cull=False, exact=True)  # fmt: skip
    rel = seg.xy[0][:, None] - track.xy
    rel_h = seg.hs[0][:, None] - track.h
    sep2, frac = _closest_on_chords(rel[None], rel_h[None], (np.abs(rel) ** 2 + rel_h**2)[None])
    out = np.empty(1)
    sig = np.full((n + 1, 1), sigma)
    margin = np.full((n + 1, 1), radius - 50.0)  # a margin adds to d_min = 50 m
    edge_loss(sep2[0], frac[0], True, margin, sig, np.arange(1), 1, n, True, 50.0, out)
    p_mc, se = _straight_pass_mc(miss, radius, sigma, seed=int(miss + sigma) + 1)
    assert abs(out[0] - p_mc) < 3 * se


def test_the_chance_falls_with_the_miss_and_with_sigma_inside():
    miss = np.linspace(0.0, 500.0, 1001)
    for sigma in (1.0, 5.0, 30.0, 100.0, 300.0):
        p = loss_probabilities(miss, 50.0, sigma)
        assert np.all(np.diff(p) <= ACCURACY), sigma
        assert p[0] > 0.5 * (1 - math.exp(-(50.0**2) / (2 * sigma**2)))  # no collapse at 0
    sigmas = np.linspace(0.5, 400.0, 800)
    for inside in (0.0, 20.0, 45.0):  # inside the disc: a vaguer track is likelier elsewhere
        assert np.all(np.diff(loss_probabilities(inside, 50.0, sigmas)) <= ACCURACY)
    # Outside it a vaguer track is likelier to be inside, until it is so vague that it is
    # likelier to be anywhere else: rising up to sigma ~ the miss / 2 at least.
    for outside in (80.0, 150.0, 300.0):
        rising = sigmas[sigmas <= outside / 2]
        assert np.all(np.diff(loss_probabilities(outside, 50.0, rising)) >= -ACCURACY)
    assert loss_probability(49.0, 50.0, 0.0) == 1.0 and loss_probability(51.0, 50.0, 0.0) == 0.0


def _crowd(seed: int, n: int = 12, sigma_m: float = 20.0, sigma_v: float = 6.0):
    rng = np.random.default_rng(seed)
    own = Ownship(x=0.0, y=0.0, h=120.0, speed=20.0, heading=0.78, bank=0.0)
    return own, [
        Intruder(id=i + 1, x=float(rng.uniform(-400, 700)), y=float(rng.uniform(-400, 700)),
                 h=float(rng.uniform(100, 140)), vx=float(rng.normal(0, 10)),
                 vy=float(rng.normal(0, 10)), vh=0.0, sigma_m=sigma_m, sigma_v=sigma_v)
        for i in range(n)
    ]  # fmt: skip


GOAL = (1000.0, 1000.0, 120.0)
BOX = {"x_bounds": (-1000.0, 2000.0), "y_bounds": (-1000.0, 2000.0)}


def test_without_track_error_probability_is_the_margin_bit_for_bit():
    """Nothing uncertain, nothing to weigh: the same trees as the wall (which then is only
    the reachable margin), decision for decision."""
    for seed in range(3):
        own, intruders = _crowd(seed, sigma_m=0.0, sigma_v=0.0)
        trees = []
        for risk in ("margin", "probability"):
            cfg = PlannerConfig(actions="vertical", risk=risk, seed=seed, **BOX)
            trees.append(MCTSPlanner(cfg).plan(own, intruders, GOAL).tree)
        a, b = trees
        assert a.risk is None and b.risk is None
        assert np.array_equal(a.visits, b.visits) and np.array_equal(a.value_sum, b.value_sum)


def test_the_search_weighs_each_line_by_its_chance_of_keeping_clear():
    """Every value the tree backs up is (1 - risk) times the clear value: at an open leaf
    of the last level, 1 - d/d_max scaled by the chance that its line keeps clear."""
    own, intruders = _crowd(4)
    cfg = PlannerConfig(actions="vertical", risk="probability", **BOX)
    tree = MCTSPlanner(cfg).plan(own, intruders, GOAL).tree
    leaves = np.flatnonzero((tree.depth == cfg.depth) & (tree.visits > 0) & (tree.terminal == 0))
    clear = 1.0 - np.linalg.norm(tree.pos[leaves] - np.array(GOAL), axis=1) / cfg.d_max
    assert (tree.risk[leaves] > 0.001).any()  # the crowd is close enough to count
    np.testing.assert_allclose(tree.q[leaves], clear * (1.0 - tree.risk[leaves]), rtol=1e-12)
    # and risk only grows along a line
    deeper = np.flatnonzero(tree.depth > 1)
    assert np.all(tree.risk[deeper] >= tree.risk[tree.parent[deeper]] - 1e-15)


def test_probability_no_wall_for_a_vague_track_margin_keeps_it():
    """A vague track 200 m off the straight route (poor ADS-B: 22 m, 8 m/s): 2 sigmas of its
    error (~ 300 m 16 s ahead) make most lines below "hold" collide; as a probability few do,
    and "hold" is worth nearly its clear value, less its small chance of losing separation."""
    own = Ownship(x=0.0, y=0.0, h=120.0, speed=20.0, heading=0.0, bank=0.0)
    intruders = [Intruder(id=7, x=200.0, y=300.0, h=120.0, vx=0.0, vy=0.0, vh=0.0,
                          sigma_m=22.0, sigma_v=8.0)]  # fmt: skip
    goal = (0.0, 1500.0, 120.0)
    wall = MCTSPlanner(PlannerConfig(**BOX)).plan(own, intruders, goal)
    chance = MCTSPlanner(PlannerConfig(risk="probability", **BOX)).plan(own, intruders, goal)
    hold_wall = next(c for c in wall.children if c.action == 4)
    hold_chance = next(c for c in chance.children if c.action == 4)
    assert hold_wall.collision_share > 0.5 and hold_wall.risk is None
    assert hold_chance.collision_share < 0.1 and 0.0 < hold_chance.risk < 0.05
    assert hold_chance.q > 2 * hold_wall.q


def test_explanations_quote_the_chance_of_losing_separation():
    own, intruders = _crowd(4)
    d = MCTSPlanner(PlannerConfig(actions="vertical", risk="probability", **BOX)).plan(
        own, intruders, GOAL
    )
    chosen = next(c for c in d.children if c.action == d.action)
    assert chosen.losses, "the crowd is close enough for the chosen line to carry a chance"
    who, p = chosen.losses[0]
    said = "under 1 %" if p < 0.005 else f"{100 * p:.0f} %"
    assert f"the chance of losing separation with intruder {who} along this line is {said}" in (
        d.explanation
    )
    assert chosen.risk == pytest.approx(1 - np.prod([1 - q for _, q in chosen.losses]))
    assert d.to_json()["children"][0]["risk"] is not None
    wall = MCTSPlanner(PlannerConfig(actions="vertical", **BOX)).plan(own, intruders, GOAL)
    assert "chance of losing separation" not in wall.explanation
    assert "risk" not in wall.to_json()["children"][0]


def test_bad_risk_settings_are_user_errors(tmp_path, capsys):
    with pytest.raises(UserError, match="risk' = 'vibes': Input should be 'margin' or 'probab"):
        PlannerConfig(risk="vibes")
    with pytest.raises(UserError, match="needs avoidance.conflict_volume: sphere"):
        PlannerConfig(risk="probability", conflict_volume="cylinder")
    path = tmp_path / "s.yaml"
    path.write_text("avoidance:\n  conflict_volume: cylinder\n  mcts:\n    risk: probability\n")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "conflict_volume: sphere" in err
    assert dataclasses.replace(PlannerConfig(), risk="probability").risk == "probability"


def test_the_risk_wall_fences_the_first_seconds_only():
    """risk_wall_s: uncertainty_k sigmas of the track error over a line's first seconds, none
    beyond; without it the probability has no wall of track error at all."""
    from uavxai.avoidance.model import intruder_margin, track_sigma

    vel, turn = np.array([[15.0, 0.0, 0.0]]), np.zeros(1)
    sm, sv = np.array([22.0]), np.array([8.0])
    t = np.array([0.0, 2.0, 4.0, 8.0, 16.0])
    base = dict(intruder_model="cv", **BOX)
    sigma = track_sigma(PlannerConfig(**base), 1, sm, sv)
    margin = intruder_margin(PlannerConfig(**base), vel, turn, sm, sv)(t)[:, 0]
    np.testing.assert_allclose(margin, 2.0 * sigma(t)[:, 0])  # the margin: a growing wall
    assert intruder_margin(PlannerConfig(risk="probability", **base), vel, turn, sm, sv) is None
    walled = PlannerConfig(risk="probability", risk_wall_s=4.0, **base)
    wall = intruder_margin(walled, vel, turn, sm, sv)(t)[:, 0]
    np.testing.assert_allclose(wall[:3], margin[:3])
    np.testing.assert_array_equal(wall[3:], 0.0)  # beyond it the chance alone, at d_min


def test_the_risk_wall_needs_the_probability(tmp_path, capsys):
    with pytest.raises(UserError, match="risk_wall_s needs avoidance.mcts.risk: probability"):
        PlannerConfig(risk_wall_s=4.0)
    path = tmp_path / "s.yaml"
    path.write_text("avoidance:\n  mcts:\n    risk_wall_s: -1\n    risk: probability\n")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "risk_wall_s" in err and "greater than 0" in err
